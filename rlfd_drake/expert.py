"""The scripted expert: a human-like demonstration of each task, recorded in simulation.

The expert knows where the fixture really is (the demonstration is recorded on the
nominal, error-free scene, as a human would see it). It moves the part frame P along
a smooth path: approach from the demo start to a pre-insertion pose above the goal
(minimum-jerk with a slight arc and mild, seeded variation in via points and timing),
a short pause to align, then a slow descent that ends a few mm below the goal so the
part is pushed home. The Panda follows the path with the Cartesian impedance
controller; what is recorded at 100 Hz is the part's ACTUAL pose (kinesthetic-style),
so contact effects are part of the demonstration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from rlfd_drake.demonstration import Demonstration
from rlfd_drake.diagram import MakeSceneControlModel, NominalGoal
from rlfd_drake.geometry import (
    quat_conjugate,
    quat_from_rotation_matrix,
    quat_from_rotation_vector,
    quat_log,
    quat_multiply,
    quat_normalize,
    quat_slerp,
)
from rlfd_drake.scene import AddRlfdScene, SceneConfig, SolvePandaIK
from rlfd_drake.systems.impedance import (
    CartesianImpedanceConfig,
    CartesianImpedanceController,
)
from rlfd_drake.tasks import TaskSpec


@dataclass(frozen=True)
class ExpertConfig:
    """Shape of the scripted demonstration (in the goal frame G, z up out of the hole).

    Attributes:
        start_offset_G_m: demo start relative to the goal, m.
        start_rotation_deg: demo start orientation relative to the goal: rotation
            vector in degrees (world axes).
        pre_insert_height_m: height of the pre-insertion pose above the fixture
            entrance, m.
        push_depth_m: how far below the goal the expert aims at the end, m.
        approach_s, pause_s, insert_s, hold_s: durations of the phases, s.
        variation_m: std of the via-point variation, m.
        timing_variation: relative std of the phase durations.
        record_period_s: recording period (100 Hz).
    """

    start_offset_G_m: tuple[float, float, float] = (-0.08, 0.06, 0.17)
    start_rotation_deg: tuple[float, float, float] = (0.0, 0.0, 20.0)
    pre_insert_height_m: float = 0.03
    push_depth_m: float = 0.004
    approach_s: float = 3.8
    pause_s: float = 0.6
    insert_s: float = 2.6
    hold_s: float = 0.5
    variation_m: float = 0.003
    timing_variation: float = 0.03
    record_period_s: float = 0.01

    def __post_init__(self) -> None:
        for name in ("approach_s", "pause_s", "insert_s", "hold_s", "record_period_s"):
            value = getattr(self, name)
            # pause_s and hold_s may be 0 (no pause, no hold); the moving phases may not.
            allow_zero = name in ("pause_s", "hold_s")
            if not np.isfinite(value) or value < 0.0 or (value == 0.0 and not allow_zero):
                kind = "a duration >= 0" if allow_zero else "a positive duration"
                raise ValueError(f"{name}: must be {kind} in s, got {value!r}")
        for name in ("pre_insert_height_m", "push_depth_m", "variation_m", "timing_variation"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0.0:
                raise ValueError(f"{name}: must be finite and >= 0, got {value!r}")


def minimum_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk profile 10 s^3 - 15 s^4 + 6 s^5 on s in [0, 1], and its derivative
    with respect to s. Returns (2, len(s))."""
    s = np.clip(s, 0.0, 1.0)
    value = 10 * s**3 - 15 * s**4 + 6 * s**5
    slope = 30 * s**2 - 60 * s**3 + 30 * s**4
    return np.stack([value, slope])


def expert_path(
    X_WGoal: RigidTransform,
    insertion_depth_m: float,
    config: ExpertConfig,
    rng: np.random.Generator,
    dt: float = 0.001,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The expert's commanded path of P, sampled every ``dt``; ``insertion_depth_m`` is
    the goal's depth below the fixture entrance.

    Returns: times (N,) s, positions (N, 3) m, quaternions (N, 4) wxyz, spatial
    velocities (N, 6) [w; v] (world).
    """
    R_WG = X_WGoal.rotation().matrix()
    p_goal = X_WGoal.translation()
    q_goal = quat_from_rotation_matrix(R_WG)
    z_G = R_WG[:, 2]
    jitter = config.variation_m * rng.standard_normal(3)
    p_start = p_goal + R_WG @ np.array(config.start_offset_G_m) + jitter
    q_start = quat_multiply(
        quat_from_rotation_vector(np.radians(config.start_rotation_deg)), q_goal
    )
    # The expert sees the hole: it lines up exactly above it before inserting.
    p_pre = p_goal + (insertion_depth_m + config.pre_insert_height_m) * z_G
    p_end = p_goal - config.push_depth_m * z_G
    # A human arcs over rather than moving in a straight line: lift the midpoint.
    arc = 0.04 * z_G + config.variation_m * rng.standard_normal(3)
    scale = 1.0 + config.timing_variation * rng.standard_normal(4)
    T1, T2, T3, T4 = np.array([config.approach_s, config.pause_s, config.insert_s, config.hold_s])
    T1, T2, T3, T4 = T1 * scale[0], T2 * scale[1], T3 * scale[2], T4 * scale[3]
    times = np.arange(0.0, T1 + T2 + T3 + T4 + 1e-9, dt)
    positions = np.empty((len(times), 3))
    velocities = np.zeros((len(times), 3))
    quats = np.empty((len(times), 4))
    omegas = np.zeros((len(times), 3))
    # Phase 1: approach (position with a sin-shaped arc; orientation slerp).
    m1 = times <= T1
    s, ds = minimum_jerk(times[m1] / T1)
    bump = np.sin(np.pi * s)
    dbump = np.pi * np.cos(np.pi * s) * ds
    positions[m1] = p_start + np.outer(s, p_pre - p_start) + np.outer(bump, arc)
    velocities[m1] = (np.outer(ds, p_pre - p_start) + np.outer(dbump, arc)) / T1
    quats[m1] = np.array([quat_slerp(q_start, q_goal, si) for si in s])
    # World angular velocity of a slerp: 2 log(q_goal conj(q_start)) * ds/dt.
    w_total = 2.0 * quat_log(quat_multiply(q_goal, quat_conjugate(q_start)))
    omegas[m1] = np.outer(ds / T1, w_total)
    # Phase 2: pause at the pre-insertion pose.
    m2 = (times > T1) & (times <= T1 + T2)
    positions[m2] = p_pre
    quats[m2] = q_goal
    # Phase 3: descend and push.
    m3 = (times > T1 + T2) & (times <= T1 + T2 + T3)
    s, ds = minimum_jerk((times[m3] - T1 - T2) / T3)
    positions[m3] = p_pre + np.outer(s, p_end - p_pre)
    velocities[m3] = np.outer(ds, p_end - p_pre) / T3
    quats[m3] = q_goal
    # Phase 4: hold.
    m4 = times > T1 + T2 + T3
    positions[m4] = p_end
    quats[m4] = q_goal
    return times, positions, quats, np.hstack([omegas, velocities])


def record_demonstration(
    task: TaskSpec, seed: int = 0, config: ExpertConfig | None = None
) -> Demonstration:
    """Runs the scripted expert on the nominal scene of ``task`` and records the part
    frame P at ``config.record_period_s``."""
    config = config if config is not None else ExpertConfig()
    rng = np.random.default_rng(seed)
    X_WGoal = NominalGoal(task)
    times, positions, quats, twists = expert_path(X_WGoal, task.fixture.depth_m, config, rng)

    builder = DiagramBuilder()
    scene = AddRlfdScene(builder, task, SceneConfig())
    plant = scene.plant
    control_plant = MakeSceneControlModel(scene)
    controller = builder.AddSystem(
        CartesianImpedanceController(control_plant, CartesianImpedanceConfig())
    )
    pose_source = builder.AddSystem(
        TrajectorySource(PiecewisePolynomial.FirstOrderHold(times, np.hstack([positions, quats]).T))
    )
    twist_source = builder.AddSystem(
        TrajectorySource(PiecewisePolynomial.FirstOrderHold(times, twists.T))
    )
    builder.Connect(pose_source.get_output_port(), controller.GetInputPort("X_WE_desired"))
    builder.Connect(twist_source.get_output_port(), controller.GetInputPort("V_WE_desired"))
    builder.Connect(
        plant.get_state_output_port(scene.panda), controller.GetInputPort("panda_state")
    )
    builder.Connect(controller.GetOutputPort("panda_torque"), plant.get_actuation_input_port())
    log = LogVectorOutput(plant.get_state_output_port(scene.panda), builder, config.record_period_s)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    X_WP0 = RigidTransform(RotationMatrix(Quaternion(quat_normalize(quats[0]))), positions[0])
    plant.SetPositions(plant_context, scene.panda, SolvePandaIK(scene, X_WP0))
    simulator.Initialize()
    simulator.AdvanceTo(times[-1])

    data = log.FindLog(context).data()
    sample_times = log.FindLog(context).sample_times()
    scratch = plant.CreateDefaultContext()
    out_p = np.empty((len(sample_times), 3))
    out_q = np.empty((len(sample_times), 4))
    for k in range(len(sample_times)):
        plant.SetPositions(scratch, scene.panda, data[:7, k])
        X_WP = scene.frame_P.CalcPoseInWorld(scratch)
        out_p[k] = X_WP.translation()
        out_q[k] = X_WP.rotation().ToQuaternion().wxyz()
    demo = Demonstration(sample_times - sample_times[0], out_p, out_q)
    demo.validate()
    miss = float(np.linalg.norm(out_p[-1] - X_WGoal.translation()))
    if miss > task.kappa_m:
        raise RuntimeError(
            f"the scripted expert did not insert the part on {task.name!r} "
            f"(final distance {miss:.4f} m > kappa {task.kappa_m} m); try another seed"
        )
    return demo
