"""rlfd seeds: a recipe's spread over training seeds, from stored or new evaluations."""

from __future__ import annotations

import itertools
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import rlfd_drake.evaluate as evaluate_module
from rlfd_drake.cli import main
from rlfd_drake.diagram import RlfdDiagramConfig
from rlfd_drake.evaluate import evaluation_name
from rlfd_drake.paths import SHIPPED_POLICY, model_path
from rlfd_drake.results import write_result
from rlfd_drake.seed_study import (
    best_of_k,
    choose_seed,
    load_seed_run,
    rule_order,
    seed_study,
    select_seed,
    spearman,
    study_name,
)
from rlfd_drake.tasks import load_task

RECIPE = {"task": "peg_easy", "algo": "sac", "episodes": 700, "residual_mode": "translation"}


def _run_folder(tmp_path, seed, **changes):
    folder = tmp_path / "runs" / f"recipe_s{seed}"
    folder.mkdir(parents=True)
    config = {**RECIPE, **changes, "seed": seed}
    command = f"rlfd train --seed {seed} --out {folder}"
    (folder / "config.json").write_text(json.dumps({"config": config, "command": command}))
    (folder / "metrics.json").write_text(
        json.dumps({"episodes": 700, "wall_time_s": 1000.0 + seed})
    )
    return folder


def _store_evaluation(
    folder, task, stochastic, success_rate, episodes=200, counted=False, seed=0, **figures
):
    """Stores an evaluation under the name studies used first, or (``counted``) under
    ``rlfd evaluate --episodes N``'s, which carries the count."""
    count = {"episodes": episodes} if counted else {}
    name = evaluation_name(
        task, str(folder / "policy.zip"), "translation", stochastic, seed, **count
    )
    bounds = list(RlfdDiagramConfig().residual_bounds(load_task(task)))
    data = {
        "task": task,
        "episodes": episodes,
        "seed": seed,
        "composition": "residual",
        "residual_bounds": bounds,
        "success_rate": success_rate,
        **figures,
    }
    write_result(name, data, seed=seed, command="rlfd evaluate (stored for the test)")


def _never_evaluate(*args, **kwargs):
    raise AssertionError("a stored evaluation should have been reused")


def test_study_reuses_stored_evaluations_and_reports_the_spread(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(evaluate_module, "evaluate", _never_evaluate)
    easy = {0: 0.955, 1: 0.85, 2: 0.92}
    hard = {0: 0.62, 1: 0.48, 2: 0.53}
    folders = []
    for seed in (2, 0, 1):  # any order; the table is by seed
        folder = _run_folder(tmp_path, seed)
        folders.append(folder)
        for stochastic, offset in ((False, 0.0), (True, 0.01)):
            _store_evaluation(folder, "peg_easy", stochastic, easy[seed] + offset)
            _store_evaluation(folder, "peg_hard", stochastic, hard[seed] + offset)
    data = seed_study(
        folders, ["peg_easy", "peg_hard"], targets={"peg_easy": 95.0, "peg_hard": 55.0}
    )
    assert data["name"] == "recipe"
    assert [row["seed"] for row in data["per_seed"]] == [0, 1, 2]
    assert [row["meets_targets"] for row in data["per_seed"]] == [True, False, False]
    assert data["seeds_meeting_targets"] == 1
    spread = data["over_seeds"]["peg_easy/mean"]
    values = [95.5, 85.0, 92.0]
    assert spread["mean"] == pytest.approx(np.mean(values))
    assert spread["std"] == pytest.approx(np.std(values, ddof=1))
    assert data["over_seeds"]["peg_hard/sampled"]["mean"] == pytest.approx(55.33333, abs=1e-4)
    assert data["training_wall_time_s"]["mean"] == pytest.approx(1001.0)
    assert data["recipe"] == {key: value for key, value in RECIPE.items()}
    markdown = (tmp_path / "results" / "seeds_recipe.md").read_text()
    assert "| 0 | 700 | 1000 | 95.5 | 96.5 | 62.0 | 63.0 | yes |" in markdown
    assert "90.8 +- 5.3" in markdown and "1 of 3" in markdown
    stored = json.loads((tmp_path / "results" / "seeds_recipe.json").read_text())
    assert stored["seed"] == 0 and stored["data"]["seeds_meeting_targets"] == 1
    # The mean action alone: its columns only.
    mean_only = seed_study(folders, ["peg_hard"], actions=("mean",), name="recipe_mean")
    assert mean_only["columns"] == ["peg_hard/mean"]
    assert mean_only["over_seeds"]["peg_hard/mean"]["mean"] == pytest.approx(54.33333, abs=1e-4)
    assert "peg_hard, sampled" not in (tmp_path / "results" / "seeds_recipe_mean.md").read_text()
    assert "chosen among its run's checkpoints" not in markdown
    # A seed whose policy rlfd select chose among its checkpoints says where.
    metrics = json.loads((folders[0] / "metrics.json").read_text())
    record = "results/select_recipe_s2_n100_s1.json"
    (folders[0] / "metrics.json").write_text(json.dumps({**metrics, "selection_record": record}))
    seed_study(folders, ["peg_hard"], actions=("mean",), name="recipe_selected")
    chosen = (tmp_path / "results" / "seeds_recipe_selected.md").read_text()
    assert f"seed 2: `{record}`" in chosen and "seed 0: `the final policy`" in chosen
    # A resumed run timed its last process only: no wall-clock, and the table says why.
    metrics = json.loads((folders[1] / "metrics.json").read_text())
    (folders[1] / "metrics.json").write_text(json.dumps({**metrics, "resumed_at_episode": 606}))
    resumed = seed_study(folders, ["peg_hard"], actions=("mean",), name="recipe_resumed")
    assert resumed["training_wall_time_s"]["mean"] == pytest.approx(1001.5)  # seeds 1, 2
    table = (tmp_path / "results" / "seeds_recipe_resumed.md").read_text()
    assert "| 0 | 700 | - (resumed at episode 606) |" in table


def test_study_refuses_runs_of_different_recipes_or_repeated_seeds(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    a = _run_folder(tmp_path, 0)
    b = _run_folder(tmp_path, 1, sac_gradient_steps=8)
    with pytest.raises(ValueError, match="differ in sac_gradient_steps: 1 vs 8"):
        seed_study([a, b], ["peg_easy"])
    # A setting the older run's config predates counts at its default.
    c = _run_folder(tmp_path, 2, force_limit_penalty=0.0)
    with pytest.raises(ValueError, match="no policy.zip to evaluate"):  # past the check
        seed_study([a, c], ["peg_easy"])
    d = _run_folder(tmp_path, 3, force_limit_penalty=1.0)
    with pytest.raises(ValueError, match="differ in force_limit_penalty: 0.0 vs 1.0"):
        seed_study([a, d], ["peg_easy"])
    with pytest.raises(ValueError, match="each seed once"):
        seed_study([a, a], ["peg_easy"])
    # A second stage from each seed's own first stage is one recipe; from one seed's is not.
    stage2 = [
        _run_folder(tmp_path, seed, init_from=f"runs/first_s{seed}/policy.zip") for seed in (4, 5)
    ]
    with pytest.raises(ValueError, match="no policy.zip to evaluate"):  # past the check
        seed_study(stage2, ["peg_easy"])
    shared = _run_folder(tmp_path, 6, init_from="runs/first_s4/policy.zip")
    with pytest.raises(ValueError, match="differ in init_from"):
        seed_study([stage2[0], shared], ["peg_easy"])
    with pytest.raises(ValueError, match="targets: task 'peg_hard' is not evaluated"):
        seed_study([a], ["peg_easy"], targets={"peg_hard": 55.0})
    with pytest.raises(ValueError, match=r"targets: peg_easy must be a success % in \[0, 100\]"):
        seed_study([a], ["peg_easy"], targets={"peg_easy": 0.95e3})
    with pytest.raises(ValueError, match="actions must be among"):
        seed_study([a], ["peg_easy"], actions=("greedy",))
    with pytest.raises(ValueError, match="targets are checked on the mean action"):
        seed_study([a], ["peg_easy"], targets={"peg_easy": 95.0}, actions=("sampled",))
    with pytest.raises(ValueError, match="no finished run"):
        load_seed_run(tmp_path / "runs" / "missing_s0")
    # Neither a policy to evaluate nor a stored evaluation: say which run and file.
    with pytest.raises(ValueError, match="no policy.zip to evaluate and no stored"):
        seed_study([a], ["peg_easy"])
    with pytest.raises(ValueError, match="no common name"):
        study_name(["runs/a_s0", "runs/b_s1"])
    assert main(["seeds", "--runs", str(a), "--target", "peg_easy:95"]) == 2


def test_a_copied_training_log_stands_in_for_a_missing_run_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    folder = _run_folder(tmp_path, 3)
    copy = tmp_path / "results" / f"train_{folder.name}"
    shutil.copytree(folder, copy)
    shutil.rmtree(folder)
    run = load_seed_run(folder)
    assert run.seed == 3 and run.command.startswith("rlfd train --seed 3")


def test_study_evaluates_a_run_that_has_no_stored_evaluation(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    shipped = model_path(SHIPPED_POLICY)
    folder = tmp_path / "runs" / "shipped_s0"
    folder.mkdir(parents=True)
    shutil.copy(shipped, folder / "policy.zip")
    shutil.copy(shipped.with_suffix(".json"), folder / "config.json")
    (folder / "metrics.json").write_text(json.dumps({"episodes": 700, "wall_time_s": 1168.0}))
    data = seed_study([folder], ["peg_easy"], episodes=1, workers=1)
    row = data["per_seed"][0]
    for column in ("peg_easy/mean", "peg_easy/sampled"):
        assert row["success"][column] in (0.0, 100.0)  # one episode
        assert (tmp_path / "results" / f"{row['evaluations'][column]}.json").is_file()
    assert data["over_seeds"]["peg_easy/mean"]["std"] is None  # one seed has no spread


def test_study_reuses_what_rlfd_evaluate_stored_and_targets_a_variant_by_name(
    tmp_path, monkeypatch
):
    variant = str(model_path("tasks/variants/rj45_slow_insert.yaml"))
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(evaluate_module, "evaluate", _never_evaluate)
    folders = []
    for seed, rate in ((0, 0.519), (1, 0.506)):
        folder = _run_folder(tmp_path, seed, task=variant)
        folders.append(folder)
        _store_evaluation(folder, variant, False, rate, episodes=160, counted=True)
    data = seed_study(
        folders, [variant], episodes=160, targets={"rj45_slow_insert": 51.0}, actions=("mean",)
    )
    assert [row["meets_targets"] for row in data["per_seed"]] == [True, False]
    assert data["per_seed"][0]["evaluations"][f"{variant}/mean"].endswith("_n160_s0")
    markdown = (tmp_path / "results" / f"seeds_{data['name']}.md").read_text()
    assert "| rj45_slow_insert, mean |" in markdown and "rj45_slow_insert >= 51 %" in markdown


def test_a_stored_study_is_replaced_only_by_one_that_keeps_all_of_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(evaluate_module, "evaluate", _never_evaluate)
    folders = [_run_folder(tmp_path, seed) for seed in (0, 1, 2)]
    for folder, rate in zip(folders, (0.9, 0.8, 0.7), strict=True):
        _store_evaluation(folder, "peg_easy", False, rate)
    seed_study(folders[:2], ["peg_easy"], actions=("mean",))
    # A seed added: the stored study's seeds are all kept, so it is replaced.
    grown = seed_study(folders, ["peg_easy"], actions=("mean",))
    assert [row["seed"] for row in grown["per_seed"]] == [0, 1, 2]
    # A seed dropped: refused, naming what would be lost, and the file is untouched.
    stored = (tmp_path / "results" / "seeds_recipe.json").read_text()
    with pytest.raises(FileExistsError, match="seed 2 peg_easy/mean"):
        seed_study(folders[:2], ["peg_easy"], actions=("mean",))
    assert (tmp_path / "results" / "seeds_recipe.json").read_text() == stored
    # Other evaluation starts are another measurement, not a superset.
    with pytest.raises(FileExistsError, match="evaluation seed 0"):
        seed_study(folders, ["peg_easy"], actions=("mean",), seed=1)
    # --overwrite, or another name, is the way out.
    shrunk = seed_study(folders[:2], ["peg_easy"], actions=("mean",), overwrite=True)
    assert [row["seed"] for row in shrunk["per_seed"]] == [0, 1]
    seed_study(folders[1:], ["peg_easy"], actions=("mean",), name="recipe_late")
    assert (tmp_path / "results" / "seeds_recipe_late.json").exists()


def _seeds_validated(tmp_path, validation: dict) -> list[str]:
    """Run folders of a recipe's seeds, each with a stored evaluation on 100 validation
    starts of evaluation seed 1: {seed: (success rate, mean peak force)}."""
    folders = []
    for seed, (rate, peak) in validation.items():
        folder = _run_folder(tmp_path, seed)
        folders.append(str(folder))
        _store_evaluation(
            folder, "peg_easy", False, rate, episodes=100, counted=True, seed=1,
            peak_force_n=peak, peak_low_passed_force_n=peak / 2,
        )  # fmt: skip
    return folders


def test_a_seed_is_chosen_by_validation_success_then_lower_peak_then_lower_seed():
    def row(seed, success, peak):
        return {"seed": seed, "success_rate": success, "peak_force_n": peak}

    assert choose_seed([row(0, 0.95, 100.0), row(1, 1.0, 140.0), row(2, 0.99, 90.0)]) == 1
    # Equal success: the lower peak; equal peak too: the lower seed, wherever it stands.
    assert choose_seed([row(3, 0.98, 130.0), row(4, 0.98, 120.0), row(5, 0.97, 50.0)]) == 1
    assert choose_seed([row(7, 0.98, 120.0), row(6, 0.98, 120.0)]) == 1
    with pytest.raises(ValueError, match="no seed"):
        choose_seed([])


def test_select_chooses_a_seed_on_stored_validation_starts_and_records_it(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(evaluate_module, "evaluate", _never_evaluate)
    folders = _seeds_validated(tmp_path, {0: (0.97, 110.0), 1: (0.99, 150.0), 2: (0.99, 120.0)})
    assert main(["select", "--runs", *folders, "--episodes", "100", "--seed", "1"]) == 0
    assert "seed   2: 99.0 %, peak 120 N  <- chosen" in capsys.readouterr().out
    record = json.loads((tmp_path / "results" / "select_seeds_recipe_n100_s1.json").read_text())
    data = record["data"]
    assert (data["chosen_seed"], data["task"], data["test_seed"]) == (2, "peg_easy", 0)
    assert data["chosen_policy"].endswith("recipe_s2/policy.zip")
    assert [row["seed"] for row in data["candidates"]] == [0, 1, 2]
    markdown = (tmp_path / "results" / "select_seeds_recipe_n100_s1.md").read_text()
    assert "| 2 **(chosen)** | 99.0 % | 120 / 60 |" in markdown
    # The record is not replaced without --overwrite; the test seed is never validation.
    with pytest.raises(FileExistsError, match="--overwrite"):
        select_seed(folders, episodes=100, seed=1)
    select_seed(folders, episodes=100, seed=1, overwrite=True)
    with pytest.raises(ValueError, match="validation seed must differ from the test seed"):
        select_seed(folders, episodes=100, seed=0, name="other")
    with pytest.raises(ValueError, match="two or more runs"):
        select_seed(folders[:1], episodes=100, seed=1, name="other")
    _run_folder(tmp_path, 5, algo="ppo")
    with pytest.raises(ValueError, match="differ in algo"):
        select_seed([folders[0], str(tmp_path / "runs" / "recipe_s5")], seed=1, name="other")
    with pytest.raises(ValueError, match="no policy.zip to evaluate and no stored"):
        select_seed(folders, episodes=50, seed=1, name="other")
    assert main(["select", "--runs", *folders, "--from-episode", "300"]) == 2
    assert "--from-episode chooses among a run's checkpoints" in capsys.readouterr().err
    assert main(["select", "--run", folders[0], "--name", "other"]) == 2
    assert "--name names a selection among seeds" in capsys.readouterr().err


def test_best_of_k_equals_the_rule_applied_to_every_subset():
    rng = np.random.default_rng(3)
    rows = [
        {"seed": seed, "success_rate": rate, "peak_force_n": peak}
        for seed, rate, peak in zip(
            range(9), rng.choice([0.95, 0.97, 0.99, 1.0], 9), rng.uniform(100, 150, 9), strict=True
        )
    ]
    test = rng.choice([0.9, 0.95, 0.98, 0.995], 9)
    table = best_of_k([test[i] for i in rule_order(rows)], target=0.98)
    assert [row["k"] for row in table] == list(range(1, 10))
    for row in table:
        subsets = list(itertools.combinations(range(9), row["k"]))
        chosen = [test[s[choose_seed([rows[i] for i in s])]] for s in subsets]
        assert row["subsets"] == len(subsets)
        assert row["mean_chosen_test_success_rate"] == pytest.approx(np.mean(chosen))
        assert row["chosen_at_target"] == sum(rate >= 0.98 for rate in chosen)
    # One seed trained: the recipe's mean; all trained: the rule's first choice.
    assert table[0]["mean_chosen_test_success_rate"] == pytest.approx(test.mean())
    assert table[-1]["mean_chosen_test_success_rate"] == test[choose_seed(rows)]
    assert "chosen_at_target" not in best_of_k([0.9, 0.8])[0]
    with pytest.raises(ValueError, match="no seed"):
        best_of_k([])


def test_spearman_matches_known_rank_correlations_and_exact_p_values():
    # d = (1, 1, 1, 1, 0): rho = 1 - 6 * 4 / (5 * 24) = 0.8; of the 120 orders of five,
    # 16 are at least as far from independence either way: exact two-sided p = 0.133.
    result = spearman([1, 2, 3, 4, 5], [2, 1, 4, 3, 5])
    assert result["rho"] == pytest.approx(0.8)
    assert result["p"] == pytest.approx(16 / 120, abs=0.01)
    assert spearman([1, 2, 3, 4, 5], [2, 1, 4, 3, 5]) == result  # seeded
    monotone = spearman([0.1, 0.5, 0.2, 0.9, 0.7, 0.3, 0.8], [1, 125, 8, 729, 343, 27, 512])
    assert monotone["rho"] == pytest.approx(1.0)
    assert monotone["p"] < 0.001
    assert spearman([3, 2, 1], [1, 2, 3])["rho"] == pytest.approx(-1.0)
    # Ties share their mean rank: (1, 2.5, 2.5, 4) against (1, 2, 3, 4), 4.5 / sqrt(4.5 * 5).
    assert spearman([1, 2, 2, 3], [1, 2, 3, 4])["rho"] == pytest.approx(np.sqrt(0.9))
    assert spearman([1, 1, 1], [1, 2, 3])["rho"] is None
    with pytest.raises(ValueError, match="three or more"):
        spearman([1, 2], [2, 1])
    with pytest.raises(ValueError, match="y: 2 values for 3"):
        spearman([1, 2, 3], [2, 1])


def test_select_judges_its_rule_on_the_test_starts_when_asked(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(evaluate_module, "evaluate", _never_evaluate)
    # seed: (validation, its mean peak, test); the rule's order is 2, 1, 0.
    figures = {0: (0.97, 110.0, 0.99), 1: (0.99, 150.0, 0.95), 2: (0.99, 120.0, 0.92)}
    folders = _seeds_validated(
        tmp_path, {seed: (rate, peak) for seed, (rate, peak, _) in figures.items()}
    )
    for folder, (_, _, test) in zip(folders, figures.values(), strict=True):
        _store_evaluation(Path(folder), "peg_easy", False, test, episodes=200, counted=True, seed=0)
    args = ["select", "--runs", *folders, "--seed", "1", "--test-episodes", "200"]
    assert main([*args, "--target", "98"]) == 0
    assert "seed   2: 99.0 %, peak 120 N, test 92.0 %  <- chosen" in capsys.readouterr().out
    data = json.loads((tmp_path / "results" / "select_seeds_recipe_n100_s1.json").read_text())
    test = data["data"]["test"]
    assert (test["task"], test["episodes"], test["target_percent"]) == ("peg_easy", 200, 98.0)
    assert test["chosen_test_success_rate"] == 0.92
    assert test["spearman_validation_test"]["rho"] == pytest.approx(-0.866, abs=1e-3)
    # k = 2: {0, 1} chooses 1 (95 %), {0, 2} and {1, 2} choose 2 (92 %).
    pairs = test["best_of_k"][1]
    assert pairs["mean_chosen_test_success_rate"] == pytest.approx((0.95 + 2 * 0.92) / 3)
    assert pairs["chosen_at_target"] == 0
    assert test["best_of_k"][0]["chosen_at_target"] == 1
    markdown = (tmp_path / "results" / "select_seeds_recipe_n100_s1.md").read_text()
    assert "| 2 **(chosen)** | 99.0 % | 120 / 60 | 92.0 % |" in markdown
    assert "| 2 | 3 | 93.0 % | 0 (0 %) |" in markdown
    assert "the chosen seed 92.0 %; the recipe over the 3 seeds 95.3 +- 3.5 %" in markdown
    # Refused: a target without test starts or outside 0-100, no test starts, and the
    # test options with --run (a choice among checkpoints).
    with pytest.raises(ValueError, match="give test_episodes"):
        select_seed(folders, seed=1, target=98.0, name="other")
    with pytest.raises(ValueError, match="test_task: 'peg_hard' is tested only with"):
        select_seed(folders, seed=1, test_task="peg_hard", name="other")
    with pytest.raises(ValueError, match="target must be a success % in"):
        select_seed(folders, seed=1, test_episodes=200, target=0.98e3, name="other")
    with pytest.raises(ValueError, match="test_episodes must be positive, got 0"):
        select_seed(folders, seed=1, test_episodes=0, name="other")
    assert main(["select", "--run", folders[0], "--test-episodes", "200"]) == 2
    assert "--test-episodes judges a selection among seeds" in capsys.readouterr().err


def test_select_pools_the_validation_starts_of_several_seeds(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(evaluate_module, "evaluate", _never_evaluate)
    # On seed 1's 100 starts seed 1 leads (99 against 98 %); 200 more of seed 4 turn it:
    # pooled, seed 0 (98 + 2 * 99.5) / 3 = 99.0 % against seed 1's (99 + 2 * 97) / 3 = 97.7 %.
    folders = _seeds_validated(tmp_path, {0: (0.98, 110.0), 1: (0.99, 140.0)})
    for folder, (rate, peak) in zip(folders, [(0.995, 116.0), (0.97, 120.0)], strict=True):
        _store_evaluation(
            Path(folder), "peg_easy", False, rate, episodes=200, counted=True, seed=4,
            peak_force_n=peak, peak_low_passed_force_n=peak / 2,
        )  # fmt: skip
    args = ["select", "--runs", *folders, "--seed", "1", "4", "--episodes", "100", "200"]
    assert main(args) == 0
    assert "seed   0: 99.0 %, peak 114 N  <- chosen" in capsys.readouterr().out
    stem = tmp_path / "results" / "select_seeds_recipe_n100+200_s1+4"
    data = json.loads(stem.with_suffix(".json").read_text())["data"]
    assert (data["validation_seed"], data["validation_episodes"]) == ([1, 4], [100, 200])
    row = data["candidates"][0]
    assert row["success_rate"] == pytest.approx(0.99)
    assert row["peak_force_n"] == pytest.approx((110.0 + 2 * 116.0) / 3)
    assert row["peak_low_passed_force_n"] == pytest.approx((55.0 + 2 * 58.0) / 3)
    assert len(row["evaluations"]) == 2
    markdown = stem.with_suffix(".md").read_text()
    assert "on 100+200 validation starts of `peg_easy` (evaluation seed 1+4;" in markdown
    # One seed's starts alone still choose seed 1; one count serves every seed.
    assert select_seed(folders, seed=1, name="one")["chosen_seed"] == 1
    with pytest.raises(ValueError, match="no stored results/.*_n200_s1.json"):
        select_seed(folders, seed=[1, 4], episodes=200, name="other")
    with pytest.raises(ValueError, match=r"one count or one per validation seed \(2\)"):
        select_seed(folders, seed=[1, 4], episodes=[100, 200, 300], name="other")
    with pytest.raises(ValueError, match="each validation seed once"):
        select_seed(folders, seed=[1, 1], name="other")
    with pytest.raises(ValueError, match="must differ from the test seed"):
        select_seed(folders, seed=[1, 0], name="other")
    assert main(["select", "--run", folders[0], "--seed", "1", "4"]) == 2
    assert "take one value when choosing a checkpoint" in capsys.readouterr().err
