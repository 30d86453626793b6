"""Demonstration by teleoperation: a person drives the part frame P from Meshcat
sliders through the Cartesian impedance controller, and P's actual pose is recorded at
100 Hz (kinesthetic-style, as the scripted expert records: contact shows in the data).

The sliders give a 6-D offset from the start pose: x, y, z (m, world axes) and roll,
pitch, yaw (deg in the GUI, rad in code) of a rotation applied in the world frame about
P's origin (``R_WP = R_offset R_WP_start``, as ``diagram.PoseFromOffset``). The
controller's set-point moves towards the commanded pose at no more than
``max_speed_m_s`` / ``max_angular_speed_rad_s``, so a slider dragged across its range
does not kick the arm. Recording ends at the "Stop recording" button or after
``duration_s``.

Headless use (tests, scripts): pass ``slider_source`` (time s -> offset (6,)) and
optionally ``stop_source`` (time s -> bool) to :func:`record_teleop_demonstration`
instead of a Meshcat; the same loop runs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import Meshcat
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from rlfd_drake.demonstration import DEFAULT_MIN_SAMPLES, Demonstration
from rlfd_drake.diagram import MakeSceneControlModel, NominalGoal
from rlfd_drake.expert import ExpertConfig
from rlfd_drake.geometry import (
    quat_conjugate,
    quat_from_rotation_vector,
    quat_multiply,
    quat_normalize,
    quat_slerp,
    rotation_vector_from_quat,
)
from rlfd_drake.scene import AddRlfdScene, SceneConfig, SolvePandaIK
from rlfd_drake.systems.impedance import (
    CartesianImpedanceConfig,
    CartesianImpedanceController,
)
from rlfd_drake.tasks import TaskSpec
from rlfd_drake.view import SETPOINT_PATH, AddTriad, SetTriadPose

__all__ = [
    "SLIDER_NAMES",
    "STOP_BUTTON",
    "MeshcatTeleopSource",
    "TeleopConfig",
    "TeleopSession",
    "AddTeleopControls",
    "offset_pose",
    "record_teleop_demonstration",
    "step_towards",
    "teleop_start_pose",
]

#: Meshcat slider labels, in the order of the 6-D offset.
SLIDER_NAMES = ("x (m)", "y (m)", "z (m)", "roll (deg)", "pitch (deg)", "yaw (deg)")
#: Meshcat button that ends the recording.
STOP_BUTTON = "Stop recording"

#: What the sliders say over time: time (s) -> offset (6,) [dx, dy, dz (m), roll, pitch, yaw (rad)].
SliderSource = Callable[[float], np.ndarray]
#: A stop source: time (s) -> True to end the recording.
StopSource = Callable[[float], bool]


@dataclass(frozen=True)
class TeleopConfig:
    """A teleoperation session.

    Attributes:
        duration_s: longest recording, s (the stop button may end it earlier).
        record_period_s: recording period (100 Hz, as the scripted expert's); the
            commands are read and the set-point updated at the same period.
        max_speed_m_s: fastest set-point translation, m/s.
        max_angular_speed_rad_s: fastest set-point rotation, rad/s.
        slider_range_m: translation sliders span +- this, m.
        slider_range_deg: rotation sliders span +- this, deg.
        slider_step_m, slider_step_deg: slider resolution.
        realtime_rate: pace of the simulation relative to the wall clock (1 for a
            person at the sliders; 0 = as fast as possible, for scripted sessions).
    """

    duration_s: float = 60.0
    record_period_s: float = 0.01
    max_speed_m_s: float = 0.1
    max_angular_speed_rad_s: float = 0.5
    slider_range_m: float = 0.25
    slider_range_deg: float = 60.0
    slider_step_m: float = 0.001
    slider_step_deg: float = 0.5
    realtime_rate: float = 1.0

    def __post_init__(self) -> None:
        for name in (
            "duration_s",
            "record_period_s",
            "max_speed_m_s",
            "max_angular_speed_rad_s",
            "slider_range_m",
            "slider_range_deg",
            "slider_step_m",
            "slider_step_deg",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        if not (math.isfinite(self.realtime_rate) and self.realtime_rate >= 0.0):
            raise ValueError(f"realtime_rate must be >= 0, got {self.realtime_rate}")


@dataclass
class TeleopSession:
    """What a teleoperation session recorded.

    Attributes:
        demonstration: P's actual pose every ``record_period_s`` (times from 0).
        setpoint_positions: (N, 3) the controller's set-point at the same times, m.
        setpoint_quats: (N, 4) wxyz, the set-point's orientation at the same times.
        stopped_by: "button" (the stop button or ``stop_source``) or "duration".
    """

    demonstration: Demonstration
    setpoint_positions: np.ndarray
    setpoint_quats: np.ndarray
    stopped_by: str


# --------------------------------------------------------------------------------------
# Pure maths.
# --------------------------------------------------------------------------------------
def _as_offset(offset: np.ndarray) -> np.ndarray:
    value = np.asarray(offset, dtype=float).reshape(-1)
    if value.shape != (6,) or not np.all(np.isfinite(value)):
        raise ValueError(
            f"a teleop command must be 6 finite numbers [dx, dy, dz, roll, pitch, yaw], "
            f"got {offset!r}"
        )
    return value


def offset_pose(
    p_start: np.ndarray, q_start: np.ndarray, offset: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The pose commanded by ``offset`` = [dx, dy, dz (m, world), roll, pitch, yaw
    (rad)] from the start ``p_start`` (3,) m, ``q_start`` (4,) wxyz: position
    ``p_start + d``, orientation ``R_rpy o q_start`` (world frame). Returns (p, q)."""
    offset = _as_offset(offset)
    R = RollPitchYaw(offset[3:]).ToRotationMatrix()
    q_offset = R.ToQuaternion().wxyz()
    q = quat_normalize(quat_multiply(q_offset, np.asarray(q_start, dtype=float)))
    return np.asarray(p_start, dtype=float) + offset[:3], q


def step_towards(
    p: np.ndarray,
    q: np.ndarray,
    p_target: np.ndarray,
    q_target: np.ndarray,
    max_step_m: float,
    max_step_rad: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Moves the pose (p (3,) m, q (4,) wxyz) towards the target by at most
    ``max_step_m`` in translation and ``max_step_rad`` in rotation (along the straight
    line and the shortest arc). Returns the new (p, q)."""
    p, p_target = np.asarray(p, dtype=float), np.asarray(p_target, dtype=float)
    gap = p_target - p
    distance = float(np.linalg.norm(gap))
    p_new = p_target if distance <= max_step_m else p + gap * (max_step_m / distance)
    angle = float(
        np.linalg.norm(rotation_vector_from_quat(quat_multiply(q_target, quat_conjugate(q))))
    )
    s = 1.0 if angle <= max_step_rad else max_step_rad / angle
    return p_new, quat_normalize(quat_slerp(q, q_target, s))


def teleop_start_pose(task: TaskSpec, expert: ExpertConfig | None = None) -> RigidTransform:
    """Where a teleoperated demonstration starts: the scripted expert's start (above and
    beside the nominal goal, turned by its start rotation), without its random
    variation."""
    expert = expert if expert is not None else ExpertConfig()
    X_WGoal = NominalGoal(task)
    R_WG = X_WGoal.rotation().matrix()
    p_start = X_WGoal.translation() + R_WG @ np.asarray(expert.start_offset_G_m, dtype=float)
    q_goal = X_WGoal.rotation().ToQuaternion().wxyz()
    q_start = quat_multiply(
        quat_from_rotation_vector(np.radians(expert.start_rotation_deg)), q_goal
    )
    return RigidTransform(Quaternion(quat_normalize(q_start)), p_start)


# --------------------------------------------------------------------------------------
# Meshcat controls.
# --------------------------------------------------------------------------------------
def AddTeleopControls(meshcat: Meshcat, config: TeleopConfig | None = None) -> None:
    """Adds the six offset sliders (:data:`SLIDER_NAMES`, at zero) and the stop button
    (:data:`STOP_BUTTON`) to Meshcat's control panel, replacing earlier ones."""
    config = config if config is not None else TeleopConfig()
    for name in SLIDER_NAMES:
        meshcat.DeleteSlider(name, strict=False)
    meshcat.DeleteButton(STOP_BUTTON, strict=False)
    for name in SLIDER_NAMES[:3]:
        r, step = config.slider_range_m, config.slider_step_m
        meshcat.AddSlider(name, -r, r, step, 0.0)
    for name in SLIDER_NAMES[3:]:
        r, step = config.slider_range_deg, config.slider_step_deg
        meshcat.AddSlider(name, -r, r, step, 0.0)
    meshcat.AddButton(STOP_BUTTON)


class MeshcatTeleopSource:
    """Reads the teleop controls of :func:`AddTeleopControls`: calling it gives the
    sliders' offset (6,) [m, m, m, rad, rad, rad]; :meth:`stop_requested` is True once
    the stop button has been clicked (since the controls were added)."""

    def __init__(self, meshcat: Meshcat) -> None:
        missing = [n for n in SLIDER_NAMES if n not in meshcat.GetSliderNames()]
        if missing or STOP_BUTTON not in meshcat.GetButtonNames():
            raise ValueError(
                f"Meshcat lacks the teleop controls {missing or [STOP_BUTTON]}; "
                "call AddTeleopControls(meshcat) first"
            )
        self._meshcat = meshcat

    def __call__(self, t: float) -> np.ndarray:
        values = np.array([self._meshcat.GetSliderValue(name) for name in SLIDER_NAMES])
        values[3:] = np.radians(values[3:])
        return values

    def stop_requested(self, t: float) -> bool:
        return self._meshcat.GetButtonClicks(STOP_BUTTON) > 0


# --------------------------------------------------------------------------------------
# The session.
# --------------------------------------------------------------------------------------
def record_teleop_demonstration(
    task: TaskSpec,
    slider_source: SliderSource | None = None,
    stop_source: StopSource | None = None,
    config: TeleopConfig | None = None,
    meshcat: Meshcat | None = None,
    X_WP_start: RigidTransform | None = None,
) -> TeleopSession:
    """Runs a teleoperation session on the nominal scene of ``task`` and records P.

    Args:
        task: the task (its scene without fixture error, as a demonstrator sees it).
        slider_source: time (s) -> offset (6,) from the start pose; default the
            Meshcat sliders (``meshcat`` must then hold :func:`AddTeleopControls`).
        stop_source: time (s) -> True to stop; default the Meshcat stop button when
            reading the sliders, else never (the session lasts ``duration_s``).
        config: timing, speed limits and slider ranges (default TeleopConfig()).
        meshcat: if given, the scene, contact surfaces and the set-point (a triad at
            ``view.SETPOINT_PATH``) are drawn live.
        X_WP_start: start pose of P (default :func:`teleop_start_pose`).

    Returns:
        The session: the demonstration (validated) and the set-points.

    Raises:
        ValueError: neither ``slider_source`` nor ``meshcat``; a malformed command;
            a session shorter than a DMP can be fitted on (70 samples).
        RuntimeError: the simulator failed (e.g. the part was pushed through the
            fixture) or no arm configuration reaches the start pose.
    """
    config = config if config is not None else TeleopConfig()
    if slider_source is None:
        if meshcat is None:
            raise ValueError("record_teleop_demonstration needs a slider_source or a meshcat")
        sliders = MeshcatTeleopSource(meshcat)
        slider_source = sliders
        if stop_source is None:
            stop_source = sliders.stop_requested
    X_WP_start = X_WP_start if X_WP_start is not None else teleop_start_pose(task)

    builder = DiagramBuilder()
    scene = AddRlfdScene(builder, task, SceneConfig())
    plant = scene.plant
    control_plant = MakeSceneControlModel(scene)
    controller = builder.AddNamedSystem(
        "impedance", CartesianImpedanceController(control_plant, CartesianImpedanceConfig())
    )
    builder.Connect(
        plant.get_state_output_port(scene.panda), controller.GetInputPort("panda_state")
    )
    builder.Connect(controller.GetOutputPort("panda_torque"), plant.get_actuation_input_port())
    builder.ExportInput(controller.GetInputPort("X_WE_desired"), "X_WE_desired")
    builder.ExportInput(controller.GetInputPort("V_WE_desired"), "V_WE_desired")
    if meshcat is not None:
        from pydrake.multibody.meshcat import ContactVisualizer, ContactVisualizerParams
        from pydrake.visualization import AddDefaultVisualization

        AddDefaultVisualization(builder, meshcat)
        params = ContactVisualizerParams()
        params.force_threshold = 0.5
        ContactVisualizer.AddToBuilder(builder, plant, meshcat, params)
        AddTriad(meshcat, SETPOINT_PATH)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.set_target_realtime_rate(config.realtime_rate)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, scene.panda, SolvePandaIK(scene, X_WP_start))
    pose_port = diagram.GetInputPort("X_WE_desired")
    twist_port = diagram.GetInputPort("V_WE_desired")

    p_start = X_WP_start.translation()
    q_start = X_WP_start.rotation().ToQuaternion().wxyz()
    p_set, q_set = p_start.copy(), q_start.copy()
    pose_port.FixValue(context, np.concatenate([p_set, q_set]))
    twist_port.FixValue(context, np.zeros(6))
    simulator.Initialize()

    dt = config.record_period_s
    max_step_m = config.max_speed_m_s * dt
    max_step_rad = config.max_angular_speed_rad_s * dt
    n_max = int(math.floor(config.duration_s / dt + 1e-9))
    times, positions, quats, set_p, set_q = [], [], [], [], []
    stopped_by = "duration"
    for k in range(n_max + 1):
        t = k * dt
        X_WP = scene.frame_P.CalcPoseInWorld(plant_context)
        times.append(t)
        positions.append(X_WP.translation().copy())
        quats.append(X_WP.rotation().ToQuaternion().wxyz())
        set_p.append(p_set.copy())
        set_q.append(q_set.copy())
        if k == n_max:
            break
        if stop_source is not None and stop_source(t):
            stopped_by = "button"
            break
        p_target, q_target = offset_pose(p_start, q_start, slider_source(t))
        p_new, q_new = step_towards(p_set, q_set, p_target, q_target, max_step_m, max_step_rad)
        # Feed-forward twist [w; v] of the set-point over the coming step.
        w = rotation_vector_from_quat(quat_multiply(q_new, quat_conjugate(q_set))) / dt
        v = (p_new - p_set) / dt
        p_set, q_set = p_new, q_new
        pose_port.FixValue(context, np.concatenate([p_set, q_set]))
        twist_port.FixValue(context, np.concatenate([w, v]))
        if meshcat is not None:
            SetTriadPose(meshcat, SETPOINT_PATH, RigidTransform(Quaternion(q_set), p_set))
        simulator.AdvanceTo(t + dt)

    if len(times) < DEFAULT_MIN_SAMPLES:
        raise ValueError(
            f"the teleop session recorded {len(times)} samples ({times[-1]:.2f} s); a DMP "
            f"needs at least {DEFAULT_MIN_SAMPLES} ({(DEFAULT_MIN_SAMPLES - 1) * dt:.2f} s)"
        )
    demo = Demonstration(np.array(times), np.array(positions), np.array(quats)).validate()
    return TeleopSession(
        demonstration=demo,
        setpoint_positions=np.array(set_p),
        setpoint_quats=np.array(set_q),
        stopped_by=stopped_by,
    )
