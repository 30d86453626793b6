"""Several ``rlfd train`` runs trained at once, each after the run it starts from.

``rlfd reproduce --train-missing`` hands the runs its tables lack to :func:`train_queue`:
each run is trained by its own command, as a user types it (``rlfd train ...``), in a
subprocess with ``--resume`` (an interrupted run continues from its newest checkpoint,
a finished one is not retrained) and ``--no-progress``. Up to ``parallel`` runs train
at the same time; a run that fine-tunes another (``after``) waits until that one has
finished, and is not started at all if it failed. With more than one run at a time,
each run's output goes to ``<folder>.train.log`` beside its folder (appended, so an
earlier attempt's log is kept) instead of interleaving on the terminal.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
import time
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "TrainingFailed",
    "TrainingJob",
    "check_count",
    "check_seed",
    "check_parallel_runs",
    "default_parallel_runs",
    "train_queue",
    "usable_cores",
]

#: Env processes of each of reproduce's runs (``--envs 2``): the learner waits while they
#: step and they wait while it updates, so one run leaves its two cores partly idle.
ENV_PROCESSES_PER_RUN = 2


@dataclass(frozen=True)
class TrainingJob:
    """One run to train.

    Attributes:
        folder: the run folder (``--out``); its ``policy.zip`` marks it trained.
        command: ``rlfd train ... --out <folder>`` as a user types it.
        after: the folder of another job of the same queue that must finish first
            (the run this one starts from), or None.
    """

    folder: str
    command: str
    after: str | None = None


class TrainingFailed(RuntimeError):
    """Some runs of a queue failed (and the runs starting from them were not started)."""


def usable_cores() -> int:
    """The cores this process may run on."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return cores or 1


def default_parallel_runs() -> int:
    """Runs to train at once on this machine: one per core it may use. On 2 cores two
    runs of two env processes each at once finish 1.43-1.45x sooner than one at a time,
    four at once 1.30x (``rlfd bench train-queue``: results/bench_train_queue_*.json)."""
    return usable_cores()


def training_argv(job: TrainingJob) -> list[str]:
    """The subprocess that trains ``job``: its ``rlfd train`` arguments, resumable."""
    parts = shlex.split(job.command)
    if parts[:2] != ["rlfd", "train"]:
        raise ValueError(
            f"run {job.folder}'s command must be 'rlfd train ...', got {job.command!r}"
        )
    return [
        sys.executable,
        "-m",
        "rlfd_drake.cli",
        "train",
        *parts[2:],
        "--resume",
        "--no-progress",
    ]


def _log_path(folder: str) -> Path:
    return Path(folder).parent / f"{Path(folder).name}.train.log"


def check_count(name: str, value: int) -> None:
    """ValueError naming ``name`` unless ``value`` is an integer >= 1 (bools refused)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")


def check_seed(name: str, value: int) -> None:
    """ValueError naming ``name`` unless ``value`` is an integer >= 0 (bools refused)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"{name} must be an integer >= 0, got {value!r}")


def check_parallel_runs(parallel: int) -> None:
    """ValueError unless ``parallel`` (runs trained at once) is an integer >= 1."""
    check_count("parallel runs", parallel)


def _check_queue(jobs: list[TrainingJob], parallel: int) -> None:
    check_parallel_runs(parallel)
    folders = [job.folder for job in jobs]
    if len(set(folders)) != len(folders):
        repeated = sorted({f for f in folders if folders.count(f) > 1})
        raise ValueError(f"jobs must not repeat a run folder, got {repeated}")
    for position, job in enumerate(jobs):
        training_argv(job)  # refuses a command that is not rlfd train before any starts
        if job.after is not None and job.after not in folders[:position]:
            raise ValueError(
                f"run {job.folder} starts after {job.after}, which is not an earlier job "
                "of the queue"
            )


def _train(job: TrainingJob, to_log: bool) -> float:
    """Trains one job in a subprocess; its wall time in seconds."""
    argv = training_argv(job)
    started = time.monotonic()
    if not to_log:
        print(f"training {job.folder}: {job.command}", flush=True)
        subprocess.run(argv, check=True)
    else:
        log = _log_path(job.folder)
        log.parent.mkdir(parents=True, exist_ok=True)
        print(f"training {job.folder} (log {log}): {job.command}", flush=True)
        with log.open("a") as stream:
            subprocess.run(argv, check=True, stdout=stream, stderr=subprocess.STDOUT)
    return time.monotonic() - started


def _failure_text(job: TrainingJob, error: BaseException, to_log: bool) -> str:
    where = f"; log {_log_path(job.folder)}" if to_log else ""
    if isinstance(error, subprocess.CalledProcessError):
        return f"{job.folder} (exit status {error.returncode}{where})"
    return f"{job.folder} ({type(error).__name__}: {error}{where})"


def train_queue(jobs: list[TrainingJob], parallel: int = 1) -> None:
    """Trains ``jobs`` (sources before the runs that start from them), up to ``parallel``
    at once, in their order where they are free to start. Jobs whose folder already has
    its ``policy.zip`` are skipped. TrainingFailed names every run that failed and every
    run not started because its source failed, after the others have finished."""
    _check_queue(jobs, parallel)
    to_log = parallel > 1
    pending = [job for job in jobs if not (Path(job.folder) / "policy.zip").exists()]
    finished: set[str] = {job.folder for job in jobs} - {job.folder for job in pending}
    failed: dict[str, str] = {}
    not_started: dict[str, str] = {}
    running: dict[Future, TrainingJob] = {}
    with ThreadPoolExecutor(max_workers=parallel) as pool:
        while pending or running:
            for job in list(pending):
                if len(running) >= parallel:
                    break
                if job.after in failed or job.after in not_started:
                    not_started[job.folder] = job.after
                    pending.remove(job)
                elif job.after is None or job.after in finished:
                    running[pool.submit(_train, job, to_log)] = job
                    pending.remove(job)
            if not running:
                continue  # every pending job waits on a failed one: dropped next pass
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                job = running.pop(future)
                error = future.exception()
                if error is None:
                    finished.add(job.folder)
                    print(f"trained {job.folder} in {future.result() / 60:.1f} min", flush=True)
                else:
                    failed[job.folder] = _failure_text(job, error, to_log)
    if failed or not_started:
        parts = []
        if failed:
            parts.append("training failed: " + ", ".join(failed.values()))
        if not_started:
            parts.append(
                "not started, as the run they start from failed: "
                + ", ".join(f"{folder} (after {source})" for folder, source in not_started.items())
            )
        raise TrainingFailed("; ".join(parts))
