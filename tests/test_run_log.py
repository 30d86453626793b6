"""Keeping a training run's log in results/ (``rlfd keep``)."""

from __future__ import annotations

import gzip
import json

import pytest

from rlfd_drake.cli import main
from rlfd_drake.run_log import (
    keep_run_log,
    read_episode_log,
    read_episode_rows,
    training_success_rates,
)

EPISODES = "episode,timesteps,success,return,length\n1,42,1,1.0,21\n2,100,0,0.0,50\n"


@pytest.fixture
def run_dir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    run = tmp_path / "runs" / "peg_ppo_s0"
    run.mkdir(parents=True)
    (run / "config.json").write_text(json.dumps({"config": {"task": "peg"}, "command": "c"}))
    (run / "metrics.json").write_text(json.dumps({"episodes": 2}))
    (run / "episodes.csv").write_text(EPISODES)
    return run


def test_keep_copies_the_log_with_the_episodes_compressed(run_dir, tmp_path):
    kept = keep_run_log(run_dir)
    assert kept == tmp_path / "results" / "train_peg_ppo_s0"
    assert sorted(p.name for p in kept.iterdir()) == [
        "config.json",
        "episodes.csv.gz",
        "metrics.json",
    ]
    assert gzip.decompress((kept / "episodes.csv.gz").read_bytes()).decode() == EPISODES
    assert read_episode_log(kept) == read_episode_log(run_dir) == EPISODES
    # Kept twice, the bytes are the same (no time stamp in the gzip header).
    first = (kept / "episodes.csv.gz").read_bytes()
    keep_run_log(run_dir, overwrite=True)
    assert (kept / "episodes.csv.gz").read_bytes() == first


def test_keep_copies_a_runs_imitation_record(run_dir):
    """A run started from a copied teacher keeps its imitation.json (teacher success, fit)."""
    imitation = {"teacher": "force_search_and_slope", "teacher_success_rate": 0.99}
    (run_dir / "imitation.json").write_text(json.dumps(imitation))
    kept = keep_run_log(run_dir)
    assert json.loads((kept / "imitation.json").read_text()) == imitation


def test_keep_refuses_to_overwrite_and_names_bad_input(run_dir, tmp_path, capsys):
    assert main(["keep", str(run_dir)]) == 0
    assert main(["keep", str(run_dir)]) == 2  # already kept: nothing replaced
    assert "--overwrite" in capsys.readouterr().err
    # A run stopped before its end (no metrics yet) is kept under another name.
    (run_dir / "metrics.json").unlink()
    assert main(["keep", str(run_dir), "--name", "peg_ppo_s0_stopped_at_2"]) == 0
    stopped = tmp_path / "results" / "train_peg_ppo_s0_stopped_at_2"
    assert not (stopped / "metrics.json").exists() and (stopped / "config.json").exists()
    with pytest.raises(ValueError, match="has no config.json"):
        keep_run_log(tmp_path / "results")
    (run_dir / "episodes.csv").unlink()
    with pytest.raises(ValueError, match="has no episodes.csv"):
        keep_run_log(run_dir, overwrite=True)
    with pytest.raises(ValueError, match="has no episodes.csv or episodes.csv.gz"):
        read_episode_log(tmp_path)
    assert main(["keep", str(run_dir), str(run_dir), "--name", "x"]) == 2
    assert "--name names one run's log, got 2 runs" in capsys.readouterr().err


def test_training_success_over_the_last_50_and_all_episodes_or_the_first_few(run_dir):
    rows = read_episode_rows(run_dir)
    assert training_success_rates(rows) == {"success_rate_last_50": 0.5, "success_rate_all": 0.5}
    assert training_success_rates(rows, 1)["success_rate_all"] == 1.0
    many = [{"success": str(int(i >= 50))} for i in range(100)]  # the last 50 succeed
    assert training_success_rates(many) == {"success_rate_last_50": 1.0, "success_rate_all": 0.5}
    assert training_success_rates([]) == {"success_rate_last_50": 0.0, "success_rate_all": 0.0}
