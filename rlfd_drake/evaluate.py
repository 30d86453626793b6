"""Evaluation harness: a policy over the paper's perturbation grids, in parallel, with
the paper's metrics (success rate, insertion time, contact forces, success vs
perturbation size) written to ``results/`` as JSON, Markdown and a PNG plot.

Policies are named by a string, so that worker processes can build their own:

* ``"dmp"``: the DMP alone (zero residual).
* ``"random"``: the Random baseline (uniform corrections in [-1, 1]; which parts are
  randomised follows ``residual_mode``), reseeded per episode from (seed, episode).
* ``"force_search"``: a hand-written force-guided search (not a paper baseline: a
  reference for what the observation allows; see ``baselines/force_guided.py``);
  ``"force_search_toward"`` its mirror image, pushing toward the centre of pressure
  (for a hole that goes onto a shaft).
* ``"slope"`` / ``"fixture_oracle"``: a constant rotation that undoes the table slope /
  the episode's whole fixture rotation (references that know what the robot does not;
  ``baselines/orientation_reference.py``), e.g. ``"force_search|fixture_oracle"``.
* a path to a Stable-Baselines3 model ``.zip`` (PPO, SAC, TD3 or sb3-contrib
  RecurrentPPO, told apart by the zip's metadata; ``"ppo:path"``, ``"sac:path"``,
  ``"td3:path"``, ``"recurrent_ppo:path"`` force the class), run deterministically.
* a path to an episodic baseline ``baseline.npz`` (``rlfd baseline``: PoWER/FDG DMP
  weights, the eNAC coupling policy or the RLS linear residual), run with its mean.
* ``"<translation spec>|<orientation spec>"``: Table IV's "translation policy /
  orientation policy" rows, e.g. ``"runs/.../baseline.npz|random"`` (Linear / Random):
  each part is any residual spec above ("dmp" = no correction of that part).
* ``"<a.zip>+<b.zip>[+...]"``: an ensemble of saved policies trained alike (same
  residual mode, no base correction), acting with the mean of their mean actions
  (``MeanOfPolicies``); e.g. three training seeds of one recipe.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import shlex
import time
import zlib
from collections import Counter, OrderedDict
from contextlib import contextmanager
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from rlfd_drake.affinity_pool import AffinityPool
from rlfd_drake.diagram import RlfdDiagramConfig
from rlfd_drake.episode import (
    EpisodeResult,
    EpisodeSpec,
    load_task_dmp,
    make_episode_specs,
    run_episode,
)
from rlfd_drake.policies import (
    RUN_SUBFOLDERS,
    DeployedPolicy,
    MeanOfPolicies,
    check_noise_scale,
    check_residual_mode,
    existing_policy_file,
    load_sb3_model,
    policy_file,
    trained_base_correction,
    trained_residual_mode,
)
from rlfd_drake.results import (
    capped_stem,
    compact_png,
    episodes_path,
    read_episodes,
    results_dir,
    write_episodes,
    write_result,
)
from rlfd_drake.run_queue import check_count
from rlfd_drake.tasks import TaskSpec, load_task

__all__ = [
    "EPISODE_GROUPINGS",
    "diagram_residual_mode",
    "RESULT_KEYS",
    "evaluate",
    "evaluation_name",
    "make_policy",
    "policy_stem",
    "trained_mode",
    "write_evaluation",
    "plot_success_panels",
    "plot_peak_forces",
    "success_by_group",
    "shared_evaluation_workers",
]

#: Keys of the dict returned by :func:`evaluate`.
RESULT_KEYS = (
    "task",
    "policy",
    "policy_sha256",
    "residual_mode",
    "seed",
    "grid",
    "episodes",
    "success_rate",
    "success_std",
    "success_std_kind",
    "insertion_time_s",
    "insertion_time_std_s",
    "peak_force_n",
    "mean_force_n",
    "peak_joint_contact_torque_nm",
    "peak_low_passed_force_n",
    "forces_by_outcome",
    "per_bin",
    "failures",
    "wall_time_s",
    "episode_table",
)

#: (policy spec, its file's modification time and size) -> (loaded SB3 model, the rule
#: it was trained on top of or None), read once per process and file version:
#: ``make_policy`` runs for every episode, and a worker outlives an evaluation
#: (``shared_evaluation_workers``) while a run may be retrained at the same path.
#: The least recently used go beyond ``_MODEL_CACHE_SIZE`` models (about 2 MB each): a
#: worker of ``rlfd reproduce`` meets some sixty policy files, one evaluation at most
#: an ensemble's few.
_MODEL_CACHE: OrderedDict[tuple[str, int, int], tuple[object, str | None]] = OrderedDict()
_MODEL_CACHE_SIZE = 8
#: Policies named by a word rather than a file.
NAMED_POLICIES = ("dmp", "random", "force_search", "force_search_toward", "slope", "fixture_oracle")


#: Joins the saved policies of an ensemble spec ("a.zip+b.zip").
ENSEMBLE_SEPARATOR = "+"


def ensemble_members(policy_spec: str, deterministic: bool = True) -> list[str]:
    """The saved policies of an ensemble spec, checked: two or more ``.zip`` files,
    trained with one residual mode and without a base correction (so that their actions
    are the same kind of residual and can be averaged), run with their mean actions
    (``deterministic``: sampling is not defined for an ensemble)."""
    if not deterministic:
        raise ValueError(
            f"an ensemble acts with its members' mean actions; it has a mean action only, "
            f"no sampled actions: {policy_spec!r}"
        )
    members = policy_spec.split(ENSEMBLE_SEPARATOR)
    if len(members) < 2 or not all(m.endswith(".zip") for m in members):
        raise ValueError(
            f"an ensemble is two or more saved policies 'a.zip+b.zip', got {policy_spec!r}"
        )
    modes = {trained_residual_mode(policy_file(m)) or "full" for m in members}
    if len(modes) > 1:
        raise ValueError(f"an ensemble's policies were trained with residual modes {sorted(modes)}")
    corrected = [m for m in members if trained_base_correction(policy_file(m)) is not None]
    if corrected:
        raise ValueError(f"an ensemble cannot average policies trained on a rule: {corrected}")
    return members


def make_policy(
    policy_spec: str,
    residual_mode: str = "full",
    episode_seed: int = 0,
    deterministic: bool = True,
    task: TaskSpec | None = None,
    dmp=None,
    noise_scale: float = 1.0,
    fixture_dq=None,
):
    """The residual policy of ``policy_spec`` for one episode (None for "dmp").

    ``episode_seed`` seeds the random baseline; a saved model is loaded once per
    process and shared (its recurrent state is reset at every episode start). A
    baseline ``.npz`` is allowed here only as a part of a split spec (whole, it may
    replace the DMP: see ``_init_worker``); ``task`` and ``dmp`` are then needed.
    ``noise_scale`` scales a saved model's sampling noise (see DeployedPolicy).
    ``fixture_dq`` is the episode's fixture rotation error, which only
    ``"fixture_oracle"`` reads (and needs).
    """
    if "|" in policy_spec:
        from rlfd_drake.baselines.split import SplitResidualPolicy

        parts = policy_spec.split("|")
        if len(parts) != 2:
            raise ValueError(f"a split policy is 'translation|orientation', got {policy_spec!r}")
        return SplitResidualPolicy(
            make_policy(
                parts[0], "translation", episode_seed, deterministic, task, dmp, noise_scale
            ),
            make_policy(
                parts[1],
                "orientation",
                episode_seed + 1,
                deterministic,
                task,
                dmp,
                noise_scale,
                fixture_dq,
            ),
        )
    if ENSEMBLE_SEPARATOR in policy_spec:
        members = ensemble_members(policy_spec, deterministic)
        return MeanOfPolicies(
            [make_policy(m, residual_mode, episode_seed, task=task) for m in members]
        )
    if policy_spec == "dmp":
        return None
    if policy_spec.endswith(".npz"):
        from rlfd_drake.baselines.episodic import load_baseline

        if task is None or dmp is None:
            raise ValueError(f"{policy_spec}: a baseline needs the task and its DMP")
        kit = load_baseline(policy_spec, task, dmp, seed=episode_seed)
        if kit.policy is None or kit.coupling_policy is not None:
            raise ValueError(
                f"{policy_spec} changes the DMP, not the residual: it cannot be one part "
                "of a translation|orientation policy"
            )
        return kit.policy
    if policy_spec in ("force_search", "force_search_toward", "slope"):
        # The hand-written rules' one registry (also rlfd train's --base-correction).
        from rlfd_drake.base_correction import make_base_correction

        return make_base_correction(policy_spec, task)
    if policy_spec == "fixture_oracle":
        from rlfd_drake.base_correction import check_offset_rule
        from rlfd_drake.baselines.orientation_reference import fixture_rotation_residual

        check_offset_rule(policy_spec, task)
        if task is None:
            raise ValueError(f"{policy_spec}: a constant rotation reference needs the task")
        if fixture_dq is None:
            raise ValueError("fixture_oracle needs the episode's fixture error (rlfd evaluate)")
        return fixture_rotation_residual(task, fixture_dq)
    if policy_spec == "random":
        from rlfd_drake.baselines.random_policy import RandomResidualPolicy

        return RandomResidualPolicy(
            episode_seed,
            translation=residual_mode in ("full", "translation"),
            orientation=residual_mode in ("full", "orientation"),
        )
    path = policy_file(policy_spec)
    stat = path.stat() if path.exists() else None  # load_sb3_model says it is missing
    key = (policy_spec, stat.st_mtime_ns, stat.st_size) if stat else (policy_spec, 0, 0)
    if key not in _MODEL_CACHE:
        try:
            import torch

            torch.set_num_threads(1)
        except ImportError:  # pragma: no cover - torch is a dependency
            pass
        _MODEL_CACHE[key] = (
            load_sb3_model(policy_spec)[0],
            trained_base_correction(path),
        )
        while len(_MODEL_CACHE) > _MODEL_CACHE_SIZE:
            _MODEL_CACHE.popitem(last=False)
    _MODEL_CACHE.move_to_end(key)
    model, base_correction = _MODEL_CACHE[key]
    policy = DeployedPolicy(
        model,
        residual_mode,
        deterministic=deterministic,
        seed=episode_seed,
        noise_scale=noise_scale,
    )
    if base_correction is None:
        return policy
    from rlfd_drake.base_correction import BaseCorrectedPolicy, make_base_correction

    # Trained on top of a rule: it acts on top of the same rule, on its own part of the
    # residual (the diagram applies the whole: diagram_residual_mode).
    return BaseCorrectedPolicy(make_base_correction(base_correction, task), policy, residual_mode)


# --------------------------------------------------------------------------------------
# Running episodes (in this process or in workers).
# --------------------------------------------------------------------------------------
_WORKER: dict[str, object] = {}
#: The pool ``evaluate`` reuses inside ``shared_evaluation_workers`` ("workers", "pool";
#: empty outside one).
_SHARED_POOL: dict[str, object] = {}


@contextmanager
def shared_evaluation_workers(workers: int):
    """Within this block every ``evaluate`` with ``workers`` workers runs its episodes
    in one pool of processes, spawned once, instead of a pool per evaluation: a
    spawned worker imports pydrake and torch afresh (1.5-4 s an evaluation, against
    about 1 s an episode on two cores; ``rlfd reproduce`` evaluates dozens). A
    worker sets itself up again whenever an episode comes from another evaluation,
    and keeps the DMP-only first halves of the episodes it ran (``run_episode``'s
    ``reuse_prefix``): an ``AffinityPool`` sends each start back to the worker that
    ran it before. Nested blocks with the same count share the outer pool."""
    check_count("workers", workers)
    if workers == 1 or _SHARED_POOL.get("workers") == workers:
        yield
        return
    outer = dict(_SHARED_POOL)
    with AffinityPool(workers) as pool:
        _SHARED_POOL.update(workers=workers, pool=pool)
        try:
            yield
        finally:
            _SHARED_POOL.clear()
            _SHARED_POOL.update(outer)


def _init_worker(
    task_name: str,
    policy_spec: str,
    residual_mode: str,
    config: RlfdDiagramConfig,
    deterministic: bool = True,
    noise_scale: float = 1.0,
) -> None:
    task = load_task(task_name)
    _WORKER.clear()
    _WORKER.update(
        setup=(task_name, policy_spec, residual_mode, config, deterministic, noise_scale),
        task=task,
        dmp=load_task_dmp(task),
        policy_spec=policy_spec,
        residual_mode=residual_mode,
        config=config,
        deterministic=deterministic,
        noise_scale=noise_scale,
        kit=None,
    )
    if policy_spec.endswith(".npz") and "|" not in policy_spec:
        # An episodic baseline (rlfd baseline): it may replace the DMP or drive its
        # coupling term, so it is loaded as a kit rather than a residual policy.
        from rlfd_drake.baselines.episodic import load_baseline

        _WORKER["kit"] = load_baseline(policy_spec, task, _WORKER["dmp"])
    elif policy_spec not in NAMED_POLICIES:
        # Load the models once, fail early.
        make_policy(
            policy_spec,
            residual_mode,
            deterministic=deterministic,
            task=task,
            dmp=_WORKER["dmp"],
            noise_scale=noise_scale,
            fixture_dq=(1.0, 0.0, 0.0, 0.0),  # a check: each episode passes its own
        )


def _run_one(job: tuple[tuple, int, int, EpisodeSpec]) -> tuple[int, EpisodeResult]:
    """Runs episode ``index`` of the evaluation set up by ``setup`` (``_init_worker``'s
    arguments), setting this process up first if its last episode was another's."""
    setup, index, episode_seed, spec = job
    if _WORKER.get("setup") != setup:
        _init_worker(*setup)
    kit = _WORKER.get("kit")
    if kit is not None:
        result = run_episode(
            _WORKER["task"],
            kit.dmp,
            spec,
            policy=kit.policy,
            coupling_policy=kit.coupling_policy,
            diagram_config=_WORKER["config"],
        )
        return index, result
    policy = make_policy(
        _WORKER["policy_spec"],
        _WORKER["residual_mode"],
        episode_seed,
        _WORKER["deterministic"],
        _WORKER["task"],
        _WORKER["dmp"],
        _WORKER["noise_scale"],
        spec.fixture_dq,
    )
    result = run_episode(
        _WORKER["task"], _WORKER["dmp"], spec, policy=policy, diagram_config=_WORKER["config"]
    )
    return index, result


def _rounded_or_none(value: float, digits: int) -> float | None:
    """``round(value, digits)``, or None for nan (JSON has no nan)."""
    return None if math.isnan(value) else round(value, digits)


def _binomial_std(p: float, n: int) -> float:
    return math.sqrt(p * (1.0 - p) / n) if n > 0 else float("nan")


#: Ways to group an evaluation's episodes by what the robot could not see: name ->
#: (episode_table column, unit, default group edges). The rotation groups are finer
#: because a plug with 0.25 mm of clearance jams within a degree or two.
EPISODE_GROUPINGS = {
    "fixture_position": ("fixture_error_mm", "mm", (0.0, 1.0, 2.0, 3.0, math.inf)),
    "fixture_rotation": ("fixture_error_deg", "deg", (0.0, 1.0, 1.5, 2.0, 2.5, math.inf)),
    # The side of the hole the fixture moved to: the quarter of the world's x-y plane
    # its position error points into (``fixture_direction_deg``).
    "fixture_direction": ("fixture_error_direction_deg", "deg", (-45.0, 45.0, 135.0, 225.0, 315.0)),
}
#: The sides of the world's x-y plane that ``fixture_direction``'s default groups are.
FIXTURE_SIDES = {-45.0: "+x", 45.0: "+y", 135.0: "-x", 225.0: "-y"}
#: Edges (mm) of the fixture position error groups of :func:`success_by_fixture_error`.
FIXTURE_ERROR_EDGES_MM = EPISODE_GROUPINGS["fixture_position"][2]


def success_by_group(
    result: dict, by: str = "fixture_position", edges: tuple[float, ...] | None = None
) -> list[dict]:
    """Success and failure kinds in groups of one of :data:`EPISODE_GROUPINGS`, from an
    evaluation's episode table (so stored evaluations can be regrouped): a list of
    ``{"from", "to", "n", "success_rate", "failures": {kind: count}}``, empty groups
    left out, ``from <= value < to``.

    Raises:
        ValueError: ``by`` is not a grouping, ``edges`` do not increase, or the
            evaluation was stored before its table had the grouping's column.
    """
    if by not in EPISODE_GROUPINGS:
        raise ValueError(f"by must be one of {sorted(EPISODE_GROUPINGS)}, got {by!r}")
    column, _, default_edges = EPISODE_GROUPINGS[by]
    edges = default_edges if edges is None else tuple(float(e) for e in edges)
    if len(edges) < 2 or any(b <= a for a, b in itertools.pairwise(edges)):
        raise ValueError(f"edges must increase, got {edges}")
    table = result["episode_table"]
    if column not in table:
        raise ValueError(f"the evaluation's episode table has no {column!r} column")
    value = np.asarray(table[column], dtype=float)
    success = np.asarray(table["success"], dtype=bool)
    failure = table.get("failure", [None] * len(success))
    groups = []
    for low, high in itertools.pairwise(edges):
        mask = (value >= low) & (value < high)
        if np.any(mask):
            kinds = Counter(
                str(reason).split(":")[0]
                for reason, inside in zip(failure, mask, strict=True)
                if inside and reason is not None
            )
            groups.append(
                {
                    "from": low,
                    "to": high,
                    "n": int(mask.sum()),
                    "success_rate": float(success[mask].mean()),
                    "failures": dict(sorted(kinds.items())),
                }
            )
    return groups


def fixture_direction_deg(fixture_dp) -> float:
    """The direction of a fixture position error in the world's x-y plane, deg, in
    [-45, 315): 0 = +x, 90 = +y (0 for no lateral error)."""
    angle = math.degrees(math.atan2(float(fixture_dp[1]), float(fixture_dp[0])))
    return angle + 360.0 if angle < -45.0 else angle


def stored_fixture_directions(record: dict, result: dict) -> list[float]:
    """``fixture_error_direction_deg`` of an evaluation stored before its episode table
    had that column: the starts are drawn again from the task its command names
    (``--task``), its seed, episode count and grid, and checked against the stored
    fixture errors' sizes.

    Raises:
        ValueError: the command names no task, or the starts drawn again are not the
            stored ones (the task or the start sampling has changed since).
    """
    words = shlex.split(record.get("command") or "")
    if "--task" not in words[:-1]:
        raise ValueError(
            f"the evaluation stores no fixture directions and its command names no --task: "
            f"{record.get('command')!r}"
        )
    task = load_task(words[words.index("--task") + 1])
    specs = make_episode_specs(task, int(result["episodes"]), int(result["seed"]), result["grid"])
    sizes = [1e3 * float(np.linalg.norm(s.fixture_dp)) for s in specs]
    stored = result["episode_table"]["fixture_error_mm"]
    if len(stored) != len(sizes) or np.max(np.abs(np.subtract(stored, sizes))) > 0.006:
        raise ValueError(
            f"the starts drawn again for {record.get('command')!r} are not the stored ones: "
            "the task or the start sampling has changed since"
        )
    return [round(fixture_direction_deg(s.fixture_dp), 1) for s in specs]


def success_by_fixture_error(
    result: dict, edges_mm: tuple[float, ...] = FIXTURE_ERROR_EDGES_MM
) -> list[dict]:
    """Success in groups of the unseen fixture position error |dp| (mm): a list of
    ``{"from_mm", "to_mm", "n", "success_rate"}`` (:func:`success_by_group`). It tells
    whether a residual searches (success where the DMP's landing misses the hole) or
    only keeps the DMP's successes."""
    try:
        groups = success_by_group(result, "fixture_position", edges_mm)
    except ValueError as error:
        raise ValueError(f"edges_mm: {error}") from error
    return [
        {"from_mm": g["from"], "to_mm": g["to"], "n": g["n"], "success_rate": g["success_rate"]}
        for g in groups
    ]


def _summarise(task: TaskSpec, specs: list[EpisodeSpec], results: list[EpisodeResult]) -> dict:
    success = np.array([r.success for r in results], dtype=float)
    n = len(results)
    p = float(success.mean())
    bins = sorted({s.bin_index for s in specs})
    per_bin = []
    for b in bins:
        idx = [i for i, s in enumerate(specs) if s.bin_index == b]
        per_bin.append(
            {
                "bin": b,
                "n": len(idx),
                "success_rate": float(success[idx].mean()),
                "position_offset_m": float(
                    np.mean([specs[i].start_position_offset_m for i in idx])
                ),
                "rotation_offset_deg": float(
                    np.mean([specs[i].start_rotation_offset_deg for i in idx])
                ),
            }
        )
    if len(per_bin) > 1:
        std = float(np.std([b["success_rate"] for b in per_bin]))
        std_kind = f"std of the success rate over {len(per_bin)} bins"
    else:
        std = _binomial_std(p, n)
        std_kind = "binomial sqrt(p (1 - p) / n)"
    times = np.array([r.insertion_time_s for r in results if r.success])
    times = times[np.isfinite(times)]
    ok = success > 0.5

    # EpisodeResult fields averaged over episodes (all, successes, failures).
    force_fields = (
        "peak_force_n",
        "mean_force_n",
        "peak_joint_contact_torque_nm",
        "peak_low_passed_force_n",
    )

    def force_means(chosen: list[EpisodeResult]) -> dict:
        return {
            field: float(np.mean([getattr(r, field) for r in chosen])) if chosen else None
            for field in force_fields
        }

    def forces(mask: np.ndarray) -> dict:
        chosen = [r for r, m in zip(results, mask, strict=True) if m]
        return {"n": len(chosen), **force_means(chosen)}

    failures = Counter(r.failure_kind for r in results if r.failure_kind is not None)
    table = {
        "bin": [s.bin_index for s in specs],
        "position_offset_mm": [round(1e3 * s.start_position_offset_m, 2) for s in specs],
        "rotation_offset_deg": [round(s.start_rotation_offset_deg, 2) for s in specs],
        "fixture_error_mm": [round(1e3 * float(np.linalg.norm(s.fixture_dp)), 2) for s in specs],
        "fixture_error_deg": [round(s.fixture_rotation_error_deg, 2) for s in specs],
        "fixture_error_direction_deg": [
            round(fixture_direction_deg(s.fixture_dp), 1) for s in specs
        ],
        "success": [int(r.success) for r in results],
        "insertion_time_s": [
            None if math.isnan(r.insertion_time_s) else r.insertion_time_s for r in results
        ],
        "final_distance_mm": [round(1e3 * r.final_distance_m, 2) for r in results],
        "peak_force_n": [round(r.peak_force_n, 2) for r in results],
        "peak_joint_contact_torque_nm": [round(r.peak_joint_contact_torque_nm, 2) for r in results],
        "peak_low_passed_force_n": [round(r.peak_low_passed_force_n, 2) for r in results],
        "peak_force_time_s": [_rounded_or_none(r.peak_force_time_s, 2) for r in results],
        "peak_force_distance_mm": [
            _rounded_or_none(1e3 * r.peak_force_distance_m, 2) for r in results
        ],
        "failure": [r.failure_reason for r in results],
    }
    return {
        "success_rate": p,
        "success_std": std,
        "success_std_kind": std_kind,
        "insertion_time_s": float(times.mean()) if times.size else None,
        "insertion_time_std_s": float(times.std()) if times.size else None,
        **force_means(results),
        "forces_by_outcome": {"success": forces(ok), "failure": forces(~ok)},
        "per_bin": per_bin,
        "failures": dict(sorted(failures.items())),
        "episode_table": table,
        "sim_time_s": float(sum(r.sim_time_s for r in results)),
        "episode_wall_time_s": float(sum(r.wall_time_s for r in results)),
    }


def evaluate(
    task_name: str,
    policy_spec: str,
    episodes: int,
    seed: int,
    workers: int = 2,
    grid: bool = True,
    residual_mode: str = "full",
    diagram_config: RlfdDiagramConfig | None = None,
    progress: bool = True,
    deterministic: bool = True,
    composition: str = "residual",
    noise_scale: float = 1.0,
) -> dict:
    """Evaluates a policy on ``episodes`` starts of a task.

    Args:
        task_name: a shipped task name or a task YAML path.
        policy_spec: one of ``NAMED_POLICIES`` or a saved policy (see module docstring).
        episodes: number of episodes (the paper: 500 for the pegs, 160 for gear/RJ-45).
        seed: seed of the starts, fixture errors and random policies.
        workers: processes (spawn); 1 runs in this process.
        grid: the paper's evaluation grid (True) or training-style random starts.
        residual_mode: "full", "translation", "orientation" or "off" (composer mode;
            for a policy trained on a base correction, the part it corrects: the
            diagram then applies the full residual, the rule's and that part).
        diagram_config: rates and gains (default RlfdDiagramConfig()); its
            residual_mode is replaced by ``residual_mode`` (or "full", above).
        progress: show a tqdm progress bar.
        deterministic: a trained policy acts with its mean (True) or samples from its
            Gaussian, seeded per episode (False).
        composition: how the action sets the set-point (``diagram.COMPOSITIONS``:
            "residual" for rLfD, "hybrid" / "pure" for policies trained that way);
            replaces ``diagram_config``'s.
        noise_scale: with ``deterministic=False``, the factor on the policy's standard
            deviation (1: as trained; see DeployedPolicy).

    Returns:
        A JSON-serialisable dict with :data:`RESULT_KEYS`: ``success_rate`` (0..1),
        ``success_std`` (the standard deviation of the per-bin success rates if the
        grid has several bins, else the binomial sqrt(p (1 - p) / n);
        ``success_std_kind`` says which), ``insertion_time_s`` (mean over successes,
        s, None if none), ``peak_force_n`` and ``mean_force_n`` (means over episodes
        of the episode's peak and time-averaged total contact force, N),
        ``peak_joint_contact_torque_nm`` (mean over episodes of the peak generalised
        contact torque on an arm joint, N m: the paper's "generalised forces felt"),
        ``peak_low_passed_force_n`` (mean of the peak of the 20 ms low-passed total
        contact force, N: without the one-step impact spikes),
        ``forces_by_outcome``, ``per_bin`` (bin, n, success_rate, mean
        position_offset_m, mean rotation_offset_deg), ``failures`` (count per
        failure kind), ``wall_time_s`` and a compact per-episode ``episode_table``.
    """
    wall_start = time.perf_counter()
    if episodes <= 0:
        raise ValueError(f"episodes must be positive, got {episodes}")
    if workers <= 0:
        raise ValueError(f"workers must be positive, got {workers}")
    check_noise_scale(noise_scale)
    if deterministic and noise_scale != 1.0:
        raise ValueError(f"noise_scale {noise_scale} needs sampled actions (deterministic=False)")
    task = load_task(task_name)
    parts = policy_spec.split("|")
    part_modes = [residual_mode] if len(parts) == 1 else ["translation", "orientation"]
    for part, mode in zip(parts, part_modes, strict=False):
        if ENSEMBLE_SEPARATOR in part:
            # Checked here, not in a worker: a worker's error would respawn it.
            for member in ensemble_members(part, deterministic):
                check_residual_mode(existing_policy_file(member), mode)
        elif part.endswith(".zip"):
            check_residual_mode(existing_policy_file(part), mode)
        elif part not in NAMED_POLICIES and not policy_file(part).is_file():
            raise ValueError(
                f"policy {part!r} is neither a named policy ({', '.join(NAMED_POLICIES)}) "
                "nor a saved policy file"
            )
    if noise_scale != 1.0:
        saved = [part for part in parts if part.endswith(".zip")]
        if not saved:
            raise ValueError(f"noise_scale {noise_scale} needs a saved policy, got {policy_spec!r}")
        for part in saved:  # here, not in a worker: a worker's error would respawn it
            DeployedPolicy(load_sb3_model(part)[0], deterministic=False, noise_scale=noise_scale)
    config = replace(
        diagram_config if diagram_config is not None else RlfdDiagramConfig(),
        residual_mode=diagram_residual_mode(policy_spec, residual_mode),
        composition=composition,
    )
    fingerprint = policy_fingerprint(policy_spec)
    specs = make_episode_specs(task, episodes, seed, grid)
    episode_seeds = np.random.SeedSequence([seed, 1]).generate_state(episodes).tolist()
    setup = (task_name, policy_spec, residual_mode, config, deterministic, noise_scale)
    jobs = [(setup, i, int(episode_seeds[i]), spec) for i, spec in enumerate(specs)]

    from tqdm.auto import tqdm

    bar = tqdm(total=episodes, desc=f"{task.name} {Path(policy_spec).name}", disable=not progress)
    results: list[EpisodeResult | None] = [None] * episodes
    success_count = 0

    def collect(index: int, result: EpisodeResult) -> None:
        nonlocal success_count
        results[index] = result
        success_count += int(result.success)
        bar.update(1)
        bar.set_postfix(success=f"{success_count}/{bar.n}")

    # A start runs on the worker that ran it before, which kept its DMP-only first
    # half (run_episode's reuse_prefix).
    affinities = [zlib.crc32(repr(spec).encode()) for spec in specs]
    try:
        if workers == 1:
            _init_worker(*setup)  # afresh: this process's last evaluation may be older
            for job in jobs:
                collect(*_run_one(job))
        elif _SHARED_POOL.get("workers") == workers:
            pool = _SHARED_POOL["pool"]
            for index, result in pool.imap_unordered(_run_one, jobs, affinities):
                collect(index, result)
        else:
            with AffinityPool(min(workers, episodes)) as pool:
                for index, result in pool.imap_unordered(_run_one, jobs, affinities):
                    collect(index, result)
    finally:
        bar.close()

    done = [r for r in results if r is not None]
    summary = _summarise(task, specs, done)
    return {
        "task": task.name,
        "policy": policy_spec,
        # Read before the episodes: a file rewritten during them is not what they ran.
        "policy_sha256": fingerprint,
        "residual_mode": residual_mode,
        "composition": composition,
        "residual_bounds": list(config.residual_bounds(task)),
        # False in evaluations stored before 2026-12-06 (the key was absent): the
        # policy was called from the start, its unapplied actions in its observations.
        "residual_policy_from_activation": config.residual_policy_from_activation,
        "deterministic": deterministic,
        "noise_scale": None if deterministic else noise_scale,
        "seed": seed,
        "grid": grid,
        "episodes": episodes,
        **summary,
        "workers": workers,
        "wall_time_s": time.perf_counter() - wall_start,
    }


# --------------------------------------------------------------------------------------
# Writing results.
# --------------------------------------------------------------------------------------
def _fmt(value: float | None, scale: float = 1.0, digits: int = 1) -> str:
    return "n/a" if value is None else f"{scale * value:.{digits}f}"


def evaluation_markdown(result: dict) -> str:
    """A Markdown table of one evaluation (success mean +- std in %, insertion time,
    peak and mean contact force), then the per-bin success and the failure counts."""
    r = result
    lines = [
        f"# {r['task']}: {r['policy']} (residual {r['residual_mode']})",
        "",
        f"{r['episodes']} episodes, seed {r['seed']}, "
        f"{'evaluation grid' if r['grid'] else 'training starts'}; "
        f"std = {r['success_std_kind']}.",
        "",
        "| task | policy | success % | insertion time s | peak force N | mean force N | episodes |",
        "|---|---|---|---|---|---|---|",
        f"| {r['task']} | {r['policy']} | {_fmt(r['success_rate'], 100)} +- "
        f"{_fmt(r['success_std'], 100)} | {_fmt(r['insertion_time_s'], digits=2)} | "
        f"{_fmt(r['peak_force_n'])} | {_fmt(r['mean_force_n'], digits=2)} | {r['episodes']} |",
        "",
        "| bin | n | success % | mean start offset mm | mean start rotation deg |",
        "|---|---|---|---|---|",
    ]
    for b in r["per_bin"]:
        lines.append(
            f"| {b['bin']} | {b['n']} | {_fmt(b['success_rate'], 100)} | "
            f"{_fmt(b['position_offset_m'], 1e3)} | {_fmt(b['rotation_offset_deg'])} |"
        )
    lines += [
        "",
        "| unseen fixture error mm | n | success % |",
        "|---|---|---|",
    ]
    for group in success_by_fixture_error(r):
        lines.append(
            f"| {group['from_mm']:g} to {group['to_mm']:g} | {group['n']} | "
            f"{_fmt(group['success_rate'], 100)} |"
        )
    if EPISODE_GROUPINGS["fixture_rotation"][0] in r["episode_table"]:
        lines += [
            "",
            "| unseen fixture rotation deg | n | success % | failures |",
            "|---|---|---|---|",
        ]
        for group in success_by_group(r, "fixture_rotation"):
            failures = ", ".join(f"{k} {v}" for k, v in group["failures"].items()) or "none"
            lines.append(
                f"| {group['from']:g} to {group['to']:g} | {group['n']} | "
                f"{_fmt(group['success_rate'], 100)} | {failures} |"
            )
    lines += _peak_force_lines(r["episode_table"])
    failures = ", ".join(f"{k} {v}" for k, v in r["failures"].items()) or "none"
    lines += ["", f"Failures: {failures}. Wall time {r['wall_time_s']:.0f} s.", ""]
    return "\n".join(lines)


#: A peak felt this close to the goal was felt at the bottom of the insertion, mm.
_AT_THE_BOTTOM_MM = 1.0


def _peak_force_lines(table: dict) -> list[str]:
    """Markdown lines: where the episodes' peak contact forces were felt, for successes
    and failures (none for evaluations stored before the table had those columns)."""
    if "peak_force_distance_mm" not in table:
        return []
    lines = [
        "",
        "| peak force felt | n | mean peak N | median time s | median distance to goal mm "
        f"| at the bottom (< {_AT_THE_BOTTOM_MM:g} mm) |",
        "|---|---|---|---|---|---|",
    ]
    success = np.asarray(table["success"], dtype=bool)
    for label, mask in (("successes", success), ("failures", ~success)):
        rows = [
            (force, time, distance)
            for force, time, distance, chosen in zip(
                table["peak_force_n"],
                table["peak_force_time_s"],
                table["peak_force_distance_mm"],
                mask,
                strict=True,
            )
            if chosen and time is not None and distance is not None
        ]
        if not rows:
            continue
        force, time, distance = np.array(rows, dtype=float).T
        bottom = int(np.sum(distance < _AT_THE_BOTTOM_MM))
        lines.append(
            f"| {label} | {len(rows)} | {force.mean():.1f} | {np.median(time):.2f} | "
            f"{np.median(distance):.1f} | {bottom} |"
        )
    return lines


def _success_curve(result: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]:
    """(x, success rate, binomial std, n, x label) for the Fig. 4 style plot."""
    per_bin = result["per_bin"]
    if len(per_bin) > 1:
        rotations = np.array([b["rotation_offset_deg"] for b in per_bin])
        if np.max(rotations) > 1e-6:
            x, label = rotations, "mean start rotation offset (deg)"
        else:
            x = 1e3 * np.array([b["position_offset_m"] for b in per_bin])
            label = "mean start position offset (mm)"
        p = np.array([b["success_rate"] for b in per_bin])
        n = np.array([b["n"] for b in per_bin])
    else:
        table = result["episode_table"]
        offsets = np.array(table["position_offset_mm"], dtype=float)
        success = np.array(table["success"], dtype=float)
        n_groups = int(np.clip(len(offsets) // 8, 1, 6))
        edges = np.quantile(offsets, np.linspace(0.0, 1.0, n_groups + 1))
        groups = np.clip(np.searchsorted(edges, offsets, side="right") - 1, 0, n_groups - 1)
        keep = [g for g in range(n_groups) if np.any(groups == g)]
        x = np.array([offsets[groups == g].mean() for g in keep])
        p = np.array([success[groups == g].mean() for g in keep])
        n = np.array([np.sum(groups == g) for g in keep])
        label = "start position offset (mm), quantile groups"
    std = np.sqrt(p * (1.0 - p) / np.maximum(n, 1))
    return x, p, std, n, label


#: More legend entries than this go below the panels, where they hide no data.
_LEGEND_INSIDE_MAX = 3


def _pyplot():
    """matplotlib's pyplot on the file-only Agg backend (no display here)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _figure(n_panels: int, height: float, n_labels: int):
    plt = _pyplot()
    below = n_labels > _LEGEND_INSIDE_MAX
    legend_in = 0.2 * ((n_labels + 1) // 2) + 0.2 if below else 0.0
    fig, axes = plt.subplots(
        1, n_panels, figsize=(5.0 * n_panels, height + legend_in), dpi=100, squeeze=False
    )
    return plt, fig, list(axes[0]), legend_in


def _save(plt, fig, axes, path: Path, legend_in: float) -> Path:
    if legend_in:
        # One entry per label over every panel (a row may be measured in one only).
        entries = {}
        for ax in axes:
            for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
                entries.setdefault(label, handle)
        handles, labels = list(entries.values()), list(entries)
        fig.tight_layout(rect=(0, legend_in / fig.get_figheight(), 1, 1))
        fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=7, frameon=False)
    else:
        for ax in axes:
            ax.legend(fontsize=7)
        fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return compact_png(path)


def _check_panels(panels: dict[str, list[tuple[str, dict]]], what: str) -> int:
    """The number of distinct labels; refuses an empty figure or panel."""
    if not panels or not all(panels.values()):
        counts = {title: len(labelled) for title, labelled in panels.items()}
        raise ValueError(f"{what} needs evaluations in every panel, got {counts}")
    return len({label for labelled in panels.values() for label, _ in labelled})


def plot_success_vs_perturbation(results: list[dict], path: Path) -> Path:
    """Success rate against perturbation size (paper Fig. 4), one line per result,
    binomial error bars; written as PNG."""
    return plot_success_panels(
        {results[0]["task"]: [(result["policy"], result) for result in results]}, path
    )


def plot_success_panels(panels: dict[str, list[tuple[str, dict]]], path: Path) -> Path:
    """Success against perturbation size (paper Fig. 4), one panel per title (a task),
    one line per labelled evaluation with its binomial error bars; written as PNG.
    A label keeps its colour in every panel."""
    n_labels = _check_panels(panels, "plot_success_panels")
    plt, fig, axes, legend_in = _figure(len(panels), 3.4, n_labels)
    colours: dict[str, str] = {}
    for ax, (title, labelled) in zip(axes, panels.items(), strict=True):
        label = ""
        for name, result in labelled:
            x, p, std, _, label = _success_curve(result)
            colour = colours.setdefault(name, f"C{len(colours) % 10}")
            ax.errorbar(x, 100 * p, yerr=100 * std, marker="o", capsize=3, label=name, color=colour)
        ax.set_xlabel(label)
        ax.set_ylabel("success (%)")
        ax.set_ylim(-5, 105)
        ax.set_title(title)
        ax.grid(alpha=0.3)
    return _save(plt, fig, axes, path, legend_in)


def plot_peak_forces(panels: dict[str, list[tuple[str, dict]]], path: Path) -> Path:
    """Mean peak contact force per labelled evaluation, one panel per title (a task),
    the labels down a shared axis: the one-step (2 ms) peak and, where stored, the
    20 ms low-passed peak; PNG."""
    _check_panels(panels, "plot_peak_forces")
    plt = _pyplot()
    names = list(dict.fromkeys(name for labelled in panels.values() for name, _ in labelled))
    fig, axes = plt.subplots(
        1,
        len(panels),
        figsize=(3.0 + 3.0 * len(panels), 1.4 + 0.3 * len(names)),
        dpi=100,
        sharey=True,
        squeeze=False,
    )
    axes = list(axes[0])
    for ax, (title, labelled) in zip(axes, panels.items(), strict=True):
        y = np.array([names.index(name) for name, _ in labelled], dtype=float)
        peak = [result["peak_force_n"] for _, result in labelled]
        # Evaluations stored before the low-passed peak existed draw no bar, not 0 N.
        low_passed = [
            np.nan if (f := result.get("peak_low_passed_force_n")) is None else f
            for _, result in labelled
        ]
        ax.barh(y - 0.2, peak, height=0.4, label="peak (2 ms)")
        ax.barh(y + 0.2, low_passed, height=0.4, label="peak, 20 ms low-passed")
        ax.set_xlabel("mean peak contact force (N)")
        ax.set_title(title)
        ax.grid(alpha=0.3, axis="x")
    axes[0].set_yticks(np.arange(len(names)), names, fontsize=7)
    axes[0].invert_yaxis()
    return _save(plt, fig, axes[:1], path, 0.0)


def called_from_start(result: dict) -> bool:
    """True for an evaluation whose residual policy was called from the episode's start
    (stored before 2026-12-06, without ``residual_policy_from_activation``): its
    unapplied actions before the residual's activation were in its observations and
    memory, unlike in training. An evaluation of the DMP alone calls no policy."""
    if result.get("policy") == "dmp":
        return False
    return not result.get("residual_policy_from_activation", False)


def write_evaluation(
    result: dict, name: str, command: str | None = None, plot: bool = False
) -> dict[str, Path]:
    """Writes ``results/<name>.json`` (via ``results.write_result``: command, seed,
    date), ``results/<name>.md`` and, with ``plot``, ``results/<name>.png`` (the JSON
    keeps what any plot needs: ``rlfd plot`` draws it later); returns their paths.
    The per-episode table goes to ``results/<name>.episodes.json.gz`` (named in the
    JSON's ``episode_table_file``); :func:`result_from_json` joins them again."""
    summary = {key: value for key, value in result.items() if key != "episode_table"}
    table = result.get("episode_table")
    if table is not None:
        summary["episode_table_file"] = episodes_path(f"{name}.json").name
    json_path = write_result(name, summary, seed=result.get("seed"), command=command)
    paths = {"json": json_path}
    if table is not None:
        paths["episodes"] = write_episodes(json_path, table)
    md_path = results_dir() / f"{name}.md"
    md_path.write_text(evaluation_markdown(result))
    paths["md"] = md_path
    if plot:
        paths["png"] = plot_success_vs_perturbation([result], results_dir() / f"{name}.png")
    return paths


def policy_stem(spec: str) -> str:
    """A file-name stem for a policy spec: the run folder of a file ``rlfd train`` or a
    baseline always names the same (policy.zip, baseline.npz), the run folder and the
    file's stem for a checkpoint or best model (every run names them alike), else the
    file's stem; "a_and_b" for a translation|orientation split."""
    if "|" in spec:
        return "_and_".join(policy_stem(part) for part in spec.split("|"))
    if ENSEMBLE_SEPARATOR in spec:
        return "_plus_".join(policy_stem(part) for part in spec.split(ENSEMBLE_SEPARATOR))
    path = policy_file(spec)
    if path.name in ("policy.zip", "baseline.npz"):
        return path.parent.name
    if path.parent.name in RUN_SUBFOLDERS and path.parent.parent.name:
        return f"{path.parent.parent.name}_{path.stem}"
    return path.stem


def policy_fingerprint(policy_spec: str) -> str | None:
    """The SHA-256 of the saved file ``policy_spec`` names (``sha256sum`` of it); of
    several (translation|orientation parts, an ensemble's members), the SHA-256 of
    their digests, one a line, in order; None for named policies only. A stored
    evaluation keeps it, so that one of a policy retrained at the same path is measured
    again (``reproduce.stored_or_new_evaluation``) rather than reused."""
    parts = policy_spec.replace(ENSEMBLE_SEPARATOR, "|").split("|")
    digests = [
        hashlib.sha256(existing_policy_file(part).read_bytes()).hexdigest()
        for part in parts
        if part not in NAMED_POLICIES
    ]
    if len(digests) <= 1:
        return digests[0] if digests else None
    return hashlib.sha256("\n".join(digests).encode()).hexdigest()


def diagram_residual_mode(policy_spec: str, residual_mode: str) -> str:
    """The residual mode the diagram runs ``policy_spec`` with: ``residual_mode``, or
    "full" for a policy trained on a base correction (it corrects its residual_mode
    part; the rule acts on the whole residual)."""
    if "|" in policy_spec or ENSEMBLE_SEPARATOR in policy_spec or not policy_spec.endswith(".zip"):
        return residual_mode  # an ensemble's members have no base correction
    from rlfd_drake.base_correction import applied_residual_mode

    return applied_residual_mode(trained_base_correction(policy_file(policy_spec)), residual_mode)


def trained_mode(policy_spec: str) -> str:
    """The residual mode a saved policy was trained with ("full" if unknown or not a
    single saved policy)."""
    if ENSEMBLE_SEPARATOR in policy_spec and "|" not in policy_spec:
        return trained_mode(ensemble_members(policy_spec)[0])  # one mode: checked there
    if "|" in policy_spec or not policy_spec.endswith(".zip"):
        return "full"
    return trained_residual_mode(policy_file(policy_spec)) or "full"


#: Longest policy part of an evaluation's default name: an ensemble of several run
#: folders would otherwise pass the 255 bytes a file name may have (every stored
#: evaluation's policy part is shorter, so none is renamed).
POLICY_STEM_MAX = 120


def evaluation_name(
    task: str,
    policy_spec: str,
    residual_mode: str,
    stochastic: bool,
    seed: int,
    noise_scale: float = 1.0,
    episodes: int | None = None,
) -> str:
    """The results file stem ``rlfd evaluate`` gives an evaluation, e.g.
    ``eval_peg_hard_<run folder>_translation_stochastic_n40_s0`` (``..._stochastic0.5_...``
    with half the policy's noise; no ``_n40`` without ``episodes``). A task given as a
    YAML path is named by its file stem (a variant's name), as ``rlfd reproduce`` names
    it, so that each reuses the other's files."""
    mode = "" if residual_mode == "full" else f"_{residual_mode}"
    if stochastic:
        mode += sampling_suffix(noise_scale)
    count = "" if episodes is None else f"_n{episodes}"
    stem = capped_stem(policy_stem(policy_spec), POLICY_STEM_MAX)
    return f"eval_{Path(task).stem}_{stem}{mode}{count}_s{seed}"


def sampling_suffix(noise_scale: float = 1.0) -> str:
    """The file-name mark of sampled actions: ``_stochastic``, ``_stochastic0.5``."""
    return "_stochastic" + ("" if noise_scale == 1.0 else f"{noise_scale:g}")


def result_from_json(path: str | Path) -> dict:
    """The evaluation dict stored in a ``write_evaluation`` JSON file, with its
    per-episode table (kept in the JSON itself by evaluations stored before the table
    had a file of its own)."""
    return joined_evaluation(json.loads(Path(path).read_text()), path)


def joined_evaluation(record: dict, path: str | Path) -> dict:
    """The evaluation dict of an already read ``write_evaluation`` record stored at
    ``path``, its per-episode table joined back from the file beside it."""
    result = record["data"]
    if "episode_table" not in result and result.get("episode_table_file"):
        result["episode_table"] = read_episodes(path)
        del result["episode_table_file"]
    return result


def episode_result_dict(result: EpisodeResult) -> dict:
    """An EpisodeResult as a plain dict (for logs and JSON)."""
    return asdict(result)
