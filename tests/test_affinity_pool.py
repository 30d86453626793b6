"""AffinityPool: jobs go home to the worker of their affinity; idle workers help out."""

from __future__ import annotations

import os
import time

import pytest

from rlfd_drake.affinity_pool import AffinityPool


def where_run(job: tuple[int, float]) -> tuple[int, int]:
    """(job id, pid of the worker that ran it), after sleeping the job's time."""
    job_id, seconds = job
    if seconds < 0:
        raise ArithmeticError(f"job {job_id} failed")
    time.sleep(seconds)
    return job_id, os.getpid()


@pytest.fixture(scope="module")
def pool():
    """Two workers, both started (a worker still starting falls behind the other,
    which then takes its jobs)."""
    with AffinityPool(2) as shared:
        list(shared.imap_unordered(where_run, [(0, 0.2), (1, 0.2)], [0, 1]))
        yield shared


def test_jobs_of_one_affinity_run_on_one_worker(pool):
    jobs = [(i, 0.05) for i in range(12)]
    first = dict(pool.imap_unordered(where_run, jobs, [i % 2 for i in range(12)]))
    again = dict(pool.imap_unordered(where_run, jobs, [i % 2 for i in range(12)]))
    assert sorted(first) == list(range(12))
    assert first == again  # each job ran where it ran before
    assert len({first[i] for i in range(0, 12, 2)}) == 1
    assert len({first[i] for i in range(1, 12, 2)}) == 1
    assert first[0] != first[1]


def test_an_idle_worker_takes_the_other_workers_jobs(pool):
    """All jobs have worker 0's affinity: worker 1 takes some rather than wait, from
    the end of worker 0's queue."""
    jobs = [(i, 0.05) for i in range(8)]
    ran = dict(pool.imap_unordered(where_run, jobs, [0] * 8))
    assert sorted(ran) == list(range(8))
    assert len(set(ran.values())) == 2
    assert ran[0] != ran[7]


def test_a_jobs_error_is_raised_and_bad_affinities_are_refused(pool):
    with pytest.raises(ArithmeticError, match="job 1 failed"):
        list(pool.imap_unordered(where_run, [(0, 0.0), (1, -1.0)], [0, 1]))
    with pytest.raises(ValueError, match="2 jobs but 1 affinities"):
        list(pool.imap_unordered(where_run, [(0, 0.0), (1, 0.0)], [0]))
    with pytest.raises(ValueError, match="affinity must be an integer >= 0, got -1"):
        list(pool.imap_unordered(where_run, [(0, 0.0)], [-1]))
    with pytest.raises(ValueError, match="workers must be an integer >= 1, got 0"):
        AffinityPool(0)
    assert dict(pool.imap_unordered(where_run, [(5, 0.0)], [3]))  # still works
