"""A training run's log kept in ``results/`` (``rlfd keep``).

Run folders (``runs/<name>/``: policy, checkpoints, TensorBoard curves) stay local and
are not committed. What a reader needs to check a reported run is its configuration
with the command that trained it, its metrics and its per-episode log: those are
copied to ``results/train_<name>/``, the per-episode CSV gzip-compressed (one short
line per episode, about a fifth of the bytes compressed), where ``rlfd seeds`` and
``rlfd reproduce`` find a run whose folder is not on this machine.
"""

from __future__ import annotations

import csv
import gzip
import io
import shutil
from pathlib import Path

from rlfd_drake.results import check_result_name, results_dir, write_compressed

__all__ = [
    "keep_run_log",
    "read_episode_log",
    "read_episode_rows",
    "run_log_file",
    "run_log_folders",
    "training_success_rates",
]

#: Files of a run folder that are copied as they are; config.json is required.
#: imitation.json (runs started from a copied teacher) holds the teacher's success and
#: how closely PPO's copy fits it, which the studies quote.
_COPIED = ("config.json", "metrics.json", "imitation.json")
_EPISODES = "episodes.csv"


def keep_run_log(run_dir: str | Path, name: str | None = None, overwrite: bool = False) -> Path:
    """Copies ``run_dir``'s config.json, metrics.json (absent while a run is stopped
    before its end), imitation.json (only runs that copied a teacher) and episodes.csv
    (as episodes.csv.gz) to ``results/train_<name>/`` (``name`` defaults to the folder's
    name); returns that folder. An existing kept log is replaced only with ``overwrite``."""
    run_dir = Path(run_dir)
    for required in ("config.json", _EPISODES):
        if not (run_dir / required).is_file():
            raise ValueError(f"run_dir: {str(run_dir)!r} has no {required} (not a training run)")
    name = run_dir.name if name is None else name
    check_result_name(name)
    kept = results_dir() / f"train_{name}"
    if kept.exists() and not overwrite:
        raise FileExistsError(f"{kept} exists; pass --overwrite to replace it, or --name")
    kept.mkdir(parents=True, exist_ok=True)
    for file in _COPIED:
        if (run_dir / file).is_file():
            shutil.copyfile(run_dir / file, kept / file)
    write_compressed(kept / f"{_EPISODES}.gz", (run_dir / _EPISODES).read_bytes())
    (kept / _EPISODES).unlink(missing_ok=True)  # an uncompressed copy of an earlier keep
    return kept


def run_log_folders(run_dir: str | Path) -> tuple[Path, Path]:
    """Where a run's log is: its folder, then (a run of another machine) the copy
    ``rlfd keep`` made in results/train_<name>/."""
    run_dir = Path(run_dir)
    return run_dir, results_dir() / f"train_{run_dir.name}"


def run_log_file(run_dir: str | Path, file: str) -> Path | None:
    """``file`` (config.json, metrics.json) of a run, from the first of
    :func:`run_log_folders` that has it; None if neither does."""
    return next((f / file for f in run_log_folders(run_dir) if (f / file).is_file()), None)


def read_episode_log(folder: str | Path) -> str:
    """The per-episode CSV of a run folder or of its kept log (compressed or not)."""
    folder = Path(folder)
    if (folder / _EPISODES).is_file():
        return (folder / _EPISODES).read_text()
    if (folder / f"{_EPISODES}.gz").is_file():
        return gzip.decompress((folder / f"{_EPISODES}.gz").read_bytes()).decode()
    raise ValueError(f"folder: {str(folder)!r} has no {_EPISODES} or {_EPISODES}.gz")


def read_episode_rows(folder: str | Path) -> list[dict[str, str]]:
    """The rows of :func:`read_episode_log`, one dict per episode, keyed by its header."""
    return list(csv.DictReader(io.StringIO(read_episode_log(folder))))


def training_success_rates(rows: list[dict[str, str]], episodes: int | None = None) -> dict:
    """``success_rate_last_50`` and ``success_rate_all`` of a run's episode log rows
    (:func:`read_episode_rows`), over its first ``episodes`` episodes (None: all); 0.0
    for no episode, as ``rlfd train`` writes them to metrics.json."""
    successes = [int(row["success"]) for row in rows[:episodes]]
    return {
        "success_rate_last_50": sum(successes[-50:]) / len(successes[-50:]) if successes else 0.0,
        "success_rate_all": sum(successes) / len(successes) if successes else 0.0,
    }
