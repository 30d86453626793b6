"""One evaluation episode of a task: its start and fixture error, its run, its metrics.

An episode (paper, Sec. V) starts the robot at rest with the part P at the
demonstration's start pose moved by a start offset (``EpisodeSpec.start_dp``,
``start_dq``), puts the fixture at its nominal pose times an unseen error
(``fixture_dp``, ``fixture_dq``), runs the DMP (plus a residual policy, if any, from
the task's activation time on) for at most ``task.episode_time_s`` and reports
success (the part within ``kappa_m`` of the true goal), insertion time and the
contact forces felt.

A simulator failure (SAP not converging raises RuntimeError) or an IK failure at the
start is a failed episode with its reason, never an exception.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import Meshcat
from pydrake.math import RigidTransform, RotationMatrix

from rlfd_drake.demonstration import load_demonstration
from rlfd_drake.diagram import (
    RESIDUAL_SIZE,
    BuildRlfdDiagram,
    DiagramStateSnapshot,
    MakeSimulator,
    PoseFromOffset,
    ResumeFromSnapshot,
    RlfdDiagram,
    RlfdDiagramConfig,
    SetEpisodeFixture,
    SetEpisodeStart,
    SnapshotDiagramState,
)
from rlfd_drake.dmp import CartesianDmp, DmpConfig, fit_cartesian_dmp
from rlfd_drake.geometry import quat_normalize
from rlfd_drake.scene import FixtureErrorTransform, FixturePoseInWorld, GoalPoseInWorld
from rlfd_drake.tasks import TaskSpec, evaluation_grid, sample_fixture_error, sample_start_offset

__all__ = [
    "EpisodeResult",
    "EpisodeSpec",
    "FAILURE_KINDS",
    "EPISODE_LOGS",
    "load_task_dmp",
    "make_episode_specs",
    "clear_diagram_cache",
    "clear_prefix_cache",
    "diagram_cache_stats",
    "prefix_cache_stats",
    "run_episode",
]

#: The first token (before ":") of ``EpisodeResult.failure_reason``.
FAILURE_KINDS = (
    "solver",  # the simulator raised RuntimeError (SAP did not converge)
    "ik",  # no joint configuration puts the part at the start pose
    "policy",  # the residual policy returned a non-finite or wrongly shaped action
    "force_limit",  # the contact force exceeded task.force_limit_n
    "orientation",  # inserted within kappa_m but rotated more than kappa_deg
    "jammed",  # entered the fixture (2 mm or more past its entrance) but stopped short
    "on_entrance",  # came to rest on or just above the fixture, not entered
    "missed",  # ended away from the fixture (approach did not get there)
)

#: The logs ``run_episode`` reads (insertion time, when the peak force was felt).
EPISODE_LOGS = ("distance_to_goal", "force_metrics")

# Depth below the entrance (m) beyond which the part counts as having entered.
_ENTERED_DEPTH_M = 0.002
# Height above the entrance (m) within which a non-entered part is "on the entrance".
_ON_ENTRANCE_HEIGHT_M = 0.02

_DMP_CACHE: dict[tuple[str, str, int, str], CartesianDmp] = {}


def load_task_dmp(task: TaskSpec, config: DmpConfig | None = None) -> CartesianDmp:
    """The DMP fitted on the task's committed demonstration (``task.demo_path()``).

    Cached per process by task name, file path, file modification time and DMP
    configuration, so a re-recorded demonstration is refitted.

    Raises:
        FileNotFoundError: if the demonstration file does not exist.
    """
    path = task.demo_path()
    key = (task.name, str(path), path.stat().st_mtime_ns, repr(config))
    model = _DMP_CACHE.get(key)
    if model is None:
        demo = load_demonstration(path)
        model = fit_cartesian_dmp(demo.times, demo.positions, demo.quats, config)
        _DMP_CACHE[key] = model
    return model


def demo_start_pose(dmp_model: CartesianDmp) -> RigidTransform:
    """X_WP of the demonstration's first sample (the DMP's y0, q0)."""
    q = quat_normalize(np.asarray(dmp_model.q0, dtype=float))
    return RigidTransform(RotationMatrix(Quaternion(q)), np.asarray(dmp_model.y0, dtype=float))


def _rotation_angle_deg(q_wxyz: np.ndarray) -> float:
    """Rotation angle (deg) of a unit quaternion, in [0, 180]."""
    w = min(1.0, abs(float(q_wxyz[0]) / float(np.linalg.norm(q_wxyz))))
    return math.degrees(2.0 * math.acos(w))


@dataclass(frozen=True)
class EpisodeSpec:
    """What makes one episode different from another.

    Attributes:
        start_dp: start position offset (3,) of P from the demonstration start,
            world frame, m.
        start_dq: start rotation offset (4,) wxyz, applied in the world frame on the
            left of the demonstration's start orientation.
        fixture_dp: fixture position error (3,) in F, m (X_WF_true = X_WF_nominal X_err).
        fixture_dq: fixture rotation error (4,) wxyz in F (table slope included).
        bin_index: evaluation-grid bin (six boxes / orientation bins; 0 for the
            uniform box), or -1 for a training-style random start.
    """

    start_dp: tuple[float, float, float] = (0.0, 0.0, 0.0)
    start_dq: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    fixture_dp: tuple[float, float, float] = (0.0, 0.0, 0.0)
    fixture_dq: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    bin_index: int = -1

    def __post_init__(self) -> None:
        for name, size in (("start_dp", 3), ("start_dq", 4), ("fixture_dp", 3), ("fixture_dq", 4)):
            value = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            if value.shape != (size,) or not np.all(np.isfinite(value)):
                raise ValueError(f"{name} must be {size} finite numbers, got {getattr(self, name)}")
            if size == 4 and abs(np.linalg.norm(value) - 1.0) > 1e-6:
                raise ValueError(f"{name} must be a unit quaternion, got {value}")
            object.__setattr__(self, name, tuple(float(v) for v in value))

    @property
    def start_position_offset_m(self) -> float:
        """|start_dp|, m."""
        return float(np.linalg.norm(self.start_dp))

    @property
    def start_rotation_offset_deg(self) -> float:
        """Rotation angle of start_dq, deg."""
        return _rotation_angle_deg(np.asarray(self.start_dq))

    @property
    def fixture_rotation_error_deg(self) -> float:
        """Rotation angle of fixture_dq (table slope included), deg."""
        return _rotation_angle_deg(np.asarray(self.fixture_dq))


def make_episode_specs(task: TaskSpec, n: int, seed: int, grid: bool = True) -> list[EpisodeSpec]:
    """``n`` episode specs, identical for identical arguments.

    Args:
        task: the task.
        n: number of episodes.
        seed: seed of the start offsets and of the fixture errors.
        grid: True draws the starts from the paper's evaluation grid
            (``tasks.evaluation_grid``: bins in increasing order, evenly filled);
            False from the training distribution (``tasks.sample_start_offset``,
            bin_index -1).

    The fixture errors come from a generator independent of the starts' (a child of
    ``SeedSequence(seed)``), so the same seed gives the same errors with or without
    the grid.
    """
    if n <= 0:
        raise ValueError(f"n must be positive, got {n}")
    start_seq, fixture_seq = np.random.SeedSequence(seed).spawn(2)
    if grid:
        starts = evaluation_grid(task, n, seed)
    else:
        start_rng = np.random.default_rng(start_seq)
        starts = [(*sample_start_offset(task, start_rng), -1) for _ in range(n)]
    fixture_rng = np.random.default_rng(fixture_seq)
    specs = []
    for dp, dq, b in starts:
        f_dp, f_dq = sample_fixture_error(task, fixture_rng)
        specs.append(
            EpisodeSpec(
                start_dp=tuple(dp),
                start_dq=tuple(quat_normalize(np.asarray(dq, float))),
                fixture_dp=tuple(f_dp),
                fixture_dq=tuple(quat_normalize(np.asarray(f_dq, float))),
                bin_index=int(b),
            )
        )
    return specs


@dataclass
class EpisodeResult:
    """Outcome and metrics of one episode.

    Attributes:
        success: the part got within ``kappa_m`` of the true goal (and within
            ``kappa_deg`` of its orientation at the end, if the task has one), no
            force limit was broken and the simulation did not fail.
        insertion_time_s: first time the part was within ``kappa_m`` of the goal, s
            (from the 100 Hz distance log; if it was there only between log samples,
            the end of the 0.1 s chunk in which success latched); nan if never.
        final_distance_m: |p_WP - p_WGoal_true| at the end, m (nan if never simulated).
        final_angle_deg: rotation angle between P and the true goal at the end, deg.
        peak_force_n: peak total contact force (sum of contact force magnitudes), N,
            sampled every plant step (2 ms): impacts show as one-step spikes.
        mean_force_n: time-averaged total contact force from t = 0 to the end of the
            simulation (the episode may stop early once inserted), N.
        peak_joint_contact_torque_nm: peak |generalised contact torque| over the arm
            joints, N m.
        peak_low_passed_force_n: peak of the total contact force low-passed with the
            observer's time constant (20 ms), N: what force limits are checked against,
            without the one-step impact spikes.
        force_limit_broken: the peak force exceeded ``task.force_limit_n``.
        failure_reason: None on success, else "<kind>: <details>" with kind in
            :data:`FAILURE_KINDS`.
        sim_time_s: simulated time reached, s.
        wall_time_s: wall-clock time of the episode (build, IK, simulation), s.
        bin_index: the spec's bin index.
        peak_force_time_s: when the peak total contact force was felt, s (the first
            log sample, every ``log_period_s``, at which the running peak had its final
            value: up to one log period late); nan if never simulated or never in contact.
        peak_force_distance_m: the part's distance to the true goal at that time, m:
            a peak near 0 is felt on reaching the bottom, one at the entrance's height
            on landing or searching there.
    """

    success: bool
    insertion_time_s: float
    final_distance_m: float
    final_angle_deg: float
    peak_force_n: float
    mean_force_n: float
    peak_joint_contact_torque_nm: float
    peak_low_passed_force_n: float
    force_limit_broken: bool
    failure_reason: str | None
    sim_time_s: float
    wall_time_s: float
    bin_index: int
    peak_force_time_s: float = float("nan")
    peak_force_distance_m: float = float("nan")

    @property
    def failure_kind(self) -> str | None:
        """The first token of ``failure_reason`` (one of FAILURE_KINDS), or None."""
        return None if self.failure_reason is None else self.failure_reason.split(":")[0]


def _final_failure_kind(task: TaskSpec, X_WF_true: RigidTransform, X_WP: RigidTransform) -> str:
    """Classifies a run that ended without inserting: jammed / on_entrance / missed."""
    p_FP = X_WF_true.inverse() @ X_WP.translation()
    if p_FP[2] <= -_ENTERED_DEPTH_M:
        return f"jammed: {1e3 * -p_FP[2]:.1f} mm deep of {1e3 * task.fixture.depth_m:.0f} mm"
    reach = 0.5 * max(task.opening_size_m()) + task.fixture.wall_m
    lateral = float(np.linalg.norm(p_FP[:2]))
    where = f"{1e3 * lateral:.1f} mm off axis, height {1e3 * p_FP[2]:+.1f} mm over the entrance"
    if lateral <= reach and p_FP[2] <= _ON_ENTRANCE_HEIGHT_M:
        return f"on_entrance: {where}"
    return f"missed: {where}"


@dataclass(frozen=True)
class _EpisodePrefix:
    """An episode up to the end of its last chunk before the residual's activation:
    the diagram's state there, the loop's bookkeeping and the logs so far."""

    chunk_index: int
    state: DiagramStateSnapshot
    latched_at: float | None
    within_since: float | None
    logs: dict[str, tuple[np.ndarray, np.ndarray]]


#: The DMP-only starts of recent episodes, by ``_prefix_key``, least recently used
#: first (per process: a snapshot holds Drake values that do not pickle).
_PREFIX_CACHE: OrderedDict[str, _EpisodePrefix] = OrderedDict()
#: About 35 kB a prefix (two logs of 4.9 s at 100 Hz and the plant's step memory;
#: results/probes/memory_per_episode.md).
_PREFIX_CACHE_SIZE = 512
_PREFIX_STATS = {"hits": 0, "stored": 0}


def prefix_cache_stats() -> dict[str, int]:
    """This process's counts of episodes that resumed from a stored DMP-only start
    ("hits") and of starts stored ("stored"), and the number held ("held")."""
    return {**_PREFIX_STATS, "held": len(_PREFIX_CACHE)}


def clear_prefix_cache() -> None:
    """Forgets every stored episode start and zeroes the counts."""
    _PREFIX_CACHE.clear()
    _PREFIX_STATS.update(hits=0, stored=0)


def _fingerprint_parts(value, out: list[bytes]) -> None:
    """Appends an exact, type-tagged byte encoding of ``value`` to ``out``."""
    if value is None or isinstance(value, bool | int | str | Path):
        out.append(f"{type(value).__name__}:{value!s};".encode())
    elif isinstance(value, float):
        out.append(f"float:{value.hex()};".encode())
    elif isinstance(value, np.ndarray):
        out.append(f"ndarray:{value.dtype.str}:{value.shape};".encode())
        out.append(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, tuple | list):
        out.append(f"{type(value).__name__}:{len(value)}(".encode())
        for item in value:
            _fingerprint_parts(item, out)
        out.append(b")")
    elif dataclasses.is_dataclass(value):
        out.append(f"{type(value).__qualname__}(".encode())
        for f in dataclasses.fields(value):
            out.append(f"{f.name}=".encode())
            _fingerprint_parts(getattr(value, f.name), out)
        out.append(b")")
    else:
        raise TypeError(f"cannot fingerprint a {type(value).__name__}")


def _fingerprint(*values) -> str:
    """A hash of ``values``' exact, type-tagged encodings (``_fingerprint_parts``)."""
    parts: list[bytes] = []
    for value in values:
        _fingerprint_parts(value, parts)
    return hashlib.blake2b(b"".join(parts), digest_size=20).hexdigest()


def _prefix_key(
    task: TaskSpec,
    dmp_model: CartesianDmp,
    spec: EpisodeSpec,
    config: RlfdDiagramConfig,
    chunk_s: float,
    stop_after_success_s: float | None,
) -> str:
    """What decides an episode up to the residual's activation: the task, the DMP, the
    start and fixture error, the diagram's configuration except what only acts on
    the residual (its mode), and the loop's chunks and stopping rule."""
    before_activation = replace(config, residual_mode="full")
    return _fingerprint(task, dmp_model, spec, before_activation, chunk_s, stop_after_success_s)


#: Diagrams ``run_episode`` built, reused by later episodes of the same task, DMP,
#: configuration and kind of policy (their policies swapped in, the fixture moved by a
#: context parameter): pydrake 1.51 never frees a diagram holding a Python system,
#: so a diagram per episode grew each process by about 1.5 MB an episode
#: (results/probes/memory_per_episode.md). An evicted diagram's memory stays taken.
_DIAGRAM_CACHE: OrderedDict[str, RlfdDiagram] = OrderedDict()
_DIAGRAM_CACHE_SIZE = 16
_DIAGRAM_STATS = {"built": 0, "reused": 0}


def diagram_cache_stats() -> dict[str, int]:
    """This process's counts of diagrams ``run_episode`` built ("built") and of
    episodes that reused one ("reused"), and the number held ("held")."""
    return {**_DIAGRAM_STATS, "held": len(_DIAGRAM_CACHE)}


def clear_diagram_cache() -> None:
    """Forgets the diagrams kept for reuse and zeroes the counts."""
    _DIAGRAM_CACHE.clear()
    _DIAGRAM_STATS.update(built=0, reused=0)


def _release_policies(rlfd: RlfdDiagram) -> None:
    """Drops the policies a kept diagram ran last (it is given new ones before its next
    episode), so that at most one kept diagram holds a model between episodes."""
    for system in (rlfd.residual_policy, rlfd.coupling_policy):
        if system is not None:
            system.ReleasePolicy()


def _episode_diagram(
    task: TaskSpec,
    dmp_model: CartesianDmp,
    config: RlfdDiagramConfig,
    policy: Callable[[np.ndarray], np.ndarray] | None,
    coupling_policy: Callable[[np.ndarray], np.ndarray] | None,
) -> RlfdDiagram:
    """A diagram for an episode without a Meshcat: a kept one with the policies and
    the DMP's forcing weights swapped in, else a new one (then kept). Its fixture is
    put by the episode."""
    unweighted = replace(
        dmp_model,
        weights_translation=np.zeros_like(dmp_model.weights_translation),
        weights_orientation=np.zeros_like(dmp_model.weights_orientation),
    )
    key = _fingerprint(task, unweighted, config, policy is None, coupling_policy is None)
    rlfd = _DIAGRAM_CACHE.get(key)
    # Only the diagram of this episode needs a policy: the others let theirs go.
    for other in _DIAGRAM_CACHE.values():
        if other is not rlfd:
            _release_policies(other)
    if rlfd is None:
        rlfd = BuildRlfdDiagram(
            task, dmp_model, config, policy=policy, coupling_policy=coupling_policy
        )
        _DIAGRAM_CACHE[key] = rlfd
        _DIAGRAM_STATS["built"] += 1
        while len(_DIAGRAM_CACHE) > _DIAGRAM_CACHE_SIZE:
            _DIAGRAM_CACHE.popitem(last=False)
        return rlfd
    _DIAGRAM_CACHE.move_to_end(key)
    _DIAGRAM_STATS["reused"] += 1
    rlfd.dmp.SetForcingWeights(dmp_model)
    if policy is not None:
        rlfd.residual_policy.SetPolicy(policy)
    if coupling_policy is not None:
        rlfd.coupling_policy.SetPolicy(coupling_policy)
    return rlfd


def _chunk_ends(t_end: float, chunk_s: float) -> list[float]:
    """The times the episode loop advances to: ``chunk_s`` added up to ``t_end``."""
    ends = []
    t = 0.0
    while t < t_end - 1e-9:
        t = min(t + chunk_s, t_end)
        ends.append(t)
    return ends


def _last_chunk_before(ends: list[float], activation_s: float, chunk_s: float) -> int | None:
    """Index of the last chunk end at least half a chunk before the activation (no
    residual update can have fired by then), or None."""
    before = [i for i, t in enumerate(ends) if t <= activation_s - 0.5 * chunk_s]
    return before[-1] if before else None


def run_episode(
    task: TaskSpec,
    dmp_model: CartesianDmp,
    spec: EpisodeSpec,
    policy: Callable[[np.ndarray], np.ndarray] | None = None,
    diagram_config: RlfdDiagramConfig | None = None,
    meshcat: Meshcat | None = None,
    record_html: str | Path | None = None,
    *,
    coupling_policy: Callable[[np.ndarray], np.ndarray] | None = None,
    stop_after_success_s: float | None = 0.5,
    chunk_s: float = 0.1,
    realtime_rate: float | None = None,
    reuse_prefix: bool = True,
) -> EpisodeResult:
    """Runs one episode and measures it.

    Without a Meshcat the diagram is one kept by this process for the task, DMP (up to
    its forcing weights) and configuration, with the policy swapped in and the fixture
    moved by a context parameter, in a new simulator and context: the same episode as
    in a diagram built for it (``tests/test_episode.py``), without the memory a
    diagram per episode kept (``diagram_cache_stats``).

    Args:
        task: the task.
        dmp_model: the base policy (e.g. ``load_task_dmp(task)``).
        spec: start offset and fixture error.
        policy: residual policy obs (26,) float32 -> action (6,) in [-1, 1], run inside
            the diagram at the residual rate; None runs the DMP alone (the residual
            input is fixed to zeros).
        diagram_config: rates and gains (default RlfdDiagramConfig()).
        meshcat: if given, the episode is drawn and recorded as an animation.
        record_html: if given (with meshcat), the recording is saved there as a
            self-contained HTML page.
        coupling_policy: a policy of the DMP's coupling term (see ``BuildRlfdDiagram``;
            the eNAC baseline), or None.
        stop_after_success_s: stop once success has latched and the part has been
            within kappa for this long, s (checked every ``chunk_s``); None runs the
            whole episode.
        chunk_s: simulation is advanced in chunks of this length, s.
        realtime_rate: if given (with meshcat), the episode is drawn live while it is
            recorded, paced at this multiple of real time (0 = as fast as possible), so
            that it can be watched; None records without drawing live (faster).
        reuse_prefix: until the residual's activation the DMP drives alone, so the
            episode's first half depends only on the task, DMP, start, fixture error
            and configuration, not on the residual policy. True keeps that part (the
            state at the last 0.1 s chunk before the activation, and the logs so far)
            in a per-process cache and resumes later episodes with the same key from
            it, bit for bit the same episode (``tests/test_episode.py``) for about 30 %
            less time. Not used with a meshcat, a coupling policy, the hybrid or pure
            compositions, or a policy called from the start.

    Returns:
        The episode's result. Never raises for simulator, IK or policy failures.

    Raises:
        ValueError: ``record_html`` without ``meshcat``, or a negative ``realtime_rate``.
    """
    wall_start = time.perf_counter()
    if record_html is not None and meshcat is None:
        raise ValueError("record_html needs a meshcat to record into")
    if realtime_rate is not None and not (math.isfinite(realtime_rate) and realtime_rate >= 0):
        raise ValueError(f"realtime_rate must be a number >= 0, got {realtime_rate}")
    config = diagram_config if diagram_config is not None else RlfdDiagramConfig()
    # Only the logs read below: each log evaluates its output at every sample (the
    # observation's alone is about 3 % of an episode).
    config = replace(config, logged_outputs=EPISODE_LOGS)
    X_err = FixtureErrorTransform(np.asarray(spec.fixture_dp), np.asarray(spec.fixture_dq))
    if meshcat is None:
        rlfd = _episode_diagram(task, dmp_model, config, policy, coupling_policy)
    else:
        rlfd = BuildRlfdDiagram(
            task,
            dmp_model,
            config,
            policy=policy,
            coupling_policy=coupling_policy,
            fixture_error=X_err,
            meshcat=meshcat,
        )
    diagram = rlfd.diagram
    simulator = MakeSimulator(rlfd)
    if realtime_rate is not None:
        simulator.set_target_realtime_rate(realtime_rate)
    context = simulator.get_mutable_context()
    SetEpisodeFixture(rlfd, context, X_err)
    if policy is None:
        diagram.GetInputPort("residual").FixValue(context, np.zeros(RESIDUAL_SIZE))

    kappa = task.kappa_m
    nan = float("nan")

    def result(failure: str | None, success: bool, **metrics: float) -> EpisodeResult:
        return EpisodeResult(
            success=success,
            insertion_time_s=metrics.get("insertion_time_s", nan),
            final_distance_m=metrics.get("final_distance_m", nan),
            final_angle_deg=metrics.get("final_angle_deg", nan),
            peak_force_n=metrics.get("peak_force_n", 0.0),
            mean_force_n=metrics.get("mean_force_n", 0.0),
            peak_joint_contact_torque_nm=metrics.get("peak_torque", 0.0),
            peak_low_passed_force_n=metrics.get("peak_low_passed_force_n", 0.0),
            force_limit_broken=bool(metrics.get("force_limit_broken", False)),
            failure_reason=failure,
            sim_time_s=float(context.get_time()),
            wall_time_s=time.perf_counter() - wall_start,
            bin_index=spec.bin_index,
            peak_force_time_s=metrics.get("peak_force_time_s", nan),
            peak_force_distance_m=metrics.get("peak_force_distance_m", nan),
        )

    ends = _chunk_ends(task.episode_time_s, chunk_s)
    prefix_index = None
    if (
        reuse_prefix
        and meshcat is None
        and coupling_policy is None
        and config.composition == "residual"
        and (policy is None or config.residual_policy_from_activation)
    ):
        prefix_index = _last_chunk_before(ends, rlfd.composer.config.activation_time_s, chunk_s)
    key = None
    prefix = None
    if prefix_index is not None:
        key = _prefix_key(task, dmp_model, spec, config, chunk_s, stop_after_success_s)
        prefix = _PREFIX_CACHE.get(key)
        if prefix is not None:
            _PREFIX_CACHE.move_to_end(key)
            _PREFIX_STATS["hits"] += 1

    if prefix is None:
        X_WP_start = PoseFromOffset(
            demo_start_pose(dmp_model), np.asarray(spec.start_dp), spec.start_dq
        )
        try:
            SetEpisodeStart(rlfd, context, X_WP_start)
        except RuntimeError as e:
            return result(f"ik: {_first_line(e)}", False)

    if meshcat is not None:
        meshcat.StartRecording(set_visualizations_while_recording=realtime_rate is not None)
    failure: str | None = None
    within_since: float | None = None
    latched_at: float | None = None
    force_limit_broken = False
    success_port = diagram.GetOutputPort("success")
    distance_port = diagram.GetOutputPort("distance_to_goal")
    force_port = diagram.GetOutputPort("force_metrics")
    first_chunk = 0
    try:
        if prefix is None:
            simulator.Initialize()
        else:
            ResumeFromSnapshot(rlfd, simulator, prefix.state)
            latched_at, within_since = prefix.latched_at, prefix.within_since
            first_chunk = prefix.chunk_index + 1
        for index in range(first_chunk, len(ends)):
            t = ends[index]
            simulator.AdvanceTo(t)
            if task.force_limit_n is not None and force_port.Eval(context)[3] > task.force_limit_n:
                force_limit_broken = True
                break
            if latched_at is None and success_port.Eval(context)[0] > 0.5:
                latched_at = t
            if distance_port.Eval(context)[0] <= kappa:
                within_since = t if within_since is None else within_since
            else:
                within_since = None
            if (
                stop_after_success_s is not None
                and success_port.Eval(context)[0] > 0.5
                and within_since is not None
                and t - within_since >= stop_after_success_s - 1e-9
            ):
                break
            if index == prefix_index:  # reached only when not resumed
                _store_prefix(key, index, rlfd, context, latched_at, within_since)
    except RuntimeError as e:
        message = _first_line(e)
        kind = "policy" if message.startswith("ResidualPolicy") else "solver"
        failure = f"{kind}: {message}"
    finally:
        if meshcat is not None:
            meshcat.StopRecording()
            meshcat.PublishRecording()
            if record_html is not None:
                Path(record_html).write_text(meshcat.StaticHtml())

    forces = force_port.Eval(context)
    distance_times, distance_data = _log_so_far(rlfd, context, "distance_to_goal", prefix)
    distances = distance_data[0]
    reached = np.flatnonzero(distances <= kappa)
    if reached.size:
        insertion_time = float(distance_times[reached[0]])
    else:
        # Within kappa only between log samples: the end of the chunk that latched it.
        insertion_time = nan if latched_at is None else latched_at
    force_times, force_data = _log_so_far(rlfd, context, "force_metrics", prefix)
    peak_time, peak_distance = _when_peaked(
        force_times,
        force_data[0],
        float(forces[0]),
        distance_times,
        distances,
    )
    metrics = {
        "peak_force_time_s": peak_time,
        "peak_force_distance_m": peak_distance,
        "insertion_time_s": insertion_time,
        "peak_force_n": float(forces[0]),
        "mean_force_n": float(forces[1]),
        "peak_torque": float(forces[2]),
        "peak_low_passed_force_n": float(forces[3]),
        "force_limit_broken": force_limit_broken,
    }
    plant = rlfd.scene.plant
    X_WP = rlfd.scene.frame_P.CalcPoseInWorld(plant.GetMyContextFromRoot(context))
    X_WGoal = GoalPoseInWorld(rlfd.scene, plant.GetMyContextFromRoot(context))
    metrics["final_distance_m"] = float(np.linalg.norm(X_WP.translation() - X_WGoal.translation()))
    metrics["final_angle_deg"] = math.degrees(
        X_WGoal.rotation().InvertAndCompose(X_WP.rotation()).ToAngleAxis().angle()
    )
    if failure is not None:
        return result(failure, False, **metrics)
    if force_limit_broken:
        broken = np.flatnonzero(force_data[3] > task.force_limit_n)
        k = int(broken[0]) if broken.size else -1
        when = f"at t = {force_times[k]:.2f} s, {1e3 * distances[k]:.1f} mm from the goal"
        reason = f"force_limit: {forces[3]:.1f} N (low-passed) > {task.force_limit_n:g} N {when}"
        return result(reason, False, **metrics)
    latched = bool(success_port.Eval(context)[0] > 0.5) or reached.size > 0
    if not latched:
        X_WF = FixturePoseInWorld(rlfd.scene, plant.GetMyContextFromRoot(context))
        return result(_final_failure_kind(task, X_WF, X_WP), False, **metrics)
    if task.kappa_deg is not None and metrics["final_angle_deg"] > task.kappa_deg:
        angle = metrics["final_angle_deg"]
        return result(f"orientation: {angle:.1f} deg > {task.kappa_deg:g} deg", False, **metrics)
    return result(None, True, **metrics)


def _store_prefix(
    key: str,
    index: int,
    rlfd,
    context,
    latched_at: float | None,
    within_since: float | None,
) -> None:
    """Keeps the episode so far (see ``run_episode``'s ``reuse_prefix``)."""
    logs = {}
    for name in EPISODE_LOGS:
        log = rlfd.logs[name].FindLog(context)
        logs[name] = (log.sample_times().copy(), log.data().copy())
    _PREFIX_CACHE[key] = _EpisodePrefix(
        index, SnapshotDiagramState(rlfd, context), latched_at, within_since, logs
    )
    _PREFIX_STATS["stored"] += 1
    while len(_PREFIX_CACHE) > _PREFIX_CACHE_SIZE:
        _PREFIX_CACHE.popitem(last=False)


def _log_so_far(
    rlfd, context, name: str, prefix: _EpisodePrefix | None
) -> tuple[np.ndarray, np.ndarray]:
    """(sample times, data) of an episode log, the stored prefix's samples first when
    the episode resumed from one (the resumed log starts at the snapshot's time)."""
    log = rlfd.logs[name].FindLog(context)
    times, data = log.sample_times(), log.data()
    if prefix is None:
        return times, data
    prefix_times, prefix_data = prefix.logs[name]
    later = times > prefix_times[-1] if prefix_times.size else np.ones(times.size, bool)
    return (
        np.concatenate([prefix_times, times[later]]),
        np.concatenate([prefix_data, data[:, later]], axis=1),
    )


def _when_peaked(
    times: np.ndarray,
    running_peak: np.ndarray,
    peak: float,
    distance_times: np.ndarray,
    distances: np.ndarray,
) -> tuple[float, float]:
    """(time, distance to goal) of the first log sample whose running peak force is the
    episode's ``peak``; (nan, nan) without samples or without contact. A peak felt
    after the last sample is dated at the last sample."""
    if times.size == 0 or peak <= 0.0:
        return float("nan"), float("nan")
    reached = np.flatnonzero(running_peak >= peak - 1e-9)
    k = int(reached[0]) if reached.size else times.size - 1
    t = float(times[k])
    distance = float(np.interp(t, distance_times, distances)) if distances.size else float("nan")
    return t, distance


def _first_line(error: BaseException) -> str:
    """The first non-empty line of an exception's message (Drake's are long)."""
    for line in str(error).splitlines():
        if line.strip():
            return line.strip()[:300]
    return type(error).__name__
