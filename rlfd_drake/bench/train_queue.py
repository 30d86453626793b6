"""Training several runs at once against one after another (``rlfd bench train-queue``).

``run()`` trains the same ``runs`` short PPO runs (``rlfd train`` in subprocesses, two
env processes each, as ``rlfd reproduce --train-missing`` does) with each number of runs
at once in ``parallel``, the settings interleaved within every repeat so they share the
machine's state, and reports the median wall time per setting and each one's speed-up
over one run at a time. It is the measurement behind ``default_parallel_runs``'s one run
per core. It writes nothing but the runs, in a temporary folder it removes.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

from rlfd_drake.run_queue import (
    ENV_PROCESSES_PER_RUN,
    TrainingJob,
    check_count,
    default_parallel_runs,
    train_queue,
    usable_cores,
)

__all__ = ["run"]


def _jobs(folder: Path, task: str, runs: int, episodes: int) -> list[TrainingJob]:
    jobs = []
    for index in range(runs):
        out = folder / f"run_{index}"
        command = (
            f"rlfd train --task {task} --algo ppo --episodes {episodes} --seed {index} "
            f"--envs {ENV_PROCESSES_PER_RUN} --out {out}"
        )
        jobs.append(TrainingJob(str(out), command))
    return jobs


def run(
    repeats: int = 1,
    runs: int = 4,
    episodes: int = 10,
    task: str = "peg_easy",
    parallel: tuple[int, ...] = (1, 2),
) -> dict:
    """Median wall time (s) of training ``runs`` runs of ``episodes`` PPO episodes on
    ``task``, for each number of runs at once in ``parallel``.

    Returns:
        ``{"wall_s": {p: median s}, "speedup_over_one_at_a_time": {p: ratio},
        "samples_s": {p: [s per repeat]}, "runs", "episodes", "task", "repeats",
        "default_parallel_runs"}``.
    """
    for name, value in (("repeats", repeats), ("runs", runs), ("episodes", episodes)):
        check_count(name, value)
    if not parallel or any(
        isinstance(p, bool) or not isinstance(p, int) or p < 1 for p in parallel
    ):
        raise ValueError(f"parallel must be integers >= 1, got {list(parallel)!r}")
    parallel = tuple(dict.fromkeys(parallel))
    samples: dict[int, list[float]] = {p: [] for p in parallel}
    with tempfile.TemporaryDirectory(prefix="rlfd_bench_train_queue_") as folder:
        for repeat in range(repeats):
            for p in parallel:
                jobs = _jobs(Path(folder) / f"r{repeat}_p{p}", task, runs, episodes)
                started = time.perf_counter()
                train_queue(jobs, parallel=p)
                samples[p].append(time.perf_counter() - started)
    wall = {p: statistics.median(s) for p, s in samples.items()}
    baseline = wall.get(1)
    return {
        "wall_s": {str(p): w for p, w in wall.items()},
        "speedup_over_one_at_a_time": {
            str(p): (baseline / w if baseline is not None else None) for p, w in wall.items()
        },
        "samples_s": {str(p): s for p, s in samples.items()},
        "runs": runs,
        "episodes": episodes,
        "task": task,
        "repeats": repeats,
        "env_processes_per_run": ENV_PROCESSES_PER_RUN,
        "usable_cores": usable_cores(),
        "default_parallel_runs": default_parallel_runs(),
    }
