"""A training recipe's spread over seeds (``rlfd seeds``).

One run folder per training seed, all made by the same ``rlfd train`` configuration
apart from the seed. Each run's policy is evaluated on each task with its mean action
and with sampled actions; ``results/seeds_<name>.{json,md}`` get each seed's success,
the mean +- sample standard deviation (ddof 1) over the seeds, each run's training
episodes and wall-clock time, and, given targets, on how many seeds they are met.

Evaluations are stored under the names ``rlfd evaluate --episodes N`` gives them (or
found under the names without ``_n<N>`` that earlier studies stored) and reused when one
of the same size and seed exists, so re-running a study after adding a seed evaluates
only the new seed and replaces the stored study; a study that would leave out part of a
stored one of the same name (a seed, a task, the other starts) is refused unless
``--overwrite``. Run folders are local (``runs/`` is not committed): a folder that
is missing here is read from its copied log ``results/train_<folder name>/`` and its
stored evaluations.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from rlfd_drake.checkpoint_selection import check_validation_starts
from rlfd_drake.evaluate import evaluation_name
from rlfd_drake.reproduce import stored_or_new_evaluation
from rlfd_drake.results import (
    format_spread,
    new_result_path,
    results_dir,
    spread_over_seeds,
    write_result,
)
from rlfd_drake.run_log import run_log_folders
from rlfd_drake.train import TrainConfig

__all__ = [
    "ACTIONS",
    "SEED_SELECTION_RULE",
    "SeedRun",
    "best_of_k",
    "choose_seed",
    "format_spread",
    "load_seed_run",
    "rule_order",
    "seed_selection_markdown",
    "seed_selection_name",
    "seed_study",
    "select_seed",
    "spearman",
    "study_name",
]

#: How a run's policy can act in an evaluation: label -> sample its actions.
ACTIONS = {"mean": False, "sampled": True}


@dataclass(frozen=True)
class SeedRun:
    """A training run of a seed study: its folder, training configuration, the command
    that trained it and its metrics."""

    folder: Path
    config: dict
    command: str | None
    metrics: dict

    @property
    def seed(self) -> int:
        return int(self.config["seed"])

    @property
    def policy(self) -> Path:
        return self.folder / "policy.zip"


def load_seed_run(folder: str | Path) -> SeedRun:
    """The run in ``folder``, or (a run of another machine) its log copied into
    ``results/train_<folder name>/``; ValueError if neither holds config.json and
    metrics.json (a run still training has no metrics.json yet)."""
    folder = Path(folder)
    for base in run_log_folders(folder):
        config, metrics = base / "config.json", base / "metrics.json"
        if config.is_file() and metrics.is_file():
            recorded = json.loads(config.read_text())
            return SeedRun(
                folder, recorded["config"], recorded.get("command"), json.loads(metrics.read_text())
            )
    raise ValueError(
        f"run folder {str(folder)!r}: no finished run (config.json and metrics.json) there "
        f"or in results/train_{folder.name}/"
    )


def _recipe_value(run: SeedRun, key: str, defaults: dict):
    """The run's setting ``key`` as its recipe names it: a run saved before a setting
    existed trained with its default, and a later stage's ``init_from`` names its own
    seed's earlier run (``..._s1/policy.zip`` for seed 1), the same step of the recipe."""
    value = run.config.get(key, defaults.get(key))
    if key == "init_from" and isinstance(value, str):
        value = re.sub(rf"_s{run.seed}(?=[/\\]|$)", "_s<seed>", value)
    return value


def _check_one_recipe(runs: list[SeedRun]) -> None:
    """ValueError unless the runs differ in their seed and nothing else."""
    seeds = [run.seed for run in runs]
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"runs: each seed once, got seeds {seeds}")
    defaults = {field.name: field.default for field in fields(TrainConfig)}
    first = runs[0]
    for run in runs[1:]:
        for key in sorted(set(first.config) | set(run.config)):
            if key == "seed":
                continue
            mine, theirs = (_recipe_value(r, key, defaults) for r in (first, run))
            if mine != theirs:
                raise ValueError(
                    f"runs {str(first.folder)!r} and {str(run.folder)!r} differ in {key}: "
                    f"{mine!r} vs {theirs!r} (a seed study compares seeds of one recipe)"
                )


def study_name(folders: list[str | Path]) -> str:
    """The folders' common name without its seed suffix, e.g. ``peg_easy_sac_gs4`` for
    ``runs/peg_easy_sac_gs4_s0`` and ``runs/peg_easy_sac_gs4_s1``."""
    stems = {re.sub(r"_s\d+$", "", Path(folder).name) for folder in folders}
    if len(stems) != 1:
        raise ValueError(f"name: the run folders have no common name, pass one ({sorted(stems)})")
    return stems.pop()


def _evaluation_name(
    task: str, policy: str, mode: str, stochastic: bool, seed: int, episodes: int
) -> str:
    """The name ``rlfd evaluate --episodes N`` gives the evaluation (``..._n<N>_s<seed>``),
    or the name without the count that studies before it used, where only that one is
    stored."""
    name = evaluation_name(task, policy, mode, stochastic, seed, episodes=episodes)
    legacy = evaluation_name(task, policy, mode, stochastic, seed)
    stored = results_dir()
    if not (stored / f"{name}.json").exists() and (stored / f"{legacy}.json").exists():
        return legacy
    return name


def _run_evaluation(
    run: SeedRun,
    task: str,
    mode: str,
    composition: str,
    episodes: int,
    seed: int,
    workers: int,
    stochastic: bool = False,
    required: tuple[str, ...] = (),
) -> tuple[str, dict]:
    """(name, result) of the run's policy evaluated on ``task``: the stored evaluation
    when one fits, else a new one; ValueError when neither the policy nor a stored
    evaluation is here (a run folder of another machine without its evaluation)."""
    evaluation = _evaluation_name(task, str(run.policy), mode, stochastic, seed, episodes)
    result = stored_or_new_evaluation(
        task,
        str(run.policy),
        evaluation,
        mode,
        episodes,
        seed,
        workers,
        stochastic,
        composition,
        required=required,
        available=run.policy.is_file(),
    )
    if result is None:
        raise ValueError(
            f"run {str(run.folder)!r}: no policy.zip to evaluate and no stored "
            f"results/{evaluation}.json of {episodes} episodes, seed {seed}"
        )
    return evaluation, result


def _column_label(column: str) -> str:
    """A column "<task>/<actions>" as "<task name>, <actions>" (a YAML by its stem)."""
    task, _, label = column.rpartition("/")
    return f"{Path(task).stem}, {label}"


def seed_study(
    folders: list[str | Path],
    tasks: list[str],
    episodes: int = 200,
    seed: int = 0,
    workers: int = 2,
    targets: dict[str, float] | None = None,
    name: str | None = None,
    actions: tuple[str, ...] = tuple(ACTIONS),
    overwrite: bool = False,
) -> dict:
    """Evaluates (or reuses the stored evaluations of) every run on every task and
    writes ``results/seeds_<name>.{json,md}``; returns the JSON's data.

    A stored study of the same name is replaced only by one that keeps all of it (its
    seeds, tasks and actions, on the same evaluation starts), e.g. after adding a seed;
    one that would drop some of it raises ``FileExistsError`` unless ``overwrite``.

    Args:
        folders: one ``rlfd train`` run folder per seed.
        tasks: the evaluation tasks (e.g. the training task and a harder one).
        episodes, seed, workers: as ``rlfd evaluate``'s.
        targets: success % per task that the mean action should reach (e.g. the
            paper's); the study counts the seeds that reach all of them.
        name: results file stem after ``seeds_`` (default: the folders' common name).
        actions: which of ``ACTIONS`` to evaluate ("mean" is needed for targets).
        overwrite: replace a stored study even if this one leaves some of it out.
    """
    if not folders:
        raise ValueError("folders: give at least one run folder")
    if not tasks:
        raise ValueError("tasks: give at least one task")
    actions = tuple(actions)
    if not actions or any(action not in ACTIONS for action in actions):
        raise ValueError(f"actions must be among {tuple(ACTIONS)}, got {actions}")
    targets = dict(targets or {})
    if targets and "mean" not in actions:
        raise ValueError("targets are checked on the mean action: actions must include 'mean'")
    # A task given as a YAML path may be targeted by its name (its file stem).
    targets = {
        next((t for t in tasks if t != task and Path(t).stem == task), task): target
        for task, target in targets.items()
    }
    for task, target in targets.items():
        if task not in tasks:
            raise ValueError(f"targets: task {task!r} is not evaluated (tasks: {tasks})")
        if not 0.0 <= target <= 100.0:
            raise ValueError(f"targets: {task} must be a success % in [0, 100], got {target}")
    name = name or study_name(folders)
    runs = sorted((load_seed_run(folder) for folder in folders), key=lambda run: run.seed)
    _check_one_recipe(runs)
    columns = [f"{task}/{label}" for task in tasks for label in actions]
    if not overwrite:
        cells = {(run.seed, column) for run in runs for column in columns}
        _refuse_to_drop_a_stored_study(name, cells, episodes, seed)
    mode = runs[0].config.get("residual_mode", "full")
    composition = runs[0].config.get("composition", "residual")

    per_seed = []
    for run in runs:
        row = {
            "seed": run.seed,
            "folder": str(run.folder),
            "training_episodes": run.metrics.get("episodes"),
            # A resumed run's metrics time its last process only: not the run's time.
            "training_wall_time_s": (
                None if "resumed_at_episode" in run.metrics else run.metrics.get("wall_time_s")
            ),
            "training_resumed_at_episode": run.metrics.get("resumed_at_episode"),
            "success": {},
            "evaluations": {},
            # A policy chosen among the run's checkpoints (rlfd select): its record.
            "selection_record": run.metrics.get("selection_record"),
        }
        for task in tasks:
            for label in actions:
                evaluation, result = _run_evaluation(
                    run, task, mode, composition, episodes, seed, workers, ACTIONS[label]
                )
                row["success"][f"{task}/{label}"] = 100.0 * result["success_rate"]
                row["evaluations"][f"{task}/{label}"] = evaluation
        row["meets_targets"] = all(
            row["success"][f"{task}/mean"] >= target for task, target in targets.items()
        )
        per_seed.append(row)

    walls = [row["training_wall_time_s"] for row in per_seed if row["training_wall_time_s"]]
    data = {
        "name": name,
        "recipe": {key: value for key, value in runs[0].config.items() if key != "seed"},
        "commands": [run.command for run in runs],
        "tasks": tasks,
        "columns": columns,
        "evaluation_episodes": episodes,
        "evaluation_seed": seed,
        "targets": targets,
        "per_seed": per_seed,
        "over_seeds": {
            column: spread_over_seeds([row["success"][column] for row in per_seed])
            for column in columns
        },
        "training_wall_time_s": spread_over_seeds(walls) if walls else None,
        "seeds_meeting_targets": sum(row["meets_targets"] for row in per_seed) if targets else None,
    }
    write_result(f"seeds_{name}", data, seed=seed)
    (results_dir() / f"seeds_{name}.md").write_text(seed_study_markdown(data))
    return data


def _refuse_to_drop_a_stored_study(
    name: str, cells: set[tuple[int, str]], episodes: int, seed: int
) -> None:
    """Raises FileExistsError if ``results/seeds_<name>.json`` holds a (seed, column)
    cell the new study lacks, or was measured on other starts (episodes or seed)."""
    # The shared path helper also checks the name before any evaluation runs.
    path = new_result_path(f"seeds_{name}", overwrite=True)
    if not path.exists():
        return
    stored = json.loads(path.read_text())["data"]
    if (stored.get("evaluation_episodes"), stored.get("evaluation_seed")) != (episodes, seed):
        raise FileExistsError(
            f"{path} was measured on {stored.get('evaluation_episodes')} starts of evaluation "
            f"seed {stored.get('evaluation_seed')}, this study on {episodes} of seed {seed}; "
            "pass --overwrite or another --name"
        )
    dropped = sorted(
        (row["seed"], column)
        for row in stored.get("per_seed", [])
        for column in row.get("success", {})
        if (row["seed"], column) not in cells
    )
    if dropped:
        shown = ", ".join(f"seed {s} {column}" for s, column in dropped[:6])
        more = f" and {len(dropped) - 6} more" if len(dropped) > 6 else ""
        raise FileExistsError(
            f"{path} holds results this study leaves out ({shown}{more}); "
            "pass --overwrite or another --name"
        )


#: How ``rlfd select --runs`` chooses one of a recipe's seeds on validation starts
#: (``full_pose_study.md`` section 39, fixed there before any validation ran).
SEED_SELECTION_RULE = (
    "highest validation success; of equal ones the lower mean one-step peak force on "
    "the validation starts, then the lower seed"
)


def choose_seed(rows: list[dict]) -> int:
    """The index of the row that :data:`SEED_SELECTION_RULE` chooses; each row has the
    seed's ``seed``, validation ``success_rate`` and mean ``peak_force_n``."""
    if not rows:
        raise ValueError("rows: no seed to choose from")
    return rule_order(rows)[0]


def rule_order(rows: list[dict]) -> list[int]:
    """The rows' indices in the order :data:`SEED_SELECTION_RULE` prefers them, best first
    (``choose_seed`` is the first)."""
    return sorted(
        range(len(rows)),
        key=lambda i: (-rows[i]["success_rate"], rows[i]["peak_force_n"], rows[i]["seed"]),
    )


def best_of_k(ranked_test_rates: list[float], target: float | None = None) -> list[dict]:
    """What choosing by the rule buys when k of the n seeds are trained, for k = 1..n:
    over all C(n, k) subsets of the seeds, the mean test success of the seed the rule
    chooses in each, and (given ``target``, a rate) in how many the choice reaches it.

    ``ranked_test_rates`` are the seeds' test success rates in the rule's order (best on
    validation first, :func:`rule_order`). Exact, without enumerating subsets: the seed
    ranked r-th (from 0) is chosen in the C(n-1-r, k-1) subsets that hold it and only
    seeds ranked below it.
    """
    n = len(ranked_test_rates)
    if n == 0:
        raise ValueError("ranked_test_rates: no seed")
    rows = []
    for k in range(1, n + 1):
        chosen_in = [math.comb(n - 1 - r, k - 1) for r in range(n)]
        counted = list(zip(chosen_in, ranked_test_rates, strict=True))
        subsets = math.comb(n, k)
        row = {
            "k": k,
            "subsets": subsets,
            "mean_chosen_test_success_rate": sum(count * rate for count, rate in counted) / subsets,
        }
        if target is not None:
            row["chosen_at_target"] = sum(count for count, rate in counted if rate >= target)
        rows.append(row)
    return rows


def spearman(x: list[float], y: list[float], permutations: int = 20000, seed: int = 0) -> dict:
    """Spearman's rank correlation of ``x`` and ``y`` (ties get their mean rank) and its
    two-sided permutation p-value (``permutations`` shuffles of ``y``'s ranks, seeded, so
    the same numbers give the same p; the +1s count the observed order as one shuffle)."""
    if len(x) != len(y):
        raise ValueError(f"y: {len(y)} values for {len(x)} x values")
    if len(x) < 3:
        raise ValueError(f"x: a rank correlation needs three or more pairs, got {len(x)}")
    rank_x, rank_y = _mean_ranks(x), _mean_ranks(y)
    if np.ptp(rank_x) == 0 or np.ptp(rank_y) == 0:
        return {"rho": None, "p": None, "permutations": permutations}
    rho = float(np.corrcoef(rank_x, rank_y)[0, 1])
    rng = np.random.default_rng(seed)
    shuffled = np.array([rng.permutation(rank_y) for _ in range(permutations)])
    centred_x = rank_x - rank_x.mean()
    centred = shuffled - shuffled.mean(axis=1, keepdims=True)
    rhos = centred @ centred_x / (np.linalg.norm(centred, axis=1) * np.linalg.norm(centred_x))
    extreme = int(np.sum(np.abs(rhos) >= abs(rho) - 1e-12))
    return {"rho": rho, "p": (extreme + 1) / (permutations + 1), "permutations": permutations}


def _mean_ranks(values: list[float]) -> np.ndarray:
    """Ranks from 1, tied values sharing their mean rank."""
    values = np.asarray(values, dtype=float)
    order = np.argsort(values, kind="stable")
    ranks = np.empty(len(values))
    ranks[order] = np.arange(1, len(values) + 1)
    for value in np.unique(values):
        tied = values == value
        ranks[tied] = ranks[tied].mean()
    return ranks


def seed_selection_name(name: str, episodes: int | list[int], seed: int | list[int]) -> str:
    """The results stem of a seed selection: ``select_seeds_<name>_n<episodes>_s<seed>``;
    validation starts of several seeds pooled join theirs with "+" (``_n100+200_s1+4``)."""
    return f"select_seeds_{name}_n{_joined(episodes)}_s{_joined(seed)}"


def _joined(value: int | list[int]) -> str:
    return "+".join(str(v) for v in value) if isinstance(value, list) else str(value)


def _validation_sets(
    episodes: int | list[int], seed: int | list[int], test_seed: int
) -> list[tuple[int, int]]:
    """(episodes, seed) of each set of validation starts, checked: one count for every
    seed or one per seed, each seed once, none the test seed."""
    seeds = seed if isinstance(seed, list) else [seed]
    counts = episodes if isinstance(episodes, list) else [episodes] * len(seeds)
    if not seeds:
        raise ValueError("seed: give at least one validation seed")
    if len(counts) != len(seeds):
        raise ValueError(
            f"episodes: give one count or one per validation seed ({len(seeds)}), got {counts}"
        )
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"seed: each validation seed once, got {seeds}")
    for count, validation_seed in zip(counts, seeds, strict=True):
        check_validation_starts(count, validation_seed, test_seed, "a seed")
    return list(zip(counts, seeds, strict=True))


def select_seed(
    folders: list[str | Path],
    task: str | None = None,
    episodes: int | list[int] = 100,
    seed: int | list[int] = 1,
    test_seed: int = 0,
    workers: int = 2,
    name: str | None = None,
    overwrite: bool = False,
    test_episodes: int | None = None,
    test_task: str | None = None,
    target: float | None = None,
) -> dict:
    """Chooses one of a recipe's training seeds by its final policy's success on
    ``episodes`` validation starts of ``task`` (None: the task the runs trained on;
    evaluation seed ``seed``, mean action) by :data:`SEED_SELECTION_RULE`, reusing the
    evaluations ``rlfd evaluate`` stored; writes the record to
    ``results/select_seeds_<name>_n<episodes>_s<seed>.{json,md}`` and returns its data.

    Training several seeds and keeping the best on validation is model selection over
    seeds: its test result is that of one chosen policy, not the recipe's mean over seeds.

    ``seed`` may be a list: the starts of those evaluation seeds are pooled (``episodes``
    one count for all or a list, one per seed), each seed's success and mean peaks
    weighted by its starts, e.g. a stored 100 of seed 1 and 200 new ones of seed 4.

    Given ``test_episodes``, every seed is also evaluated (or its stored evaluation read)
    on that many starts of ``test_task`` (None: the runs' training task) at ``test_seed``,
    and the record judges the rule on them: the rank correlation of validation and test
    success, the chosen seed's test success, and :func:`best_of_k` (with ``target``, a
    success %, how often the choice among k seeds reaches it).

    Raises:
        ValueError: a validation ``seed`` equals ``test_seed`` or is given twice,
            ``episodes`` neither one count nor one per seed, fewer than two runs, runs of
            different recipes, a run with neither a policy nor a stored evaluation, a
            ``test_episodes`` that is not positive, a ``target`` outside [0, 100], or a
            ``target`` or ``test_task`` without ``test_episodes``.
        FileExistsError: the record exists and not ``overwrite``.
    """
    validation = _validation_sets(episodes, seed, test_seed)
    if test_episodes is not None and test_episodes <= 0:
        raise ValueError(f"test_episodes must be positive, got {test_episodes}")
    if target is not None and test_episodes is None:
        raise ValueError(f"target: {target} % is judged on test starts; give test_episodes")
    if test_task is not None and test_episodes is None:
        raise ValueError(f"test_task: {test_task!r} is tested only with test_episodes; give it")
    if target is not None and not 0 <= target <= 100:
        raise ValueError(f"target must be a success % in [0, 100], got {target}")
    if len(folders) < 2:
        raise ValueError(f"folders: give two or more runs (one per seed), got {len(folders)}")
    runs = sorted((load_seed_run(folder) for folder in folders), key=lambda run: run.seed)
    _check_one_recipe(runs)
    task = task if task is not None else runs[0].config["task"]
    name = name or study_name(folders)
    counts = [count for count, _ in validation]
    seeds = [validation_seed for _, validation_seed in validation]
    # One set keeps the plain numbers (and its record's name); pooled sets list theirs.
    episodes, seed = (counts[0], seeds[0]) if len(validation) == 1 else (counts, seeds)
    record = seed_selection_name(name, episodes, seed)
    new_result_path(record, overwrite)
    mode = runs[0].config.get("residual_mode", "full")
    composition = runs[0].config.get("composition", "residual")

    rows = [_pooled_validation(run, task, mode, composition, validation, workers) for run in runs]
    chosen = choose_seed(rows)
    data = {
        "name": name,
        "task": task,
        "validation_seed": seed,
        "test_seed": test_seed,
        "validation_episodes": episodes,
        "rule": SEED_SELECTION_RULE,
        "recipe": {key: value for key, value in runs[0].config.items() if key != "seed"},
        "commands": [run.command for run in runs],
        "candidates": rows,
        "chosen": chosen,
        "chosen_seed": rows[chosen]["seed"],
        "chosen_policy": str(runs[chosen].policy),
    }
    if test_episodes is not None:
        test_task = test_task if test_task is not None else runs[0].config["task"]
        for run, row in zip(runs, rows, strict=True):
            row["test_evaluation"], result = _run_evaluation(
                run, test_task, mode, composition, test_episodes, test_seed, workers
            )
            row["test_success_rate"] = result["success_rate"]
        data["test"] = _judged_on_test(rows, test_task, test_episodes, target)
    write_result(record, data, seed=seed if isinstance(seed, int) else None)
    (results_dir() / f"{record}.md").write_text(seed_selection_markdown(data))
    return data


def _pooled_validation(
    run: SeedRun,
    task: str,
    mode: str,
    composition: str,
    validation: list[tuple[int, int]],
    workers: int,
) -> dict:
    """The run's row of a seed selection: its success and mean peaks on the validation
    starts, each set weighted by its number of starts."""
    names, results = [], []
    for count, seed in validation:
        name, result = _run_evaluation(
            run, task, mode, composition, count, seed, workers, required=("peak_force_n",)
        )
        names.append(name)
        results.append(result)
    total = sum(count for count, _ in validation)

    def pooled(key: str) -> float | None:
        values = [result.get(key) for result in results]
        if any(value is None for value in values):
            return None
        weighted = (count * value for (count, _), value in zip(validation, values, strict=True))
        return sum(weighted) / total

    return {
        "seed": run.seed,
        "folder": str(run.folder),
        "evaluation": " + ".join(names),
        "evaluations": names,
        "success_rate": pooled("success_rate"),
        "peak_force_n": pooled("peak_force_n"),
        "peak_low_passed_force_n": pooled("peak_low_passed_force_n"),
    }


def _judged_on_test(rows: list[dict], task: str, episodes: int, target: float | None) -> dict:
    """How the rule's choices among these seeds fare on their test success."""
    order = rule_order(rows)
    test_rates = [row["test_success_rate"] for row in rows]
    return {
        "task": task,
        "episodes": episodes,
        "target_percent": target,
        "chosen_test_success_rate": test_rates[order[0]],
        "spearman_validation_test": spearman([row["success_rate"] for row in rows], test_rates),
        "over_seeds": spread_over_seeds([100.0 * rate for rate in test_rates]),
        "best_of_k": best_of_k(
            [test_rates[i] for i in order], None if target is None else target / 100.0
        ),
    }


def seed_selection_markdown(data: dict) -> str:
    """The seeds' validation results as a Markdown table, the chosen one marked."""
    lines = [
        f"# Seed selection: {data['name']}",
        "",
        f"Each seed's final policy on {_joined(data['validation_episodes'])} validation "
        f"starts of `{data['task']}` (evaluation seed {_joined(data['validation_seed'])}; "
        f"the test seed {data['test_seed']} is not used), mean action. Rule: {data['rule']}. "
        f"Chosen: seed {data['chosen_seed']}, `{data['chosen_policy']}`. Its test result is "
        "the chosen policy's, not the recipe's mean over seeds.",
        "",
        "Training commands:",
        "",
        *[f"    {command}" for command in data["commands"] if command],
        "",
    ]
    test = data.get("test")
    test_header = f" test success ({test['episodes']} starts) |" if test else ""
    lines += [
        f"| training seed | validation success | peak / low-passed force (N) |{test_header} "
        "evaluation |",
        "|---|---|---|" + ("---|" if test else "") + "---|",
    ]
    for index, row in enumerate(data["candidates"]):
        mark = " **(chosen)**" if index == data["chosen"] else ""
        low = row["peak_low_passed_force_n"]
        test_cell = f" {100 * row['test_success_rate']:.1f} % |" if test else ""
        lines.append(
            f"| {row['seed']}{mark} | {100 * row['success_rate']:.1f} % | "
            f"{row['peak_force_n']:.0f} / {'-' if low is None else f'{low:.0f}'} |{test_cell} "
            f"`{row['evaluation']}` |"
        )
    if test:
        lines += _test_judgement_lines(data, test)
    return "\n".join(lines) + "\n"


def _test_judgement_lines(data: dict, test: dict) -> list[str]:
    """The rule judged on the test starts: rank agreement and the best of k seeds."""
    rank = test["spearman_validation_test"]
    agreement = (
        "undefined (one of them is the same for every seed)"
        if rank["rho"] is None
        else f"{rank['rho']:.2f} (permutation p {rank['p']:.2g})"
    )
    target = test["target_percent"]
    lines = [
        "",
        f"On {test['episodes']} test starts of `{test['task']}` (evaluation seed "
        f"{data['test_seed']}): the chosen seed {100 * test['chosen_test_success_rate']:.1f} %; "
        f"the recipe over the {len(data['candidates'])} seeds "
        f"{format_spread(test['over_seeds'])} %; Spearman rank correlation of validation "
        f"and test success {agreement}.",
        "",
        "The rule's choice when only k of these seeds are trained, over every k-subset:",
        "",
        "| seeds trained, k | subsets | chosen policy's test success, mean |"
        + (f" subsets whose choice reaches {target:g} % |" if target is not None else ""),
        "|---|---|---|" + ("---|" if target is not None else ""),
    ]
    for row in test["best_of_k"]:
        at_target = ""
        if target is not None:
            share = 100 * row["chosen_at_target"] / row["subsets"]
            at_target = f" {row['chosen_at_target']:,} ({share:.0f} %) |"
        lines.append(
            f"| {row['k']} | {row['subsets']:,} | "
            f"{100 * row['mean_chosen_test_success_rate']:.1f} % |{at_target}"
        )
    return lines


def _unknown_wall(resumed_at_episode: int | None) -> str:
    """The wall-clock cell of a run whose time is not known."""
    return "-" if resumed_at_episode is None else f"- (resumed at episode {resumed_at_episode})"


def _selection_lines(per_seed: list[dict]) -> list[str]:
    """Where each seed's policy was chosen among its checkpoints (``rlfd select``), if
    any was: the episodes column is then the chosen checkpoint's."""
    records = [(row["seed"], row.get("selection_record")) for row in per_seed]
    if not any(record for _, record in records):
        return []
    chosen = ", ".join(f"seed {seed}: `{record or 'the final policy'}`" for seed, record in records)
    return [
        "Each policy was chosen among its run's checkpoints on validation starts "
        f"(rlfd select; episodes = the chosen checkpoint's): {chosen}.",
        "",
    ]


def seed_study_markdown(data: dict) -> str:
    """The study as a Markdown table: one row per seed, then mean +- std over seeds."""
    columns = data["columns"]
    targets = data["targets"]
    lines = [
        f"# Seed study: {data['name']}",
        "",
        f"Success % over {data['evaluation_episodes']} evaluation starts (evaluation seed "
        f"{data['evaluation_seed']}); mean = the policy's mean action, sampled = sampled actions.",
        "Training commands:",
        "",
        *[f"    {command}" for command in data["commands"] if command],
        "",
        *_selection_lines(data["per_seed"]),
        "| training seed | episodes | wall-clock (s) | "
        + " | ".join(_column_label(column) for column in columns)
        + (" | meets targets |" if targets else " |"),
        "|---" * (3 + len(columns) + bool(targets)) + "|",
    ]
    for row in data["per_seed"]:
        wall = row["training_wall_time_s"]
        cells = [
            str(row["seed"]),
            str(row["training_episodes"]),
            f"{wall:.0f}" if wall else _unknown_wall(row.get("training_resumed_at_episode")),
            *[f"{row['success'][column]:.1f}" for column in columns],
        ]
        if targets:
            cells.append("yes" if row["meets_targets"] else "no")
        lines.append("| " + " | ".join(cells) + " |")
    n = len(data["per_seed"])
    spread = data["over_seeds"]
    cells = [
        f"mean +- std over {n} seeds",
        "",
        "",
        *[format_spread(spread[column]) for column in columns],
    ]
    if targets:
        cells.append(f"{data['seeds_meeting_targets']} of {n}")
    lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    if targets:
        wanted = ", ".join(f"{Path(task).stem} >= {target:g} %" for task, target in targets.items())
        lines.append(f"Targets (mean action): {wanted}.")
    lines.append("The std is the sample standard deviation over training seeds (ddof 1).")
    return "\n".join(lines) + "\n"
