"""run_queue: several rlfd train runs at once, a fine-tune after its source."""

from __future__ import annotations

import subprocess
import threading
from pathlib import Path

import pytest

import rlfd_drake.run_queue as run_queue
from rlfd_drake.run_queue import TrainingFailed, TrainingJob, train_queue


def _job(folder: str, after: str | None = None) -> TrainingJob:
    return TrainingJob(folder, f"rlfd train --task peg --episodes 2 --out {folder}", after)


def _fake_trainer(monkeypatch, events, fail=(), barrier=None):
    """subprocess.run as rlfd train leaves it (a policy in --out), recording start and
    end; folders in ``fail`` exit 1; with ``barrier``, every run waits for the others."""
    lock = threading.Lock()

    def run(argv, check, **output):
        folder = argv[argv.index("--out") + 1]
        with lock:
            events.append(("start", folder))
        if "stdout" in output:
            output["stdout"].write(f"training {folder}\n")
        if barrier is not None:
            barrier.wait()
        if folder in fail:
            with lock:
                events.append(("fail", folder))
            raise subprocess.CalledProcessError(1, argv)
        Path(folder).mkdir(parents=True, exist_ok=True)
        (Path(folder) / "policy.zip").write_bytes(b"")
        with lock:
            events.append(("end", folder))

    monkeypatch.setattr(run_queue.subprocess, "run", run)


def test_independent_runs_train_at_the_same_time(tmp_path, monkeypatch):
    """Each fake run waits until the other has started: only concurrent runs finish."""
    monkeypatch.chdir(tmp_path)
    events = []
    _fake_trainer(monkeypatch, events, barrier=threading.Barrier(2, timeout=20))
    train_queue([_job("runs/a"), _job("runs/b")], parallel=2)
    assert [kind for kind, _ in events[:2]] == ["start", "start"]
    assert (tmp_path / "runs/a/policy.zip").exists() and (tmp_path / "runs/b/policy.zip").exists()


def test_a_fine_tune_starts_after_its_source_and_logs_are_appended(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    events = []
    _fake_trainer(monkeypatch, events)
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs/b.train.log").write_text("an earlier attempt\n")
    train_queue([_job("runs/a"), _job("runs/b", after="runs/a"), _job("runs/c")], parallel=2)
    assert events.index(("end", "runs/a")) < events.index(("start", "runs/b"))
    assert {folder for kind, folder in events if kind == "end"} == {"runs/a", "runs/b", "runs/c"}
    log = (tmp_path / "runs/b.train.log").read_text()
    assert log == "an earlier attempt\ntraining runs/b\n"


def test_one_run_at_a_time_prints_to_the_terminal_and_skips_trained_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    events = []
    _fake_trainer(monkeypatch, events)
    (tmp_path / "runs/a").mkdir(parents=True)
    (tmp_path / "runs/a/policy.zip").write_bytes(b"")
    train_queue([_job("runs/a"), _job("runs/b", after="runs/a")], parallel=1)
    assert events == [("start", "runs/b"), ("end", "runs/b")]
    assert not list((tmp_path / "runs").glob("*.log"))


def test_a_failed_run_stops_only_the_runs_that_start_from_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    events = []
    _fake_trainer(monkeypatch, events, fail={"runs/a"})
    jobs = [_job("runs/a"), _job("runs/b", after="runs/a"), _job("runs/c")]
    with pytest.raises(TrainingFailed) as error:
        train_queue(jobs, parallel=2)
    message = str(error.value)
    assert "training failed: runs/a (exit status 1; log runs/a.train.log)" in message
    assert "not started, as the run they start from failed: runs/b (after runs/a)" in message
    assert ("end", "runs/c") in events and ("start", "runs/b") not in events


@pytest.mark.parametrize(
    ("jobs", "parallel", "match"),
    [
        ([_job("runs/a")], 0, "parallel runs must be an integer >= 1, got 0"),
        ([_job("runs/a")], True, "parallel runs must be an integer >= 1, got True"),
        ([_job("runs/a"), _job("runs/a")], 1, r"must not repeat a run folder, got \['runs/a'\]"),
        ([_job("runs/b", after="runs/a"), _job("runs/a")], 1, "runs/b starts after runs/a"),
        ([TrainingJob("runs/x", "rlfd evaluate --out runs/x")], 1, "must be 'rlfd train"),
    ],
)
def test_a_bad_queue_is_refused_before_anything_trains(
    tmp_path, monkeypatch, jobs, parallel, match
):
    monkeypatch.chdir(tmp_path)
    events = []
    _fake_trainer(monkeypatch, events)
    with pytest.raises(ValueError, match=match):
        train_queue(jobs, parallel)
    assert events == []


def test_default_parallel_runs_is_one_per_usable_core(monkeypatch):
    for cores in (1, 2, 5):
        monkeypatch.setattr(run_queue.os, "sched_getaffinity", lambda pid, n=cores: set(range(n)))
        assert run_queue.default_parallel_runs() == run_queue.usable_cores() == cores


def test_the_training_argv_is_the_users_command_resumed():
    argv = run_queue.training_argv(_job("runs/a"))
    assert argv[:4] == [run_queue.sys.executable, "-m", "rlfd_drake.cli", "train"]
    assert argv[4:] == [
        *"--task peg --episodes 2 --out runs/a".split(),
        "--resume",
        "--no-progress",
    ]
