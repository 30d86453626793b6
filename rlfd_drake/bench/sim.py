"""Speed and accuracy of the bare simulation (plant + scene graph), per task.

The arm is held by Drake's C++ ``InverseDynamicsController`` (joint-space PD with
gravity and Coriolis compensation, acceleration gains kp = 100 1/s^2, kd = 20 1/s,
i.e. critically damped at 10 rad/s), so the numbers measure the plant and contact,
not a Python controller. The rLfD diagram's Python systems come on top of this.

* ``run``: real-time factor in free motion (the part moving 5 cm above the fixture)
  and in contact (the part pressed on the hole edge 3 mm off axis; the PD target is
  the goal, 3 cm lower, so the arm keeps pushing, ~10-20 N), median of ``repeats``.
* ``time_step_study``: for plant steps of 0.5, 1, 2 and 4 ms: energy gain of the
  unactuated arm swinging under gravity (must be <= 0: joint damping only dissipates),
  joint-position drift from the 0.5 ms run, and for the part pushed onto the edge the
  penetration below the fixture top, the steady force ripple and the peak joint speed.

Measured on the 2-core dev machine (shared, so +-30 %), 2 ms, one thread: free motion
21-35x real time, part pressed on the edge 3.6-9x (peg 6x, peg_hard 3.6x, gear 9x,
rj45 3.8x). Contact costs more than with a plain box hole because the chamfered walls
are convex meshes (more contact-surface polygons for SAP).

Nothing is written to disk (``rlfd bench sim --json`` does that).
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.controllers import InverseDynamicsController
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from rlfd_drake.scene import (
    AddRlfdScene,
    CalcPartPose,
    FixturePoseInWorld,
    GoalPoseInWorld,
    Scene,
    SceneConfig,
    SolvePandaIK,
)
from rlfd_drake.tasks import TaskSpec, list_tasks, load_task

PD_KP = 100.0  # 1/s^2 (acceleration gain of the inverse-dynamics controller)
PD_KD = 20.0  # 1/s


@dataclass
class HeldScene:
    """A scene whose arm tracks a constant joint target (see module docstring)."""

    diagram: Diagram
    scene: Scene
    target: ConstantVectorSource
    controller: InverseDynamicsController | None

    def set_target(self, root_context: Context, q: np.ndarray) -> None:
        """Sets the joint target q (7,) rad (velocity target 0)."""
        value = np.concatenate([q, np.zeros(7)])
        self.target.get_mutable_source_value(
            self.target.GetMyMutableContextFromRoot(root_context)
        ).set_value(value)

    def plant_context(self, root_context: Context) -> Context:
        return self.scene.plant.GetMyMutableContextFromRoot(root_context)


def BuildHeldScene(
    task: TaskSpec,
    config: SceneConfig | None = None,
    fixture_error: RigidTransform | None = None,
    actuated: bool = True,
    kp: float = PD_KP,
    kd: float = PD_KD,
) -> HeldScene:
    """The rLfD scene with the arm held by an inverse-dynamics joint PD (``actuated``) or
    with zero actuation (``actuated=False``: the arm falls under gravity)."""
    builder = DiagramBuilder()
    scene = AddRlfdScene(builder, task, config, fixture_error)
    plant = scene.plant
    target = builder.AddSystem(ConstantVectorSource(np.zeros(14)))
    controller = None
    if actuated:
        controller = builder.AddSystem(
            InverseDynamicsController(plant, np.full(7, kp), np.zeros(7), np.full(7, kd), False)
        )
        builder.Connect(plant.get_state_output_port(scene.panda), controller.get_input_port(0))
        builder.Connect(target.get_output_port(), controller.get_input_port(1))
        builder.Connect(
            controller.get_output_port_control(), plant.get_actuation_input_port(scene.panda)
        )
    else:
        zero = builder.AddSystem(ConstantVectorSource(np.zeros(7)))
        builder.Connect(zero.get_output_port(), plant.get_actuation_input_port(scene.panda))
    return HeldScene(builder.Build(), scene, target, controller)


def _pose_in_fixture(scene: Scene, p_F: np.ndarray, yaw_deg: float = 0.0) -> RigidTransform:
    """X_WP for P at p_F (m) in F, with the goal orientation turned by ``yaw_deg`` about
    F's z."""
    default_context = scene.plant.CreateDefaultContext()
    X_WF = FixturePoseInWorld(scene, default_context)
    X_WGoal = GoalPoseInWorld(scene, default_context)
    R_WP = X_WGoal.rotation() @ RotationMatrix.MakeZRotation(np.radians(yaw_deg))
    return RigidTransform(R_WP, X_WF @ np.asarray(p_F, dtype=float))


def press_setup(
    held: HeldScene,
    lateral_m: float,
    start_height_m: float = 0.003,
    push_depth_m: float = 0.005,
    yaw_deg: float = 0.0,
) -> tuple[Context, np.ndarray, np.ndarray]:
    """A root context with P ``start_height_m`` above the entrance, ``lateral_m`` off
    axis (along F's x), turned by ``yaw_deg`` about F's z, at rest, and the joint
    target at the goal depth plus ``push_depth_m`` (so the PD pushes down, about 3 N at
    the goal and 10-40 N when stopped at the entrance). Returns (context, q_start,
    q_target)."""
    scene = held.scene
    depth = scene.task.fixture.depth_m
    X_start = _pose_in_fixture(scene, [lateral_m, 0.0, start_height_m], yaw_deg)
    q_start = SolvePandaIK(scene, X_start)
    X_target = _pose_in_fixture(scene, [lateral_m, 0.0, -depth - push_depth_m], yaw_deg)
    q_target = SolvePandaIK(scene, X_target, q_start)
    context = held.diagram.CreateDefaultContext()
    scene.plant.SetPositions(held.plant_context(context), q_start)
    held.set_target(context, q_target)
    return context, q_start, q_target


def p_FP(held: HeldScene, context: Context) -> np.ndarray:
    """Position of P in the true fixture frame F (3,), m."""
    scene = held.scene
    plant_context = held.plant_context(context)
    X_WP = CalcPartPose(scene.plant, plant_context, scene)
    return FixturePoseInWorld(scene, plant_context).inverse() @ X_WP.translation()


def _real_time_factor(held: HeldScene, context: Context, sim_time_s: float) -> float:
    simulator = Simulator(held.diagram, context)
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(context.get_time() + sim_time_s)
    return sim_time_s / (time.perf_counter() - start)


def run(repeats: int = 3, sim_time_s: float = 2.0) -> dict:
    """Real-time factors per task: {task: {"time_step", "real_time_factor_free",
    "real_time_factor_contact", "contact_hydroelastic_surfaces"}}, median of
    ``repeats`` runs of ``sim_time_s`` simulated seconds, one thread.

    Free: P starts 5 cm above the entrance and the PD target is 5 cm higher (a 5 cm
    move then holding). Contact: P starts 3 mm above the entrance, 3 mm off axis, and
    the PD pushes it onto the edge.
    """
    results = {}
    for name in list_tasks():
        task = load_task(name, check_demo=False)
        held = BuildHeldScene(task)
        scene = held.scene
        free, contact = [], []
        surfaces = 0
        for _ in range(repeats):
            context = held.diagram.CreateDefaultContext()
            q0 = SolvePandaIK(scene, _pose_in_fixture(scene, [0.0, 0.0, 0.05]))
            q1 = SolvePandaIK(scene, _pose_in_fixture(scene, [0.0, 0.0, 0.10]), q0)
            scene.plant.SetPositions(held.plant_context(context), q0)
            held.set_target(context, q1)
            free.append(_real_time_factor(held, context, sim_time_s))
            context, _, _ = press_setup(held, lateral_m=0.003)
            contact.append(_real_time_factor(held, context, sim_time_s))
            results_port = scene.plant.get_contact_results_output_port()
            surfaces = results_port.Eval(held.plant_context(context)).num_hydroelastic_contacts()
        results[name] = {
            "time_step": scene.config.time_step_s,
            "real_time_factor_free": statistics.median(free),
            "real_time_factor_contact": statistics.median(contact),
            "contact_hydroelastic_surfaces": surfaces,
        }
    return results


def _energy(held: HeldScene, context: Context) -> float:
    plant = held.scene.plant
    pc = held.plant_context(context)
    return plant.CalcKineticEnergy(pc) + plant.CalcPotentialEnergy(pc)


def time_step_study(
    task_name: str = "peg", time_steps_s: tuple[float, ...] = (0.0005, 0.001, 0.002, 0.004)
) -> dict:
    """Accuracy against the plant step (see module docstring). Returns
    {"task": ..., "steps": {step_ms: {...}}} with, per step:

    * ``free_energy_gain_j``: max over 1 s of (E(t) - E(0)), E = kinetic + potential
      energy of the unactuated arm falling from home, J (<= 0 means no numerical
      energy gain; joint damping dissipates).
    * ``free_q_error_rad``: |q(1 s) - q_ref(1 s)|_inf against the smallest step.
    * ``edge_min_height_mm``: lowest height of P above the fixture top while pushed
      onto the edge 3 mm off axis for 1 s, mm (negative = penetration / tunnelling).
    * ``edge_height_ripple_mm``: peak-to-peak height of P over the last 0.5 s, mm.
    * ``edge_max_joint_speed_rad_s``: peak joint speed during the push.
    * ``real_time_factor_contact``: speed of the pushing run.
    """
    task = load_task(task_name, check_demo=False)
    steps: dict[str, dict] = {}
    q_ref = None
    for h in sorted(time_steps_s):
        config = SceneConfig(time_step_s=h)
        # Free fall of the unactuated arm.
        held = BuildHeldScene(task, config, actuated=False)
        context = held.diagram.CreateDefaultContext()
        simulator = Simulator(held.diagram, context)
        simulator.Initialize()
        e0 = _energy(held, context)
        gain = 0.0
        for t in np.arange(1, 21) * 0.05:
            simulator.AdvanceTo(t)
            gain = max(gain, _energy(held, context) - e0)
        q_end = held.scene.plant.GetPositions(held.plant_context(context))
        if q_ref is None:
            q_ref = q_end
        # Pushed onto the edge.
        held = BuildHeldScene(task, config)
        context, _, _ = press_setup(held, lateral_m=0.003)
        simulator = Simulator(held.diagram, context)
        simulator.Initialize()
        heights, speeds = [], []
        start = time.perf_counter()
        for t in np.arange(1, 101) * 0.01:
            simulator.AdvanceTo(t)
            heights.append(p_FP(held, context)[2])
            v = held.scene.plant.GetVelocities(held.plant_context(context))
            speeds.append(np.max(np.abs(v)))
        rtf = 1.0 / (time.perf_counter() - start)
        steps[f"{1e3 * h:g}"] = {
            "free_energy_gain_j": float(gain),
            "free_q_error_rad": float(np.max(np.abs(q_end - q_ref))),
            "edge_min_height_mm": 1e3 * float(min(heights)),
            "edge_height_ripple_mm": 1e3 * float(np.ptp(heights[50:])),
            "edge_max_joint_speed_rad_s": float(max(speeds)),
            "real_time_factor_contact": rtf,
        }
    return {"task": task_name, "steps": steps}
