"""Speed of the complete rLfD diagram against the plant alone, per task.

``run`` measures, for each task, a full 10 s episode of the diagram of
:func:`rlfd_drake.diagram.BuildRlfdDiagram` (DMP 100 Hz, extrapolator, composer,
Cartesian impedance controller 500 Hz, plant 2 ms SAP hydroelastic, observer, the
episode loggers; no visualiser) with a zero residual, from the demonstration's start
pose (so the episode includes the approach, the contact-rich insertion and the hold).

The plant-alone figure replays the SAME arm motion without any Python system: the
controller's torques are recorded step by step in an untimed run, then fed back
through a C++ ``TrajectorySource`` (zero-order hold at the 2 ms plant steps) into the
same scene (plant + scene graph of :func:`rlfd_drake.scene.AddRlfdScene`). The plant
is deterministic and its actuation input sees bit-identical torques at every step,
so the replay reproduces the episode (``replay_max_q_error_rad`` checks it); the
difference in wall time is exactly the Python systems and their port evaluations.
The plant's sampled output ports (contact results, reaction forces) are computed by
every step in both runs.

All runs are pinned to one CPU core (when the OS allows) and restored afterwards.
Nothing is written to disk (``rlfd bench diagram --json`` does that).
"""

from __future__ import annotations

import cProfile
import os
import pstats
import statistics
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from rlfd_drake.bench.python_floor import AddPythonFloorProbes
from rlfd_drake.demonstration import load_demonstration
from rlfd_drake.diagram import BuildRlfdDiagram, RlfdDiagram, SetEpisodeStart
from rlfd_drake.dmp import fit_cartesian_dmp
from rlfd_drake.episode import demo_start_pose
from rlfd_drake.scene import AddRlfdScene
from rlfd_drake.tasks import TaskSpec, list_tasks, load_task

#: Episode length of the benchmark, s.
EPISODE_S = 10.0
#: Python callbacks of the diagram's systems reported by the profile, by system.
_CALLBACKS = {
    "dmp": ("dmp_system.py", ("_update", "_calc_pose", "_calc_velocity", "_calc_phase")),
    "extrapolator": ("extrapolator.py", ("_update", "_calc_X", "_calc_V")),
    "composer": ("composer.py", ("_calc_X", "_calc_V")),
    "controller": ("impedance.py", ("_update",)),
    # Only in tasks with an incremental residual (residual_rate_per_s).
    "integrator": ("residual_integrator.py", ("_update",)),
    "observer": (
        "observer.py",
        (
            "_update_metrics",
            "_calc_observation",
            "_calc_reward",
            "_calc_success",
            "_calc_force_metrics",
            "_calc_distance",
        ),
    ),
}


@contextmanager
def _one_core():
    """Pins this process to one CPU core for the duration (no-op where unsupported)."""
    if not hasattr(os, "sched_getaffinity"):
        yield
        return
    previous = os.sched_getaffinity(0)
    try:
        os.sched_setaffinity(0, {min(previous)})
        yield
    finally:
        os.sched_setaffinity(0, previous)


def _build(task: TaskSpec) -> tuple[RlfdDiagram, RigidTransform]:
    demo = load_demonstration(task.demo_path())
    model = fit_cartesian_dmp(demo.times, demo.positions, demo.quats)
    rlfd = BuildRlfdDiagram(task, model)
    X_WP_start = demo_start_pose(model)
    return rlfd, X_WP_start


def _episode_simulator(rlfd: RlfdDiagram, X_WP_start: RigidTransform) -> Simulator:
    """A fresh simulator at the episode start, initialised (zero residual)."""
    simulator = Simulator(rlfd.diagram)
    context = simulator.get_mutable_context()
    rlfd.diagram.GetInputPort("residual").FixValue(context, np.zeros(6))
    SetEpisodeStart(rlfd, context, X_WP_start)
    simulator.Initialize()
    return simulator


def _time_full(rlfd: RlfdDiagram, X_WP_start: RigidTransform) -> tuple[float, dict]:
    """Wall time (s) of one full episode and its outcome."""
    simulator = _episode_simulator(rlfd, X_WP_start)
    start = time.perf_counter()
    simulator.AdvanceTo(EPISODE_S)
    wall = time.perf_counter() - start
    context = simulator.get_context()
    outcome = {
        "success": bool(rlfd.diagram.GetOutputPort("success").Eval(context)[0] > 0.5),
        "distance_to_goal_m": float(
            rlfd.diagram.GetOutputPort("distance_to_goal").Eval(context)[0]
        ),
        "peak_contact_force_n": float(rlfd.diagram.GetOutputPort("force_metrics").Eval(context)[0]),
    }
    return wall, outcome


def _record_torques(
    rlfd: RlfdDiagram, X_WP_start: RigidTransform
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Untimed run: (times (N,) s, torques (7, N) N m that the plant's step at each time
    uses, q0 (7,) rad, q at the end (7,) rad)."""
    simulator = _episode_simulator(rlfd, X_WP_start)
    context = simulator.get_mutable_context()
    plant = rlfd.scene.plant
    plant_context = plant.GetMyContextFromRoot(context)
    q0 = plant.GetPositions(plant_context, rlfd.scene.panda).copy()
    torque_port = rlfd.controller.GetOutputPort("panda_torque")
    controller_context = rlfd.controller.GetMyContextFromRoot(context)
    h = rlfd.config.scene.time_step_s
    steps = int(round(EPISODE_S / h))
    times = np.empty(steps + 1)
    torques = np.empty((7, steps + 1))
    for k in range(steps + 1):
        if k > 0:
            simulator.AdvanceTo(k * h)
        # The value held now is what the plant's update at this time reads.
        times[k] = context.get_time()
        torques[:, k] = torque_port.Eval(controller_context)
    q_end = plant.GetPositions(plant_context, rlfd.scene.panda).copy()
    return times, torques, q0, q_end


def _time_replay(
    task: TaskSpec,
    rlfd: RlfdDiagram,
    times: np.ndarray,
    torques: np.ndarray,
    q0: np.ndarray,
    python_probes: bool = False,
) -> tuple[float, np.ndarray]:
    """Wall time (s) of the plant alone replaying ``torques``; q at the end (7,).

    With ``python_probes`` the do-nothing Python systems of
    :mod:`rlfd_drake.bench.python_floor` run beside it (same rates, same pulls).
    """
    builder = DiagramBuilder()
    scene = AddRlfdScene(builder, task, rlfd.config.scene)
    source = builder.AddSystem(TrajectorySource(PiecewisePolynomial.ZeroOrderHold(times, torques)))
    builder.Connect(source.get_output_port(), scene.plant.get_actuation_input_port(scene.panda))
    if python_probes:
        AddPythonFloorProbes(builder, scene)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    if python_probes:
        diagram.GetInputPort("residual").FixValue(simulator.get_mutable_context(), np.zeros(6))
    plant_context = scene.plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    scene.plant.SetPositions(plant_context, scene.panda, q0)
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(EPISODE_S)
    wall = time.perf_counter() - start
    return wall, scene.plant.GetPositions(plant_context, scene.panda).copy()


def profile_episode(task_name: str | Path = "peg", top: int = 12) -> dict:
    """cProfile of one full episode: where the time goes.

    Returns ``{"task", "profiled_wall_s", "cpp_plant_and_framework_s",
    "python_callbacks_s", "callbacks": {system: {callback: {"calls", "cumulative_s"}}},
    "top_self_time": [[function, calls, self_s], ...]}``. ``cpp_plant_and_framework_s``
    is the self time of ``Simulator.AdvanceTo`` (the plant's steps, geometry and the
    framework's event dispatch, C++); ``python_callbacks_s`` the rest (Python systems
    and the pybind calls they make). A callback's cumulative time includes the
    upstream outputs it pulls (the controller's update evaluates the composer's and
    the extrapolator's outputs), and profiling inflates Python time about twofold:
    quote the wall-clock ``overhead_fraction`` of :func:`run` for the split.
    ``task_name`` is a task name or a task YAML path (a variant).
    """
    task = load_task(task_name)
    rlfd, X_WP_start = _build(task)
    simulator = _episode_simulator(rlfd, X_WP_start)
    profiler = cProfile.Profile()
    start = time.perf_counter()
    profiler.enable()
    simulator.AdvanceTo(EPISODE_S)
    profiler.disable()
    wall = time.perf_counter() - start
    stats = pstats.Stats(profiler).stats
    advance = [v for k, v in stats.items() if k[2].endswith("AdvanceTo>")]
    advance_self, advance_cum = (advance[0][2], advance[0][3]) if advance else (0.0, 0.0)
    callbacks: dict[str, dict] = {}
    for system, (filename, names) in _CALLBACKS.items():
        entries = {}
        for (path, _, func), (_, calls, _, cum, _) in stats.items():
            if path.endswith(os.sep + filename) and func in names:
                entries[func] = {"calls": int(calls), "cumulative_s": round(cum, 4)}
        callbacks[system] = entries
    ranked = sorted(stats.items(), key=lambda item: item[1][2], reverse=True)[:top]
    top_self = [
        [f"{os.path.basename(path)}:{line}({func})", int(v[1]), round(v[2], 4)]
        for (path, line, func), v in ranked
    ]
    return {
        "task": task.name,
        "profiled_wall_s": round(wall, 3),
        "cpp_plant_and_framework_s": round(advance_self, 3),
        "python_callbacks_s": round(advance_cum - advance_self, 3),
        "callbacks": callbacks,
        "top_self_time": top_self,
    }


def run(
    repeats: int = 3,
    tasks: list[str | Path] | None = None,
    profile_task: str | Path = "peg",
) -> dict:
    """Real-time factors of a 10 s zero-residual episode from the demo start, per task.

    ``tasks`` are task names or task YAML paths (variants; default: every shipped
    task); results are keyed by the task's name. A task with an incremental residual
    runs its integrator on a zero rate, so its episode is the same as its shipped
    task's and the difference in wall time is the integrator's cost.

    Returns ``{task: {"real_time_factor", "plant_real_time_factor",
    "overhead_fraction", "full_wall_s", "plant_wall_s", "replay_max_q_error_rad",
    "success", "distance_to_goal_m", "peak_contact_force_n"}, "profile": {...}}``:
    medians over ``repeats`` of the wall time of the complete diagram (t_full) and of
    the plant replaying the same torques (t_plant, see the module docstring);
    ``overhead_fraction = (t_full - t_plant) / t_plant``;
    ``python_floor_overhead_fraction`` is the same for the plant with the do-nothing
    Python probes of :mod:`rlfd_drake.bench.python_floor` (t_floor): the part of the
    overhead that is Drake's Python dispatch, not our systems' work. ``profile`` is
    :func:`profile_episode` of ``profile_task``.
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    results: dict[str, dict] = {}
    specs = [load_task(name) for name in (tasks if tasks is not None else list_tasks())]
    names = [task.name for task in specs]
    if not specs or len(set(names)) < len(names):
        raise ValueError(f"tasks: expected distinct tasks, got {names}")
    with _one_core():
        for task in specs:
            rlfd, X_WP_start = _build(task)
            times, torques, q0, q_end = _record_torques(rlfd, X_WP_start)
            full, plant, floor = [], [], []
            outcome: dict = {}
            replay_error = 0.0
            for _ in range(repeats):
                wall, outcome = _time_full(rlfd, X_WP_start)
                full.append(wall)
                wall, q_replay = _time_replay(task, rlfd, times, torques, q0)
                plant.append(wall)
                replay_error = float(np.max(np.abs(q_replay - q_end)))
                wall, _ = _time_replay(task, rlfd, times, torques, q0, python_probes=True)
                floor.append(wall)
            t_full, t_plant = statistics.median(full), statistics.median(plant)
            t_floor = statistics.median(floor)
            results[task.name] = {
                "real_time_factor": EPISODE_S / t_full,
                "plant_real_time_factor": EPISODE_S / t_plant,
                "overhead_fraction": (t_full - t_plant) / t_plant,
                "python_floor_overhead_fraction": (t_floor - t_plant) / t_plant,
                "full_wall_s": t_full,
                "plant_wall_s": t_plant,
                "python_floor_wall_s": t_floor,
                "replay_max_q_error_rad": replay_error,
                **outcome,
            }
        results["profile"] = profile_episode(profile_task)
    return results
