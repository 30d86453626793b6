"""Choosing a run's policy among its checkpoints on held-out starts (``rlfd select``).

PPO's last iterate is not always its best: a seed's training success can fall by 10-20
points between two checkpoints 100 episodes apart, and the policy a run ends with is
whichever the last update left. Model selection on a validation set is the usual cure.
:func:`select_checkpoint` evaluates each checkpoint of a run (``checkpoints/``, one per
100 training episodes by default, and the final ``policy.zip``) on validation starts:
the evaluation grid drawn with a seed other than the test seed, so other start offsets
inside the same bins and other fixture errors. The test seed is refused as the
validation seed: a choice made on the starts it is then reported on would be biased up.

The chosen policy is written as a run folder of its own beside the run,
``runs/<recipe>_selected_s<seed>/`` (policy.zip, the run's config.json and episode log,
and metrics.json with ``episodes`` the chosen checkpoint's and the selection's record),
so ``rlfd evaluate``, ``rlfd seeds`` and ``rlfd keep`` take it like any run. The record
of every candidate's validation success and forces goes to
``results/select_<run>_n<N>_s<seed>.{json,md}``.
"""

from __future__ import annotations

import json
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

from rlfd_drake.policies import checkpoint_steps
from rlfd_drake.results import format_json, new_result_path, results_dir, write_result
from rlfd_drake.run_log import read_episode_log, read_episode_rows, training_success_rates

__all__ = [
    "Candidate",
    "check_validation_starts",
    "choose_candidate",
    "chosen_policy_metrics",
    "run_candidates",
    "select_checkpoint",
    "selected_run_folder",
    "selection_markdown",
]


#: metrics.json entries of a whole run that a chosen checkpoint's training does not share:
#: kept in the selected folder as trained_<entry> (PPO's update count at a checkpoint is
#: not logged, so the chosen policy has none of its own).
_WHOLE_RUN_METRICS = ("success_rate_last_50", "success_rate_all", "gradient_updates")


@dataclass(frozen=True)
class Candidate:
    """A policy a run saved: its file, the training steps and episodes behind it."""

    path: Path
    timesteps: int
    episodes: int


def _episodes_by_steps(run_dir: Path) -> list[tuple[int, int]]:
    """(episode, timesteps at its end) of each finished training episode."""
    return [(int(row["episode"]), int(row["timesteps"])) for row in read_episode_rows(run_dir)]


def run_candidates(run_dir: str | Path, from_episode: int = 0) -> list[Candidate]:
    """The policies ``rlfd train`` saved in ``run_dir`` after at least ``from_episode``
    training episodes, oldest first: each checkpoint, and the final ``policy.zip``
    unless a checkpoint holds the same step (then the final file stands for both).

    Raises:
        ValueError: ``run_dir`` is not a finished run, or no saved policy qualifies.
    """
    run_dir = Path(run_dir)
    if from_episode < 0:
        raise ValueError(f"from_episode must be >= 0, got {from_episode}")
    metrics_file = run_dir / "metrics.json"
    if not (run_dir / "policy.zip").is_file() or not metrics_file.is_file():
        raise ValueError(
            f"run_dir: {str(run_dir)!r} holds no finished run (policy.zip and metrics.json)"
        )
    metrics = json.loads(metrics_file.read_text())
    ends = _episodes_by_steps(run_dir)

    def episodes_at(steps: int) -> int:
        return sum(1 for _, end in ends if end <= steps)

    final_steps = int(metrics["timesteps"])
    saved = {path: checkpoint_steps(path) for path in (run_dir / "checkpoints").glob("*_steps.zip")}
    found = [
        Candidate(path, steps, episodes_at(steps))
        for path, steps in saved.items()
        if steps < final_steps
    ]
    found.append(Candidate(run_dir / "policy.zip", final_steps, int(metrics["episodes"])))
    chosen = sorted((c for c in found if c.episodes >= from_episode), key=lambda c: c.timesteps)
    if not chosen:
        raise ValueError(
            f"from_episode: no saved policy of {str(run_dir)!r} has {from_episode} or more "
            f"training episodes (it ran {metrics['episodes']})"
        )
    return chosen


def check_validation_starts(episodes: int, seed: int, test_seed: int, chosen: str) -> None:
    """ValueError unless ``episodes`` validation starts of evaluation ``seed`` can choose
    ``chosen`` (e.g. "a checkpoint"): a positive count, and not the test seed's starts,
    on which a choice would score too high."""
    if seed == test_seed:
        raise ValueError(
            f"seed: the validation seed must differ from the test seed ({test_seed}), got "
            f"{seed}: {chosen} chosen on the starts it is reported on scores too high"
        )
    if episodes <= 0:
        raise ValueError(f"episodes must be positive, got {episodes}")


def choose_candidate(success_rates: list[float]) -> int:
    """The index of the highest validation success; of equal ones the latest (the
    candidates are oldest first: more training, the same validation evidence)."""
    if not success_rates:
        raise ValueError("success_rates: no candidate to choose from")
    best = max(success_rates)
    return max(i for i, rate in enumerate(success_rates) if rate == best)


def chosen_policy_metrics(
    run_metrics: dict, episode_rows: list[dict[str, str]], chosen: Candidate
) -> dict:
    """The metrics.json of a run's chosen checkpoint: the training steps, episodes and
    training success up to it; the whole run's as trained_* (wall_time_s stays the
    run's: choosing needed the whole run)."""
    return {
        **{key: value for key, value in run_metrics.items() if key not in _WHOLE_RUN_METRICS},
        "episodes": chosen.episodes,
        "timesteps": chosen.timesteps,
        **training_success_rates(episode_rows, chosen.episodes),
        "trained_episodes": run_metrics["episodes"],
        "trained_timesteps": run_metrics["timesteps"],
        **{f"trained_{key}": run_metrics[key] for key in _WHOLE_RUN_METRICS if key in run_metrics},
    }


def selected_run_folder(run_dir: str | Path) -> Path:
    """``runs/<recipe>_selected_s<seed>`` for ``runs/<recipe>_s<seed>`` (the seed stays
    last, where ``rlfd seeds`` reads a study's name), else ``<run>_selected``."""
    run_dir = Path(run_dir)
    recipe, sep, seed = run_dir.name.rpartition("_s")
    if sep and recipe and seed.isdigit():
        return run_dir.with_name(f"{recipe}_selected_s{seed}")
    return run_dir.with_name(f"{run_dir.name}_selected")


def select_checkpoint(
    run_dir: str | Path,
    task: str | None,
    episodes: int,
    seed: int,
    test_seed: int = 0,
    workers: int = 2,
    from_episode: int = 0,
    overwrite: bool = False,
) -> dict:
    """Evaluates the run's saved policies on ``episodes`` validation starts of ``task``
    (None: the task the run trained on; evaluation seed ``seed``), writes the best as a
    run folder of its own (:func:`selected_run_folder`) and the record to
    ``results/select_<run>_n<episodes>_s<seed>.{json,md}``; returns the record's data.

    Raises:
        ValueError: ``seed`` equals ``test_seed``, or a bad run / argument.
        FileExistsError: the selected folder or the record exists and not ``overwrite``.
    """
    from rlfd_drake import evaluate as evaluate_module

    run_dir = Path(run_dir)
    check_validation_starts(episodes, seed, test_seed, "a checkpoint")
    candidates = run_candidates(run_dir, from_episode)
    config_record = json.loads((run_dir / "config.json").read_text())
    config = config_record["config"]
    task = task if task is not None else config["task"]
    name = f"select_{run_dir.name}_n{episodes}_s{seed}"
    new_result_path(name, overwrite)
    destination = selected_run_folder(run_dir)
    if destination.exists() and not overwrite:
        raise FileExistsError(f"{destination} exists; pass --overwrite to replace it")

    start = time.perf_counter()
    rows = []
    for candidate in candidates:
        print(f"  {candidate.path.name}: {candidate.episodes} training episodes", flush=True)
        result = evaluate_module.evaluate(
            task,
            str(candidate.path),
            episodes,
            seed,
            workers=workers,
            residual_mode=config.get("residual_mode", "full"),
            composition=config.get("composition", "residual"),
        )
        rows.append(
            {
                "policy": str(candidate.path),
                "training_episodes": candidate.episodes,
                "training_timesteps": candidate.timesteps,
                "success_rate": result["success_rate"],
                "failures": result["failures"],
                "peak_force_n": result["peak_force_n"],
                "peak_low_passed_force_n": result["peak_low_passed_force_n"],
            }
        )
    chosen = choose_candidate([row["success_rate"] for row in rows])
    wall = time.perf_counter() - start

    metrics = json.loads((run_dir / "metrics.json").read_text())
    selection = {
        "run": str(run_dir),
        "task": task,
        "validation_seed": seed,
        "test_seed": test_seed,
        "validation_episodes": episodes,
        "from_episode": from_episode,
        "rule": "highest validation success; of equal ones the latest",
        "chosen": chosen,
        "candidates": rows,
        "selection_wall_time_s": wall,
        "selected_folder": str(destination),
    }
    if destination.exists():
        shutil.rmtree(destination)
    destination.mkdir(parents=True)
    shutil.copyfile(candidates[chosen].path, destination / "policy.zip")
    shutil.copyfile(run_dir / "config.json", destination / "config.json")
    (destination / "episodes.csv").write_text(read_episode_log(run_dir))
    selected_metrics = {
        **chosen_policy_metrics(metrics, read_episode_rows(run_dir), candidates[chosen]),
        "selection": {key: value for key, value in selection.items() if key != "candidates"},
        "selection_record": f"results/{name}.json",
    }
    (destination / "metrics.json").write_text(format_json(selected_metrics) + "\n")
    data = {**selection, "training_command": config_record.get("command")}
    write_result(name, data, seed=seed)
    (results_dir() / f"{name}.md").write_text(selection_markdown(data))
    return data


def selection_markdown(data: dict) -> str:
    """The candidates' validation results as a Markdown table, the chosen one marked."""
    lines = [
        f"# Checkpoint selection: {Path(data['run']).name}",
        "",
        f"Each saved policy of `{data['run']}` with {data['from_episode']} or more training "
        f"episodes on {data['validation_episodes']} validation starts of `{data['task']}` "
        f"(evaluation seed {data['validation_seed']}; the test seed {data['test_seed']} is "
        f"not used), mean action. Rule: {data['rule']}. The chosen policy is "
        f"`{data['selected_folder']}/policy.zip`.",
        "",
        "Trained by:",
        "",
        f"    {data['training_command']}",
        "",
        "| policy | training episodes | validation success | peak / low-passed force (N) "
        "| failures |",
        "|---|---|---|---|---|",
    ]
    for index, row in enumerate(data["candidates"]):
        mark = " **(chosen)**" if index == data["chosen"] else ""
        failures = ", ".join(f"{k} {v}" for k, v in row["failures"].items()) or "-"
        lines.append(
            f"| {Path(row['policy']).name}{mark} | {row['training_episodes']} | "
            f"{100 * row['success_rate']:.1f} % | {row['peak_force_n']:.0f} / "
            f"{row['peak_low_passed_force_n']:.0f} | {failures} |"
        )
    lines += ["", f"Selection wall-clock: {data['selection_wall_time_s']:.0f} s."]
    return "\n".join(lines) + "\n"
