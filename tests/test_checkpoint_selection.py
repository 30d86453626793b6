"""rlfd select: a run's policy chosen among its checkpoints on validation starts."""

from __future__ import annotations

import json
import shutil

import pytest

import rlfd_drake.evaluate as evaluate_module
from rlfd_drake.checkpoint_selection import (
    choose_candidate,
    run_candidates,
    select_checkpoint,
    selected_run_folder,
)
from rlfd_drake.cli import main
from rlfd_drake.paths import SHIPPED_POLICY, model_path
from rlfd_drake.seed_study import load_seed_run

# (episode, timesteps at its end): checkpoints fire at 2, 4 and 6 finished episodes.
EPISODE_ENDS = [(1, 50), (2, 80), (3, 130), (4, 150), (5, 200), (6, 230)]
SUCCESSES = [0, 1, 1, 0, 1, 1]  # 2 of the first 4 episodes, 4 of all 6


def _run(tmp_path, policy_bytes=b"final", name="recipe_s3", task="peg_easy"):
    """A finished run folder with checkpoints at 80 and 150 steps and a final policy
    at 230 steps that the last checkpoint duplicates."""
    run = tmp_path / "runs" / name
    (run / "checkpoints").mkdir(parents=True)
    config = {"task": task, "algo": "ppo", "seed": 3, "residual_mode": "translation"}
    (run / "config.json").write_text(json.dumps({"config": config, "command": "rlfd train"}))
    metrics = {"episodes": 6, "timesteps": 230, "wall_time_s": 12.0, "gradient_updates": 30}
    metrics |= {"success_rate_last_50": 4 / 6, "success_rate_all": 4 / 6}
    (run / "metrics.json").write_text(json.dumps(metrics))
    lines = ["episode,timesteps,success,return,length"]
    lines += [f"{e},{t},{ok},0.0,10" for (e, t), ok in zip(EPISODE_ENDS, SUCCESSES, strict=True)]
    (run / "episodes.csv").write_text("\n".join(lines) + "\n")
    for steps in (80, 150, 230):
        (run / "checkpoints" / f"policy_{steps}_steps.zip").write_bytes(b"at %d" % steps)
    (run / "policy.zip").write_bytes(policy_bytes)
    return run


def test_candidates_are_the_checkpoints_then_the_final_policy_with_their_episodes(tmp_path):
    run = _run(tmp_path)
    found = run_candidates(run)
    assert [c.path.name for c in found] == [
        "policy_80_steps.zip",
        "policy_150_steps.zip",
        "policy.zip",  # stands for the checkpoint at its own step
    ]
    assert [c.episodes for c in found] == [2, 4, 6]
    assert [c.timesteps for c in found] == [80, 150, 230]
    assert [c.episodes for c in run_candidates(run, from_episode=3)] == [4, 6]
    with pytest.raises(ValueError, match="from_episode: no saved policy"):
        run_candidates(run, from_episode=7)
    with pytest.raises(ValueError, match="from_episode must be >= 0"):
        run_candidates(run, from_episode=-1)
    (run / "metrics.json").unlink()  # still training
    with pytest.raises(ValueError, match="no finished run"):
        run_candidates(run)


def test_the_best_validation_success_wins_and_ties_go_to_the_later_policy():
    assert choose_candidate([0.5, 0.9, 0.7]) == 1
    assert choose_candidate([0.9, 0.8, 0.9]) == 2
    with pytest.raises(ValueError, match="no candidate"):
        choose_candidate([])


def test_the_selected_folder_keeps_the_seed_last(tmp_path):
    assert selected_run_folder(tmp_path / "peg_ppo_e700_s2").name == "peg_ppo_e700_selected_s2"
    assert selected_run_folder(tmp_path / "my_run").name == "my_run_selected"


def _fake_evaluations(monkeypatch, success_by_file):
    calls = []

    def fake(task, policy, episodes, seed, **kwargs):
        calls.append((task, policy, episodes, seed, kwargs["residual_mode"]))
        name = policy.rsplit("/", 1)[-1]
        return {
            "success_rate": success_by_file[name],
            "failures": {"timeout": 1},
            "peak_force_n": 100.0,
            "peak_low_passed_force_n": 50.0,
        }

    monkeypatch.setattr(evaluate_module, "evaluate", fake)
    return calls


def test_selection_writes_the_best_checkpoint_as_a_run_and_records_every_candidate(
    tmp_path, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    run = _run(tmp_path)
    success = {"policy_80_steps.zip": 0.6, "policy_150_steps.zip": 0.95, "policy.zip": 0.9}
    calls = _fake_evaluations(monkeypatch, success)
    data = select_checkpoint(run, None, episodes=20, seed=1)
    # Every candidate on the run's own task, the validation seed and its residual mode.
    assert [(c[0], c[2], c[3], c[4]) for c in calls] == [("peg_easy", 20, 1, "translation")] * 3
    assert data["chosen"] == 1
    chosen = tmp_path / "runs" / "recipe_selected_s3"
    assert data["selected_folder"] == str(chosen)
    assert (chosen / "policy.zip").read_bytes() == b"at 150"
    assert (chosen / "config.json").read_text() == (run / "config.json").read_text()
    metrics = json.loads((chosen / "metrics.json").read_text())
    assert (metrics["episodes"], metrics["trained_episodes"]) == (4, 6)
    # Training success up to the chosen checkpoint; the whole run's as trained_*.
    assert (metrics["success_rate_last_50"], metrics["success_rate_all"]) == (0.5, 0.5)
    assert metrics["trained_success_rate_all"] == pytest.approx(4 / 6)
    assert metrics["trained_gradient_updates"] == 30 and "gradient_updates" not in metrics
    assert metrics["wall_time_s"] == 12.0  # the run the choice needed
    assert metrics["selection"]["validation_seed"] == 1
    # A run like any other for the seed study.
    assert load_seed_run(chosen).seed == 3
    record = json.loads((tmp_path / "results" / "select_recipe_s3_n20_s1.json").read_text())
    assert [row["success_rate"] for row in record["data"]["candidates"]] == [0.6, 0.95, 0.9]
    markdown = (tmp_path / "results" / "select_recipe_s3_n20_s1.md").read_text()
    assert "| policy_150_steps.zip **(chosen)** | 4 | 95.0 % |" in markdown

    # Nothing is replaced without asking; with --overwrite the new choice replaces it.
    with pytest.raises(FileExistsError, match="exists"):
        select_checkpoint(run, None, episodes=20, seed=1)
    success["policy.zip"] = 0.95
    data = select_checkpoint(run, None, episodes=20, seed=1, overwrite=True)
    assert data["chosen"] == 2
    assert (chosen / "policy.zip").read_bytes() == b"final"


def test_the_test_seed_is_refused_for_validation(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    run = _run(tmp_path)
    _fake_evaluations(monkeypatch, {})
    with pytest.raises(ValueError, match="validation seed must differ from the test seed"):
        select_checkpoint(run, None, episodes=20, seed=0)
    assert main(["select", "--run", str(run), "--seed", "4", "--test-seed", "4"]) == 2
    assert "seed: the validation seed must differ" in capsys.readouterr().err
    assert main(["select", "--run", str(run), "--episodes", "0"]) == 2
    assert "episodes must be positive, got 0" in capsys.readouterr().err
    assert not (tmp_path / "runs" / "recipe_selected_s3").exists()


def test_a_checkpoint_is_evaluated_with_its_runs_configuration(tmp_path, monkeypatch, capsys):
    """A real evaluation: the shipped translation policy stands for every saved policy
    of a run, so each candidate runs in the diagram with the run's residual mode."""
    monkeypatch.chdir(tmp_path)
    shipped = model_path(SHIPPED_POLICY)
    run = _run(tmp_path, policy_bytes=shipped.read_bytes(), name="shipped_s0")
    shutil.copyfile(shipped.with_suffix(".json"), run / "config.json")
    for checkpoint in (run / "checkpoints").iterdir():
        shutil.copyfile(shipped, checkpoint)
    code = main(
        ["select", "--run", str(run), "--episodes", "2", "--workers", "1", "--from-episode", "5"]
    )
    assert code == 0
    assert "6 episodes:" in capsys.readouterr().out
    record = json.loads((tmp_path / "results" / "select_shipped_s0_n2_s1.json").read_text())
    (candidate,) = record["data"]["candidates"]
    assert record["data"]["task"] == "peg_easy"
    assert 0.0 <= candidate["success_rate"] <= 1.0
    assert candidate["peak_force_n"] > 0.0
    assert (tmp_path / "runs" / "shipped_selected_s0" / "policy.zip").is_file()
