"""Drawing an rLfD episode in Meshcat, and the diagram as Graphviz.

What an episode shows besides the scene (the robot, part, fixture and table, the
hydroelastic contact surfaces and forces of ``ContactVisualizer``):

    rlfd/dmp_plan       the DMP's open-loop plan from the episode's start (polyline)
    rlfd/setpoint       the residual-corrected set-point X_WE_desired (triad, animated)
    rlfd/dmp_setpoint   the DMP's own set-point X_WE_base (translucent triad, animated)
    rlfd/goal_nominal   the goal the demonstration saw (what the DMP aims at)
    rlfd/goal_true      the goal where the fixture really is (unseen by the DMP)

The paths are relative, so Meshcat puts them under its ``/drake`` prefix. The triads
are moved by :class:`rlfd_drake.systems.setpoint_triad.SetpointTriad` (added by
``BuildRlfdDiagram`` when given a Meshcat); the plan is drawn by ``SetEpisodeStart``.

The functions taking a Meshcat only draw; :func:`dmp_plan_positions` and the
``static_html_*`` readers of saved replays are pure; :func:`diagram_svg` renders only
where the optional ``pydot`` package and Graphviz's ``dot`` are installed.
"""

from __future__ import annotations

import base64
import math
import re
import warnings
from dataclasses import dataclass, field

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import Cylinder, Meshcat, Rgba
from pydrake.math import RigidTransform, RotationMatrix

from rlfd_drake.dmp import CartesianDmp, rollout

__all__ = [
    "BASE_SETPOINT_PATH",
    "DMP_PLAN_PATH",
    "NOMINAL_GOAL_PATH",
    "SETPOINT_PATH",
    "TRUE_GOAL_PATH",
    "EpisodeViewConfig",
    "TriadStyle",
    "AddTriad",
    "DrawDmpPlan",
    "DrawGoals",
    "DrawPolyline",
    "LookAtWorkCell",
    "SetTriadPose",
    "diagram_svg",
    "dmp_plan_positions",
    "pose_vector_to_rigid_transform",
    "static_html_animated_paths",
    "static_html_commands",
    "static_html_objects",
]

DMP_PLAN_PATH = "rlfd/dmp_plan"
SETPOINT_PATH = "rlfd/setpoint"
BASE_SETPOINT_PATH = "rlfd/dmp_setpoint"
NOMINAL_GOAL_PATH = "rlfd/goal_nominal"
TRUE_GOAL_PATH = "rlfd/goal_true"

# Axis colours of a triad: x red, y green, z blue (Drake's and RViz's convention).
_AXIS_RGB = {"x": (0.9, 0.1, 0.1), "y": (0.1, 0.8, 0.1), "z": (0.1, 0.2, 0.95)}


@dataclass(frozen=True)
class TriadStyle:
    """Size and opacity of a coordinate triad.

    Attributes:
        length_m: length of each axis, m.
        radius_m: radius of each axis, m.
        opacity: in (0, 1].
    """

    length_m: float = 0.06
    radius_m: float = 0.0015
    opacity: float = 1.0

    def __post_init__(self) -> None:
        for name in ("length_m", "radius_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive number of metres, got {value}")
        if not 0.0 < self.opacity <= 1.0:
            raise ValueError(f"opacity must be in (0, 1], got {self.opacity}")


@dataclass(frozen=True)
class EpisodeViewConfig:
    """How an episode is drawn on top of the scene.

    Attributes:
        setpoint: triad of the residual-corrected set-point X_WE_desired.
        base_setpoint: triad of the DMP's set-point X_WE_base (translucent, slightly
            smaller, so that the residual shows as the gap between the two).
        goal: triads of the nominal and the true goal.
        triad_period_s: how often the set-point triads are moved, s (32 Hz: about
            every other frame of Meshcat's 64 fps recordings).
        plan_rgba: colour of the DMP plan (r, g, b, a) in [0, 1].
        plan_line_width_px: width of the plan's line (WebGL may draw 1 px regardless).
        plan_dt_s: sampling period of the drawn plan, s.
    """

    setpoint: TriadStyle = field(default_factory=TriadStyle)
    base_setpoint: TriadStyle = field(
        default_factory=lambda: TriadStyle(length_m=0.045, radius_m=0.0012, opacity=0.35)
    )
    goal: TriadStyle = field(
        default_factory=lambda: TriadStyle(length_m=0.03, radius_m=0.001, opacity=0.6)
    )
    triad_period_s: float = 1.0 / 32.0
    plan_rgba: tuple[float, float, float, float] = (0.1, 0.45, 1.0, 1.0)
    plan_line_width_px: float = 3.0
    plan_dt_s: float = 0.02

    def __post_init__(self) -> None:
        for name in ("triad_period_s", "plan_dt_s", "plan_line_width_px"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be positive, got {value}")
        rgba = np.asarray(self.plan_rgba, dtype=float)
        if rgba.shape != (4,) or np.any(rgba < 0.0) or np.any(rgba > 1.0):
            raise ValueError(f"plan_rgba must be 4 numbers in [0, 1], got {self.plan_rgba}")


def pose_vector_to_rigid_transform(x: np.ndarray) -> RigidTransform:
    """``[p (3) m, q (4) wxyz]`` -> RigidTransform (the quaternion is normalised)."""
    x = np.asarray(x, dtype=float).reshape(-1)
    if x.shape != (7,) or not np.all(np.isfinite(x)):
        raise ValueError(f"a pose vector must be 7 finite numbers [p; q_wxyz], got {x}")
    norm = np.linalg.norm(x[3:])
    if norm < 1e-9:
        raise ValueError(f"the quaternion of a pose vector must be non-zero, got {x[3:]}")
    return RigidTransform(Quaternion(x[3:] / norm), x[:3])


# --------------------------------------------------------------------------------------
# Drawing.
# --------------------------------------------------------------------------------------
def AddTriad(meshcat: Meshcat, path: str, style: TriadStyle | None = None) -> None:
    """Adds a coordinate triad (three cylinders: x red, y green, z blue) at ``path``;
    move it with :func:`SetTriadPose`. Replaces whatever was at ``path``."""
    style = style if style is not None else TriadStyle()
    half = 0.5 * style.length_m
    # A Cylinder's axis is its z axis: turn it onto each axis and shift it by half its
    # length, so the triad's origin is the frame's origin.
    placements = {
        "x": RigidTransform(RotationMatrix.MakeYRotation(math.pi / 2), [half, 0.0, 0.0]),
        "y": RigidTransform(RotationMatrix.MakeXRotation(math.pi / 2), [0.0, half, 0.0]),
        "z": RigidTransform([0.0, 0.0, half]),
    }
    for axis, X_TA in placements.items():
        axis_path = f"{path}/{axis}-axis"
        meshcat.SetObject(
            axis_path,
            Cylinder(style.radius_m, style.length_m),
            Rgba(*_AXIS_RGB[axis], style.opacity),
        )
        meshcat.SetTransform(axis_path, X_TA)


def SetTriadPose(
    meshcat: Meshcat,
    path: str,
    X_WT: RigidTransform,
    time_in_recording: float | None = None,
) -> None:
    """Moves the triad at ``path`` to ``X_WT`` (also into the recording at
    ``time_in_recording``, s, if Meshcat is recording)."""
    meshcat.SetTransform(path, X_WT, time_in_recording)


def DrawPolyline(
    meshcat: Meshcat,
    path: str,
    positions: np.ndarray,
    rgba: tuple[float, float, float, float] = (0.1, 0.1, 0.1, 1.0),
    line_width_px: float = 2.0,
) -> None:
    """Draws the points ``positions`` (N, 3), m, world frame, joined by straight lines."""
    positions = np.asarray(positions, dtype=float)
    if positions.ndim != 2 or positions.shape[1] != 3 or len(positions) < 2:
        raise ValueError(f"positions must have shape (N >= 2, 3), got {positions.shape}")
    if not np.all(np.isfinite(positions)):
        raise ValueError("positions must be finite")
    meshcat.SetLine(path, np.asfortranarray(positions.T), line_width_px, Rgba(*rgba))


def dmp_plan_positions(
    dmp_model: CartesianDmp,
    X_WP_start: RigidTransform,
    duration_s: float | None = None,
    dt_s: float = 0.02,
) -> np.ndarray:
    """The DMP's open-loop plan from ``X_WP_start`` (rest) to its goal: positions
    (N, 3), m, every ``dt_s`` over ``duration_s`` (default the DMP's tau)."""
    _, positions, _, _, _ = rollout(
        dmp_model,
        start_position=X_WP_start.translation(),
        start_quat=X_WP_start.rotation().ToQuaternion().wxyz(),
        dt=dt_s,
        duration=duration_s,
    )
    return positions


def DrawDmpPlan(
    meshcat: Meshcat,
    dmp_model: CartesianDmp,
    X_WP_start: RigidTransform,
    duration_s: float | None = None,
    config: EpisodeViewConfig | None = None,
) -> np.ndarray:
    """Draws the DMP's plan from ``X_WP_start`` at :data:`DMP_PLAN_PATH`; returns its
    positions (N, 3), m."""
    config = config if config is not None else EpisodeViewConfig()
    positions = dmp_plan_positions(dmp_model, X_WP_start, duration_s, config.plan_dt_s)
    DrawPolyline(meshcat, DMP_PLAN_PATH, positions, config.plan_rgba, config.plan_line_width_px)
    return positions


def DrawGoals(
    meshcat: Meshcat,
    X_WGoal_nominal: RigidTransform,
    X_WGoal_true: RigidTransform,
    config: EpisodeViewConfig | None = None,
) -> None:
    """Triads at the nominal goal (what the demonstration saw) and the true goal (where
    the fixture really is): their offset is the fixture's calibration error."""
    config = config if config is not None else EpisodeViewConfig()
    for path, X_WG in ((NOMINAL_GOAL_PATH, X_WGoal_nominal), (TRUE_GOAL_PATH, X_WGoal_true)):
        AddTriad(meshcat, path, config.goal)
        meshcat.SetTransform(path, X_WG)


def LookAtWorkCell(meshcat: Meshcat, X_WGoal: RigidTransform) -> None:
    """Points Meshcat's camera at the arm and the fixture (Meshcat's default view shows
    the whole floor, with the robot small in the middle). Saved replays keep it."""
    p_goal = X_WGoal.translation()
    # Half-way between the arm's base (the world origin) and the goal, seen from the
    # front right, slightly above.
    target = np.array([0.5 * p_goal[0], 0.5 * p_goal[1], p_goal[2] + 0.15])
    meshcat.SetCameraPose(target + np.array([0.95, -1.05, 0.55]), target)


# --------------------------------------------------------------------------------------
# Diagram pictures and saved HTML.
# --------------------------------------------------------------------------------------
def diagram_svg(graphviz_dot: str) -> str | None:
    """SVG of a Graphviz ``dot`` text (e.g. ``diagram.GetGraphvizString(max_depth=1)``),
    or None when it cannot be rendered here: rendering needs the ``pydot`` package and
    Graphviz's ``dot`` program, neither of which the project requires."""
    with warnings.catch_warnings():
        # pydot's parser warns about pyparsing's renamed methods: not our users' concern.
        warnings.simplefilter("ignore", DeprecationWarning)
        try:
            import pydot

            graphs = pydot.graph_from_dot_data(graphviz_dot)
            if not graphs:
                return None
            svg = graphs[0].create_svg()
        except Exception:  # noqa: BLE001 - no pydot, no `dot`, or pydot's own errors
            return None
    return svg.decode() if isinstance(svg, bytes) else str(svg)


_DATA_URL = re.compile(r"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)")
_COMMAND_TYPE = re.compile(rb"type.(set_[a-z_]+)")
_SCENE_PATH = re.compile(rb"/drake/[A-Za-z0-9_/+.\-]+")


def static_html_commands(html: str) -> list[tuple[str, bytes]]:
    """The Meshcat commands embedded in a page from ``Meshcat.StaticHtml()``, in order:
    (type, msgpack bytes), type one of set_object, set_transform, set_property,
    set_animation (what a browser replays without a server)."""
    commands = []
    for chunk in _DATA_URL.findall(html):
        data = base64.b64decode(chunk)
        kind = _COMMAND_TYPE.search(data[:32])
        commands.append((kind.group(1).decode() if kind else "unknown", data))
    return commands


def static_html_objects(html: str) -> dict[str, int]:
    """Paths given an object (geometry) in a ``StaticHtml()`` page, each with the size of
    its set_object command, bytes: a mesh weighs kilobytes to megabytes."""
    sizes: dict[str, int] = {}
    for kind, data in static_html_commands(html):
        path = _SCENE_PATH.search(data) if kind == "set_object" else None
        if path is not None:
            name = path.group(0).decode()
            sizes[name] = max(sizes.get(name, 0), len(data))
    return sizes


def static_html_animated_paths(html: str) -> set[str]:
    """Paths with tracks in the recorded animation of a ``StaticHtml()`` page."""
    return {
        match.group(0).decode()
        for kind, data in static_html_commands(html)
        if kind == "set_animation"
        for match in _SCENE_PATH.finditer(data)
    }
