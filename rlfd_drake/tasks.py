"""Insertion tasks: typed specs loaded from ``models/tasks/<name>.yaml`` and the
paper's perturbation distributions (Davchev et al. 2022, Sec. V).

Frames (monogram notation, X_AB = pose of B in A):

* W: world. H: ``panda_hand``. F: the fixture frame, origin at the centre of the
  fixture's insertion entrance (top of the hole / top of the shaft), z up.
* P: the part frame, origin at the centre of the part's insertion tip (bottom face of
  the peg, tip of the plug, bottom face of the gear at its hole), z up (the insertion
  direction reversed). With the hand pointing down, X_HP is a half turn about x plus
  an offset along the hand's z.
* The goal X_FP_goal is P fully inserted: the part bottom on the hole floor (peg, plug)
  or on the base plate (gear), i.e. P at ``(0, 0, -fixture.depth_m)`` in F, same
  orientation as F.

Start perturbations (``sample_start_offset``, ``evaluation_grid``) are offsets of the
start pose of P relative to the demonstration's start pose: the start position is
``p_demo + dp`` and the start orientation is ``dq * q_demo`` (world-frame rotation
applied on the left, wxyz quaternions, the same composition as the residual
``Q_f = Q_delta o Q_b``).

Fixture error (``sample_fixture_error``) is the calibration error the demonstration
did not see: the true fixture pose is ``X_WF_true = X_WF_nominal * X_err``. Without it
the DMP, which converges to the demonstrated goal, would succeed almost always or,
with a tight hole, fail on every approach the same way; a few millimetres and a degree
or so of error (the size of a camera / hand-eye calibration error) make the DMP alone
succeed only sometimes, which is the regime in which the paper's residual helps.

This module uses numpy only (no Drake), so it can be imported anywhere.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from rlfd_drake.geometry import quat_from_angle_axis, quat_multiply, rotation_vector_from_quat
from rlfd_drake.paths import models_dir, shipped_path

PART_KINDS = ("square_peg", "gear", "rj45_plug")
FIXTURE_KINDS = ("square_hole", "square_shaft", "rj45_socket")
# Which fixture each part goes into.
FIXTURE_FOR_PART = {"square_peg": "square_hole", "gear": "square_shaft", "rj45_plug": "rj45_socket"}
START_KINDS = ("uniform_box", "six_boxes", "orientation_bins")


# --------------------------------------------------------------------------------------
# Helpers (numpy only).
# --------------------------------------------------------------------------------------
def _random_unit_vector(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    while np.linalg.norm(v) < 1e-9:  # pragma: no cover - probability zero
        v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def rpy_deg_to_matrix(rpy_deg: tuple[float, float, float]) -> np.ndarray:
    """Rotation matrix (3, 3) of roll-pitch-yaw angles in degrees, R = Rz(y) Ry(p) Rx(r)
    (Drake's RollPitchYaw convention)."""
    r, p, y = np.radians(rpy_deg)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


# --------------------------------------------------------------------------------------
# Specs.
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PoseSpec:
    """A pose given as a position (m) and roll-pitch-yaw angles (deg, Drake's
    convention R = Rz(yaw) Ry(pitch) Rx(roll))."""

    position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def rotation_matrix(self) -> np.ndarray:
        """R (3, 3)."""
        return rpy_deg_to_matrix(self.rpy_deg)

    def matrix(self) -> np.ndarray:
        """Homogeneous transform (4, 4)."""
        T = np.eye(4)
        T[:3, :3] = self.rotation_matrix()
        T[:3, 3] = self.position_m
        return T


@dataclass(frozen=True)
class PartSpec:
    """The held part (one compliant-hydroelastic body).

    Attributes:
        kind: "square_peg", "gear" or "rj45_plug".
        size_m: outer size (x, y, z) in the part frame P, m; z is the length along the
            insertion axis (peg length, gear thickness, plug body length).
        mass_kg: mass, kg (uniform density over the collision boxes).
        hydroelastic_modulus_pa: compliant hydroelastic modulus, Pa. 1e8 Pa for the
            shipped pegs and gear (5e7 for the RJ-45 plug): measured with the peg pushed
            with ~35 N onto a 1-2 mm wide hole edge, 1e7 Pa lets it sink 0.7-1.3 mm (more
            than the clearances), 1e8 Pa 0.07-0.15 mm, at the same simulation speed.
        hunt_crossley_dissipation_s_per_m: Hunt-Crossley dissipation, s/m.
        friction: Coulomb friction coefficient (static = dynamic).
        hole_size_m: (gear only) the square hole (x, y), m; it goes through the gear.
        latch_size_m: (rj45 only) the latch protrusion on the +y face (x width,
            y thickness, z length), m.
        latch_offset_m: (rj45 only) distance from the tip to the start of the latch, m.
    """

    kind: str
    size_m: tuple[float, float, float]
    mass_kg: float
    hydroelastic_modulus_pa: float = 1.0e8
    hunt_crossley_dissipation_s_per_m: float = 5.0
    friction: float = 0.4
    hole_size_m: tuple[float, float] | None = None
    latch_size_m: tuple[float, float, float] | None = None
    latch_offset_m: float | None = None


@dataclass(frozen=True)
class FixtureSpec:
    """The fixture (rigid hydroelastic, welded to the world), frame F at the centre of
    its entrance, z up.

    The fit is defined by the part and the clearance: a hole's opening (or the gear's
    shaft) is the part's cross-section plus (minus) ``clearance_m``.

    Attributes:
        kind: "square_hole", "square_shaft" or "rj45_socket".
        clearance_m: total clearance, hole width minus part width, m (0.4 mm for the
            paper's physical peg: 0.2 mm per side when centred).
        chamfer_m: 45-degree chamfer at the entrance (hole edge or shaft top edge), m;
            0 for none.
        depth_m: hole depth or shaft height above the base plate, m. The goal puts
            the part bottom at this depth below F.
        wall_m: wall thickness around the opening (hole, socket) or the margin of the
            base plate around the shaft (gear), m. The same on all four sides so that
            the chamfered wall pieces meet on 45-degree mitres without gaps.
        floor_thickness_m: thickness of the hole floor / base plate, m.
        friction: Coulomb friction coefficient (static = dynamic).
    """

    kind: str
    clearance_m: float
    chamfer_m: float
    depth_m: float
    wall_m: float
    floor_thickness_m: float = 0.01
    friction: float = 0.4


@dataclass(frozen=True)
class StartDistributionSpec:
    """Distribution of the start-pose offset of P relative to the demonstration start.

    Kinds (paper, Sec. V):

    * ``uniform_box``: position uniform in +-``half_extent_m`` per axis (simulated peg
      tasks: 12 cm), orientation unchanged; evaluation grid has one bin.
    * ``six_boxes``: physical peg; ``n_eval`` starts drawn from six 3-D uniform boxes of
      half size ``box_half_extent_m``, box k centred at ``box_distances_m[k]`` along
      every axis with a random sign per axis ("centred at up to +-3 cm along each
      axis"); the bin index is k, so success can be plotted against the distance.
    * ``orientation_bins``: gear and RJ-45; ``n_bins`` bins of ``samples_per_bin``
      rotations about uniformly random unit axes, angles uniform within bin b's range
      [b, b + 1] * max_angle_deg / n_bins, plus a position offset uniform in
      +-``half_extent_m`` per axis (1 cm).
    """

    kind: str
    half_extent_m: float = 0.0
    box_distances_m: tuple[float, ...] = ()
    box_half_extent_m: float = 0.0
    n_bins: int = 0
    samples_per_bin: int = 0
    max_angle_deg: float = 0.0
    n_eval: int = 500


@dataclass(frozen=True)
class FixtureErrorSpec:
    """Unseen error of the fixture pose (see module docstring).

    Attributes:
        position_bound_m: uniform position error bound per axis of F, m.
        rotation_bound_deg: rotation about a uniformly random axis, angle uniform in
            [0, bound], deg.
        table_slope_deg: a constant tilt of the table (and the fixture on it) about
            ``table_slope_axis`` (world), deg; 1 deg on the paper's physical set-up.
        table_slope_axis: axis of the tilt, in F (level in its nominal pose, so this
            is also the world axis for the shipped tasks).
    """

    position_bound_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation_bound_deg: float = 0.0
    table_slope_deg: float = 0.0
    table_slope_axis: tuple[float, float, float] = (0.0, 1.0, 0.0)


@dataclass(frozen=True)
class TaskSpec:
    """One insertion task.

    Attributes:
        name: task name (the YAML file's stem for shipped tasks).
        description: one line for humans.
        part, fixture: see PartSpec, FixtureSpec.
        X_WFixture: nominal pose of F in the world (what the demonstration saw).
        grasp: X_HP, pose of the part frame P in the hand frame H.
        kappa_m: success threshold on |p_WP - p_WGoal|, m (reward 1[L2 <= kappa]).
        kappa_deg: optional success threshold on the rotation angle between P and the
            goal, deg (RJ-45: position AND orientation).
        start: start-pose perturbation distribution.
        fixture_error: unseen fixture pose error.
        force_limit_n: optional limit on the contact force magnitude, N (RJ-45's
            plastic tip breaks above it).
        demo: demonstration file, relative to models/ (e.g. "demos/peg.csv").
        episode_time_s: episode length, s (paper: 10 s).
        residual_activation_s: time at which the residual starts acting, s (paper,
            simulation: half the episode).
        residual_max_translation_m, residual_max_rotation_rad: what a residual action
            of 1 means for this task (m, rad): a few times its fixture error, so the
            policy's range and its exploration are on the scale of what it must
            correct (RJ-45's 30 N limit breaks under a 1 cm jiggle).
        residual_max_push_m: optional bound on how far a residual may move the
            set-point down (world -z, into the fixture), m (None = the translation
            range, as every other direction; 0 = the residual may lift and steer but
            never push: the DMP does the pushing). Residual composition only.
        rotational_stiffness_Nm_per_rad: optional rotational stiffness of the Cartesian
            impedance controller on this task, N m/rad (None = the controller's, 150):
            a softer wrist turns a rotation residual into a smaller contact torque.
        translational_stiffness_N_per_m: optional translational stiffness of the
            controller on this task, N/m (None = the controller's, 2000): the spring
            force with which a part resting on its fixture is pressed down.
        residual_period_s: period of the residual policy, s (paper: 0.1 s, 10 Hz).
            A shorter period lets the residual react sooner after contact (a
            deviation from the paper; models/tasks/variants/rj45_fast_residual.yaml).
        residual_filter_time_constant_s: optional time constant of a first-order
            low-pass filter on the residual action (None = none: each residual action
            steps the set-point), s.
        residual_rate_per_s: optional: the residual action is a rate, integrated into
            the held offset the composer adds (systems/residual_integrator.py), in
            residual units per second (None = the paper's residual: the action is the
            offset). Residual composition only.
        dmp_phase_stop_gain_per_m2: ``alpha_px`` of the DMP's phase stopping, 1/m^2
            (0, the paper's DMP: none). The DMP then runs with ``tau (1 + alpha_px
            max(0, |e| - dmp_phase_stop_deadband_m)^2)``, ``e`` the controller's
            translational tracking error, so it slows while contact holds the part
            back (Ijspeert et al. 2013; a deviation from the paper;
            models/tasks/variants/rj45_phase_stop.yaml).
        dmp_phase_stop_deadband_m: tracking error below which the DMP is not slowed, m.
        residual_starts_at_table_slope: with a rate residual: the held offset starts at
            the constant turn that undoes the table's slope (``table_slope_residual``)
            instead of zero, so the learner searches from a set-point that is level
            with the fixture's known tilt (the cell's measured slope, the part of the
            fixture error that is the same in every episode; a deviation from the
            paper, whose residual starts at zero; models/tasks/variants/
            peg_incremental_slope_start.yaml).
    """

    name: str
    part: PartSpec
    fixture: FixtureSpec
    X_WFixture: PoseSpec
    grasp: PoseSpec
    kappa_m: float
    start: StartDistributionSpec
    fixture_error: FixtureErrorSpec
    demo: str
    description: str = ""
    kappa_deg: float | None = None
    force_limit_n: float | None = None
    episode_time_s: float = 10.0
    residual_activation_s: float = 5.0
    residual_max_translation_m: float = 0.01
    residual_max_rotation_rad: float = 0.087
    residual_max_push_m: float | None = None
    residual_period_s: float = 0.1
    rotational_stiffness_Nm_per_rad: float | None = None
    translational_stiffness_N_per_m: float | None = None
    residual_filter_time_constant_s: float | None = None
    residual_rate_per_s: float | None = None
    dmp_phase_stop_gain_per_m2: float = 0.0
    dmp_phase_stop_deadband_m: float = 0.0
    residual_starts_at_table_slope: bool = False
    source: Path | None = field(default=None, compare=False)

    @property
    def X_FP_goal(self) -> PoseSpec:
        """Pose of P in F when fully inserted: P at (0, 0, -depth_m), aligned with F."""
        return PoseSpec(position_m=(0.0, 0.0, -self.fixture.depth_m))

    def demo_path(self) -> Path:
        """Absolute path of the demonstration file (may not exist yet)."""
        return models_dir() / self.demo

    def opening_size_m(self) -> tuple[float, float]:
        """Hole opening (x, y) for holes and sockets, or the shaft side (x, y) for the
        gear shaft, m."""
        c = self.fixture.clearance_m
        if self.fixture.kind == "square_shaft":
            assert self.part.hole_size_m is not None
            return (self.part.hole_size_m[0] - c, self.part.hole_size_m[1] - c)
        y = self.part.size_m[1]
        if self.fixture.kind == "rj45_socket":
            assert self.part.latch_size_m is not None
            y += self.part.latch_size_m[1]
        return (self.part.size_m[0] + c, y + c)


# --------------------------------------------------------------------------------------
# Loading and validation.
# --------------------------------------------------------------------------------------
def tasks_dir() -> Path:
    """The folder of the shipped task YAML files."""
    return models_dir() / "tasks"


def list_tasks() -> list[str]:
    """Names of the shipped tasks, sorted."""
    return sorted(p.stem for p in tasks_dir().glob("*.yaml"))


def _convert(value: object, hint: object, where: str) -> object:
    """Converts a YAML value to the annotated type, raising ValueError naming ``where``."""
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return _convert(value, inner, where)
    if dataclasses.is_dataclass(hint):
        if not isinstance(value, dict):
            raise ValueError(f"{where}: expected a mapping, got {value!r}")
        return _from_dict(hint, value, where)
    if hint is float:
        if isinstance(value, str):
            # PyYAML (YAML 1.1) reads "1.0e7" (no exponent sign) as a string.
            try:
                value = float(value)
            except ValueError:
                raise ValueError(f"{where}: expected a number, got {value!r}") from None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{where}: expected a number, got {value!r}")
        if not math.isfinite(float(value)):
            raise ValueError(f"{where}: expected a finite number, got {value!r}")
        return float(value)
    if hint is bool:
        if not isinstance(value, bool):
            raise ValueError(f"{where}: expected true or false, got {value!r}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{where}: expected an integer, got {value!r}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ValueError(f"{where}: expected a string, got {value!r}")
        return value
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"{where}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ValueError(f"{where}: expected {len(args)} values, got {len(value)}")
        return tuple(
            _convert(v, a, f"{where}[{i}]")
            for i, (v, a) in enumerate(zip(value, args, strict=True))
        )
    raise TypeError(f"{where}: unsupported type {hint}")  # pragma: no cover


def _from_dict(cls: type, data: dict, where: str) -> object:
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.name != "source"}
    for key in data:
        if key not in fields:
            raise ValueError(
                f"unknown field {where + '.' if where else ''}{key} "
                f"(known: {', '.join(sorted(fields))})"
            )
    kwargs = {}
    for name, f in fields.items():
        path = f"{where}.{name}" if where else name
        if name not in data:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise ValueError(f"missing field {path}")
            continue
        kwargs[name] = _convert(data[name], hints[name], path)
    return cls(**kwargs)


def _positive(value: float | None, name: str, allow_zero: bool = False) -> None:
    if value is None:
        return
    if not math.isfinite(value) or value < 0.0 or (value == 0.0 and not allow_zero):
        kind = "non-negative" if allow_zero else "positive"
        raise ValueError(f"{name} must be {kind}, got {value}")


def _validate(task: TaskSpec) -> None:
    part, fix = task.part, task.fixture
    if part.kind not in PART_KINDS:
        raise ValueError(f"part.kind must be one of {PART_KINDS}, got {part.kind!r}")
    if fix.kind not in FIXTURE_KINDS:
        raise ValueError(f"fixture.kind must be one of {FIXTURE_KINDS}, got {fix.kind!r}")
    if FIXTURE_FOR_PART[part.kind] != fix.kind:
        raise ValueError(
            f"fixture.kind {fix.kind!r} does not fit part.kind {part.kind!r} "
            f"(expected {FIXTURE_FOR_PART[part.kind]!r})"
        )
    for i, v in enumerate(part.size_m):
        _positive(v, f"part.size_m[{i}]")
    _positive(part.mass_kg, "part.mass_kg")
    _positive(part.hydroelastic_modulus_pa, "part.hydroelastic_modulus_pa")
    _positive(
        part.hunt_crossley_dissipation_s_per_m, "part.hunt_crossley_dissipation_s_per_m", True
    )
    _positive(part.friction, "part.friction")
    _positive(fix.clearance_m, "fixture.clearance_m", allow_zero=True)
    _positive(fix.chamfer_m, "fixture.chamfer_m", allow_zero=True)
    _positive(fix.depth_m, "fixture.depth_m")
    _positive(fix.wall_m, "fixture.wall_m")
    _positive(fix.floor_thickness_m, "fixture.floor_thickness_m")
    _positive(fix.friction, "fixture.friction")
    if part.kind == "gear":
        if part.hole_size_m is None:
            raise ValueError("part.hole_size_m is required for a gear")
        for i, v in enumerate(part.hole_size_m):
            _positive(v, f"part.hole_size_m[{i}]")
            if v >= part.size_m[i]:
                raise ValueError(f"part.hole_size_m[{i}] = {v} must be smaller than the gear")
        if fix.depth_m < part.size_m[2]:
            raise ValueError(
                f"fixture.depth_m = {fix.depth_m} (shaft height) must be at least the gear "
                f"thickness part.size_m[2] = {part.size_m[2]}"
            )
    elif part.hole_size_m is not None:
        raise ValueError(f"part.hole_size_m is only for a gear, not {part.kind!r}")
    if part.kind == "rj45_plug":
        if part.latch_size_m is None or part.latch_offset_m is None:
            raise ValueError("part.latch_size_m and part.latch_offset_m are required for rj45")
        for i, v in enumerate(part.latch_size_m):
            _positive(v, f"part.latch_size_m[{i}]")
        _positive(part.latch_offset_m, "part.latch_offset_m", allow_zero=True)
        if part.latch_size_m[0] >= part.size_m[0]:
            raise ValueError("part.latch_size_m[0] must be narrower than the plug")
        if part.latch_offset_m + part.latch_size_m[2] > part.size_m[2]:
            raise ValueError("part.latch_offset_m + part.latch_size_m[2] exceeds the plug")
    elif part.latch_size_m is not None or part.latch_offset_m is not None:
        raise ValueError(f"part.latch_size_m / latch_offset_m are only for rj45, not {part.kind!r}")
    if fix.kind in ("square_hole", "rj45_socket") and fix.depth_m > part.size_m[2]:
        raise ValueError(
            f"fixture.depth_m = {fix.depth_m} is deeper than the part is long "
            f"(part.size_m[2] = {part.size_m[2]})"
        )
    opening = task.opening_size_m()
    for i, v in enumerate(opening):
        _positive(v, f"opening[{i}] (from the part size and fixture.clearance_m)")
        if 2 * fix.chamfer_m >= min(v, fix.wall_m):
            raise ValueError(
                f"fixture.chamfer_m = {fix.chamfer_m} is too large for the opening {v} "
                f"or the wall {fix.wall_m}"
            )
    _positive(task.kappa_m, "kappa_m")
    _positive(task.kappa_deg, "kappa_deg")
    _positive(task.force_limit_n, "force_limit_n")
    _positive(task.episode_time_s, "episode_time_s")
    _positive(task.residual_activation_s, "residual_activation_s", allow_zero=True)
    _positive(task.residual_max_translation_m, "residual_max_translation_m")
    _positive(task.residual_max_rotation_rad, "residual_max_rotation_rad")
    _positive(task.residual_max_push_m, "residual_max_push_m", allow_zero=True)
    _positive(task.rotational_stiffness_Nm_per_rad, "rotational_stiffness_Nm_per_rad")
    _positive(task.translational_stiffness_N_per_m, "translational_stiffness_N_per_m")
    _positive(task.residual_filter_time_constant_s, "residual_filter_time_constant_s")
    _positive(task.residual_rate_per_s, "residual_rate_per_s")
    _positive(task.residual_period_s, "residual_period_s")
    _positive(task.dmp_phase_stop_gain_per_m2, "dmp_phase_stop_gain_per_m2", allow_zero=True)
    _positive(task.dmp_phase_stop_deadband_m, "dmp_phase_stop_deadband_m", allow_zero=True)
    if task.residual_starts_at_table_slope:
        if task.residual_rate_per_s is None:
            raise ValueError(
                "residual_starts_at_table_slope needs a rate residual (residual_rate_per_s), "
                "got residual_rate_per_s = None (an offset residual: use --base-correction slope)"
            )
        units = np.abs(table_slope_residual(task)[3:6])
        if np.any(units > 1.0):
            raise ValueError(
                f"residual_starts_at_table_slope: the slope's turn is {units.max():.2f} of "
                f"residual_max_rotation_rad = {task.residual_max_rotation_rad}, beyond the range"
            )
    if task.residual_period_s > task.episode_time_s - task.residual_activation_s:
        raise ValueError(
            f"residual_period_s = {task.residual_period_s} is longer than the time the "
            f"residual acts (episode_time_s - residual_activation_s = "
            f"{task.episode_time_s - task.residual_activation_s})"
        )
    if task.residual_activation_s > task.episode_time_s:
        raise ValueError(
            f"residual_activation_s = {task.residual_activation_s} is after the episode end "
            f"episode_time_s = {task.episode_time_s}"
        )
    start = task.start
    if start.kind not in START_KINDS:
        raise ValueError(f"start.kind must be one of {START_KINDS}, got {start.kind!r}")
    _positive(start.half_extent_m, "start.half_extent_m", allow_zero=start.kind == "six_boxes")
    if start.kind == "six_boxes":
        if not start.box_distances_m:
            raise ValueError("start.box_distances_m must list the box centre distances")
        for i, v in enumerate(start.box_distances_m):
            _positive(v, f"start.box_distances_m[{i}]", allow_zero=True)
        _positive(start.box_half_extent_m, "start.box_half_extent_m")
    if start.kind == "orientation_bins":
        if start.n_bins <= 0:
            raise ValueError(f"start.n_bins must be positive, got {start.n_bins}")
        if start.samples_per_bin <= 0:
            raise ValueError(f"start.samples_per_bin must be positive, got {start.samples_per_bin}")
        _positive(start.max_angle_deg, "start.max_angle_deg")
    if start.n_eval <= 0:
        raise ValueError(f"start.n_eval must be positive, got {start.n_eval}")
    err = task.fixture_error
    for i, v in enumerate(err.position_bound_m):
        _positive(v, f"fixture_error.position_bound_m[{i}]", allow_zero=True)
    _positive(err.rotation_bound_deg, "fixture_error.rotation_bound_deg", allow_zero=True)
    if abs(err.table_slope_deg) > 10.0:
        raise ValueError(
            f"fixture_error.table_slope_deg must be within +-10 deg, got {err.table_slope_deg}"
        )
    if np.linalg.norm(err.table_slope_axis) < 1e-9:
        raise ValueError(
            f"fixture_error.table_slope_axis must be non-zero, got {err.table_slope_axis}"
        )


def _merged(base: dict, changes: dict) -> dict:
    """``base`` with ``changes`` laid over it: mappings merge key by key, anything else
    (numbers, lists, null) replaces the base's value."""
    merged = dict(base)
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = _merged(merged[key], value)
        else:
            merged[key] = value
    return merged


def _read_task_data(path: Path, chain: tuple[Path, ...]) -> dict:
    """The YAML mapping of a task file, with its ``based_on`` chain resolved.

    A variant names its base task in ``based_on``: a shipped task name or a path
    relative to the variant's own folder. The variant holds only what it changes, so
    a fix to the base reaches every variant and a variant's file shows its difference.
    """
    data = yaml.safe_load(path.read_text())
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping at the top level")
    if "based_on" not in data:
        return data
    changes = dict(data)
    base_name = changes.pop("based_on")
    if not isinstance(base_name, str) or not base_name:
        raise ValueError(f"{path}: based_on must name a task or a YAML file, got {base_name!r}")
    if "name" not in changes:
        raise ValueError(f"{path}: a task based on {base_name!r} must give its own name")
    if base_name.endswith((".yaml", ".yml")):
        base_path = (path.parent / base_name).resolve()
    else:
        base_path = tasks_dir() / f"{base_name}.yaml"
    if not base_path.exists():
        raise ValueError(f"{path}: based_on {base_name!r}: no such task file {base_path}")
    chain = (*chain, path.resolve())
    if base_path.resolve() in chain:
        loop = " -> ".join(p.name for p in (*chain, base_path))
        raise ValueError(f"{path}: based_on {base_name!r} makes a loop: {loop}")
    return _merged(_read_task_data(base_path, chain), changes)


def load_task(name_or_path: str | Path, check_demo: bool = True) -> TaskSpec:
    """Loads and validates a task.

    Args:
        name_or_path: a shipped task name (see ``list_tasks()``) or a path to a YAML file.
            A file may name a base task in ``based_on`` and hold only its changes
            (mappings merge field by field; ``models/tasks/variants/`` are written so).
        check_demo: if True, the demonstration file named by ``demo`` must exist.

    Raises:
        ValueError: unknown task, unknown or missing field, bad value (the message names
            the field and the value), or missing demonstration file.
    """
    path = shipped_path(name_or_path)
    if path.suffix not in (".yaml", ".yml"):
        path = tasks_dir() / f"{name_or_path}.yaml"
        if not path.exists():
            raise ValueError(f"unknown task {name_or_path!r}; known: {', '.join(list_tasks())}")
    elif not path.exists():
        raise ValueError(f"task file {path} does not exist")
    data = _read_task_data(path, ())
    task = _from_dict(TaskSpec, data, "")
    assert isinstance(task, TaskSpec)
    task = dataclasses.replace(task, source=path)
    _validate(task)
    if check_demo and not task.demo_path().exists():
        raise ValueError(f"demo: demonstration file {task.demo_path()} does not exist")
    return task


def describe_task(task: TaskSpec) -> dict:
    """A JSON-serialisable summary of a task (for ``rlfd tasks``)."""
    return {
        "description": task.description,
        "part": f"{task.part.kind} {' x '.join(f'{1e3 * v:g}' for v in task.part.size_m)} mm",
        "fixture": task.fixture.kind,
        "clearance_mm": 1e3 * task.fixture.clearance_m,
        "chamfer_mm": 1e3 * task.fixture.chamfer_m,
        "depth_mm": 1e3 * task.fixture.depth_m,
        "kappa_mm": 1e3 * task.kappa_m,
        "kappa_deg": task.kappa_deg,
        "start": task.start.kind,
        "n_eval": evaluation_size(task),
        "fixture_error_mm": [1e3 * v for v in task.fixture_error.position_bound_m],
        "fixture_error_deg": task.fixture_error.rotation_bound_deg,
        "table_slope_deg": task.fixture_error.table_slope_deg,
        "force_limit_n": task.force_limit_n,
        "demo": task.demo,
        "demo_exists": task.demo_path().exists(),
    }


# --------------------------------------------------------------------------------------
# Perturbations.
# --------------------------------------------------------------------------------------
_IDENTITY_Q = np.array([1.0, 0.0, 0.0, 0.0])


def evaluation_size(task: TaskSpec) -> int:
    """Number of starts of the paper's evaluation grid: ``n_bins * samples_per_bin`` for
    orientation bins (8 x 20 = 160), else ``start.n_eval`` (500)."""
    s = task.start
    if s.kind == "orientation_bins":
        return s.n_bins * s.samples_per_bin
    return s.n_eval


def _sample_in_bin(
    task: TaskSpec, rng: np.random.Generator, bin_index: int | None
) -> tuple[np.ndarray, np.ndarray, int]:
    s = task.start
    if s.kind == "uniform_box":
        dp = rng.uniform(-s.half_extent_m, s.half_extent_m, size=3)
        return dp, _IDENTITY_Q.copy(), 0
    if s.kind == "six_boxes":
        k = int(rng.integers(len(s.box_distances_m))) if bin_index is None else bin_index
        signs = rng.choice([-1.0, 1.0], size=3)
        centre = s.box_distances_m[k] * signs
        dp = centre + rng.uniform(-s.box_half_extent_m, s.box_half_extent_m, size=3)
        return dp, _IDENTITY_Q.copy(), k
    # orientation_bins
    width = s.max_angle_deg / s.n_bins
    if bin_index is None:
        angle_deg = rng.uniform(0.0, s.max_angle_deg)
        b = min(int(angle_deg // width), s.n_bins - 1)
    else:
        b = bin_index
        angle_deg = rng.uniform(b * width, (b + 1) * width)
    axis = _random_unit_vector(rng)
    dq = quat_from_angle_axis(math.radians(angle_deg), axis)
    dp = rng.uniform(-s.half_extent_m, s.half_extent_m, size=3)
    return dp, dq, b


def sample_start_offset(task: TaskSpec, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One training start offset: (dp (3,) m, dq (4,) wxyz) relative to the demo start.

    uniform_box: uniform in the box. six_boxes: a random box, then uniform in it.
    orientation_bins: angle uniform in [0, max_angle_deg] about a uniformly random
    axis, position uniform in +-half_extent_m.
    """
    dp, dq, _ = _sample_in_bin(task, rng, None)
    return dp, dq


def evaluation_grid(
    task: TaskSpec, n: int | None = None, seed: int = 0
) -> list[tuple[np.ndarray, np.ndarray, int]]:
    """The paper's evaluation starts: a list of (dp (3,) m, dq (4,) wxyz, bin index).

    Deterministic for a given seed. ``n`` defaults to ``evaluation_size(task)`` (500
    for the peg tasks, 160 = 8 bins x 20 for gear and RJ-45). The starts are split as
    evenly as possible over the bins (six boxes / orientation bins), bin by bin in
    increasing order; the uniform box has one bin (0).
    """
    n = evaluation_size(task) if n is None else n
    if n <= 0:
        raise ValueError(f"n must be positive, got {n}")
    rng = np.random.default_rng(seed)
    s = task.start
    n_bins = {"uniform_box": 1, "six_boxes": len(s.box_distances_m)}.get(s.kind, s.n_bins)
    grid = []
    for b in range(n_bins):
        count = n // n_bins + (1 if b < n % n_bins else 0)
        for _ in range(count):
            grid.append(_sample_in_bin(task, rng, b))
    return grid


def sample_fixture_error(task: TaskSpec, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A fixture pose error X_err = (dp (3,) m, dq (4,) wxyz), to be composed as
    X_WF_true = X_WF_nominal * X_err (dp and dq expressed in F).

    The position is uniform in +-position_bound_m per axis; the rotation is the table
    slope (a constant tilt of table_slope_deg about table_slope_axis) times a random
    rotation about a uniformly random axis by an angle uniform in
    [0, rotation_bound_deg].
    """
    err = task.fixture_error
    bound = np.asarray(err.position_bound_m)
    dp = rng.uniform(-bound, bound)
    angle = math.radians(rng.uniform(0.0, err.rotation_bound_deg))
    q_random = quat_from_angle_axis(angle, _random_unit_vector(rng))
    return dp, quat_multiply(table_slope_quaternion(task), q_random)


def table_slope_quaternion(task: TaskSpec) -> np.ndarray:
    """The table slope's rotation (wxyz, in F): the part of the fixture error that is
    the same in every episode (``sample_fixture_error``)."""
    err = task.fixture_error
    return quat_from_angle_axis(math.radians(err.table_slope_deg), np.asarray(err.table_slope_axis))


def fixture_turn_in_world(task: TaskSpec, dq_in_fixture) -> np.ndarray:
    """A fixture rotation ``dq`` (wxyz, in F) as the world rotation vector (3,) that
    turns the part with it, ``R_WF R_dq R_WF^T``: the residual turns the part in the
    world (R_cmd = R_delta R_dmp), the fixture error is expressed in F."""
    return task.X_WFixture.rotation_matrix() @ rotation_vector_from_quat(np.asarray(dq_in_fixture))


def table_slope_residual(task: TaskSpec) -> np.ndarray:
    """The residual (6,), in units of the task's ranges, that undoes the table slope: no
    translation, the slope's world turn over ``residual_max_rotation_rad``. Not clipped."""
    rotation = fixture_turn_in_world(task, table_slope_quaternion(task))
    return np.r_[np.zeros(3), rotation / task.residual_max_rotation_rad]
