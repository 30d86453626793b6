"""A pool of worker processes that keeps jobs with the same affinity on one worker.

``rlfd reproduce`` evaluates dozens of policies on the same starts of a task, and an
episode's first half (the DMP alone, up to the residual's activation) is the same for
all of them: each worker keeps it in a per-process cache (``episode.run_episode``'s
``reuse_prefix``). ``multiprocessing.Pool`` hands a job to whichever worker is free,
so a start lands on the worker that has its first half only half the time. Here each
job has an affinity, and goes to worker ``affinity % workers`` while that worker has
jobs of its own; a worker with none left takes the last queued job of the busiest
other one rather than wait (so the pool is as busy as a plain one, and only the last
few jobs of a batch may run away from home).
"""

from __future__ import annotations

import multiprocessing
import queue
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from rlfd_drake.run_queue import check_count, check_seed

__all__ = ["AffinityPool"]


class AffinityPool:
    """``workers`` single-process pools, fed one job at a time each.

    Use as a context manager (the processes are terminated on exit), like
    ``multiprocessing.Pool``. Jobs and results must pickle; a job's exception is
    raised in the caller by :meth:`imap_unordered`, as ``Pool.imap_unordered`` does.
    """

    def __init__(self, workers: int, context=None):
        check_count("workers", workers)
        ctx = context if context is not None else multiprocessing.get_context("spawn")
        self._pools = [ctx.Pool(1) for _ in range(workers)]

    @property
    def workers(self) -> int:
        return len(self._pools)

    def __enter__(self) -> AffinityPool:
        return self

    def __exit__(self, *exc) -> None:
        self.terminate()

    def terminate(self) -> None:
        for pool in self._pools:
            pool.terminate()
        for pool in self._pools:
            pool.join()

    def imap_unordered(
        self, function: Callable[[Any], Any], jobs: Iterable[Any], affinities: Iterable[int]
    ) -> Iterator[Any]:
        """Yields ``function(job)`` for every job, in the order they finish.

        Args:
            function: a picklable function of one job.
            jobs: the jobs.
            affinities: one integer per job; jobs with equal affinities run on the same
                worker unless it falls behind the others.

        Raises:
            ValueError: ``jobs`` and ``affinities`` differ in length, or an affinity
                is not an integer >= 0.
        """
        jobs = list(jobs)
        affinities = list(affinities)
        if len(jobs) != len(affinities):
            raise ValueError(f"{len(jobs)} jobs but {len(affinities)} affinities")
        home: list[deque] = [deque() for _ in self._pools]
        for job, affinity in zip(jobs, affinities, strict=True):
            check_seed("affinity", affinity)
            home[affinity % self.workers].append(job)
        finished: queue.SimpleQueue = queue.SimpleQueue()

        def submit(worker: int) -> bool:
            if home[worker]:
                job = home[worker].popleft()
            else:
                busiest = max(home, key=len)
                if not busiest:
                    return False
                job = busiest.pop()  # its last: the ones it reaches next stay home
            self._pools[worker].apply_async(
                function,
                (job,),
                callback=lambda value: finished.put((worker, True, value)),
                error_callback=lambda error: finished.put((worker, False, error)),
            )
            return True

        running = sum(submit(worker) for worker in range(self.workers))
        while running:
            worker, ok, value = finished.get()
            running -= 1
            if not ok:
                raise value
            running += submit(worker)
            yield value
