"""rlfd reproduce: table assembly (the measurements are stubbed by stored results)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import rlfd_drake.reproduce as reproduce
import rlfd_drake.run_queue as run_queue
from rlfd_drake.paths import models_dir


def _fake_evaluation(
    task,
    policy,
    name,
    mode,
    episodes,
    seed,
    workers,
    stochastic=False,
    composition="residual",
    required=(),
    available=True,
    noise_scale=1.0,
):
    if not available:
        return None
    rate = {"dmp": 0.5, "random": 0.6}.get(policy, 0.7)
    return {
        "success_rate": rate,
        "success_std": 0.05,
        "insertion_time_s": 6.0,
        "peak_force_n": 40.0,
        "forces_by_outcome": {
            "success": {"peak_force_n": 30.0},
            "failure": {"peak_force_n": None},
        },
        "peak_joint_contact_torque_nm": 2.5,
        "peak_low_passed_force_n": 20.0,
        "episodes": episodes,
        "policy": policy,
        "residual_policy_from_activation": True,
        "per_bin": [
            {"rotation_offset_deg": 0.0, "position_offset_m": d, "success_rate": rate, "n": 4}
            for d in (0.005, 0.01)
        ],
    }


def test_reproduce_table_writes_paper_and_ours_side_by_side(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    trained = []

    def fake_run(method, task, mode, episodes, seed, workers):
        trained.append((method, task, mode, episodes))
        return tmp_path / "runs" / f"{task}_{method}" / "baseline.npz"

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", _fake_evaluation)
    monkeypatch.setattr(reproduce, "_baseline_run", fake_run)
    data = reproduce.reproduce_table("1", budget="quick", seed=0, workers=1)
    # Every baseline of Table I is trained on the easy hole only, with the quick budget.
    assert sorted(trained) == sorted(
        (m, "peg_easy", "full", 100) for m in ("enac", "fdg", "power") for _ in (0, 1)
    )
    rows = {row["label"]: row for row in data["rows"]}
    assert rows["A  DMP"]["ours"]["easy"]["success_pct"] == pytest.approx(50.0)
    assert rows["A  DMP"]["paper"]["easy"] == 24.0
    markdown = (tmp_path / "results" / "table_1.md").read_text()
    assert "| A  DMP | 24.0 | 50.0 +- 5.0 | 8.0 | 50.0 +- 5.0 | n/a |" in markdown
    stored = json.loads((tmp_path / "results" / "table_1.json").read_text())
    assert stored["seed"] == 0 and "command" in stored
    # The figure: success against the perturbation, one panel per column, linked.
    assert "![" in markdown and "](table_1.png)" in markdown
    png = tmp_path / "results" / "table_1.png"
    assert png.read_bytes()[:4] == b"\x89PNG"
    from PIL import Image

    with Image.open(png) as plot:  # the legend of the table's many rows below the panels
        width, height = plot.size
        assert width == 500 * len(reproduce.TABLES["1"].columns) and height > 340


def test_rows_that_cannot_run_say_why(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", _fake_evaluation)
    monkeypatch.setattr(
        reproduce, "_baseline_run", lambda *a: tmp_path / "runs" / "x" / "baseline.npz"
    )
    data = reproduce.reproduce_table("4", budget="quick", seed=0, workers=1)
    ppo = next(row for row in data["rows"] if row["label"] == "PPO / None, mean action")
    assert ppo["ours"]["peg"]["status"] == "not run"
    markdown = (tmp_path / "results" / "table_4.md").read_text()
    assert "Not run: " in markdown
    assert "--algo ppo --episodes 300 --seed 0 --envs 2 --residual-mode translation" in markdown
    # A trained run folder is evaluated; a missing one says how to train it.
    sac = next(row for row in data["rows"] if row["label"] == "SAC / SAC (rLfD), mean action")
    assert "rlfd train --task peg --algo sac" in sac["ours"]["peg"]["reason"]
    # A later stage names its command, which starts from the earlier stage's policy.
    longer = next(row for row in data["rows"] if "1,400 episodes, mean" in row["label"])
    assert (
        "--init-from runs/gear_ppo_std2_so_tt_e700_s0/policy.zip"
        in (longer["ours"]["gear"]["reason"])
    )
    assert (
        "--force-limit-penalty 1 --init-from "
        "runs/rj45_ppo_std2_so_torque005_pen1_tt_e700_s0/policy.zip"
        in (longer["ours"]["rj45"]["reason"])
    )
    # A recipe run on some tasks only says which task it has no run on.
    data = reproduce.reproduce_table("incremental", budget="quick", seed=0, workers=1)
    longer = next(
        row for row in data["rows"] if "incremental, 1,400 episodes, mean" in row["label"]
    )
    assert longer["ours"]["peg"] == {
        "status": "not run",
        "reason": "no rlfd_ppo_incremental_1400 run on models/tasks/variants/peg_incremental.yaml",
    }


def test_trained_run_folders_are_evaluated(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    run = tmp_path / "runs" / "gear_sac_te1_s0"
    run.mkdir(parents=True)
    (run / "policy.zip").write_bytes(b"")
    (run / "metrics.json").write_text(json.dumps({"episodes": 500}))
    # A policy trained in two stages: the second here, the first's log in results/ only.
    second = tmp_path / "runs" / "gear_ppo_std2_so_tt_e700_then700_s0"
    first_log = tmp_path / "results" / "train_gear_ppo_std2_so_tt_e700_s0"
    for folder, init_from in (
        (second, "runs/gear_ppo_std2_so_tt_e700_s0/policy.zip"),
        (first_log, None),
    ):
        folder.mkdir(parents=True)
        (folder / "metrics.json").write_text(json.dumps({"episodes": 700}))
        (folder / "config.json").write_text(json.dumps({"config": {"init_from": init_from}}))
    (second / "policy.zip").write_bytes(b"")
    names = []

    def recording(*args, **kwargs):
        names.append(args[2])
        return _fake_evaluation(*args, **kwargs)

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", recording)
    monkeypatch.setattr(
        reproduce, "_baseline_run", lambda *a: tmp_path / "runs" / "x" / "baseline.npz"
    )
    data = reproduce.reproduce_table("4", budget="quick", seed=0, workers=1)
    rows = {row["label"]: row["ours"] for row in data["rows"]}
    assert rows["SAC / SAC (rLfD), mean action"]["gear"]["training_episodes"] == 500
    assert rows["SAC / SAC (rLfD), mean action"]["peg"]["status"] == "not run"
    assert "eval_gear_gear_sac_te1_s0_stochastic_n40_s0" in names
    staged = rows["PPO / PPO (rLfD), log std -2, time limit terminal, 1,400 episodes, mean action"]
    assert staged["gear"]["training_episodes"] == 1400
    # Without the first stage's log the total is unknown, not the last stage's alone.
    (first_log / "metrics.json").unlink()
    data = reproduce.reproduce_table("4", budget="quick", seed=0, workers=1)
    rows = {row["label"]: row["ours"] for row in data["rows"]}
    assert (
        rows["PPO / PPO (rLfD), log std -2, time limit terminal, 1,400 episodes, mean action"][
            "gear"
        ]["training_episodes"]
        is None
    )


def _recording_trainer(monkeypatch, calls):
    """subprocess.run as ``rlfd train`` would leave it: the --out folder gets a policy."""

    def run(argv, check, **output):
        assert check and argv[:4] == [run_queue.sys.executable, "-m", "rlfd_drake.cli", "train"]
        calls.append(argv)
        out = Path(argv[argv.index("--out") + 1])
        out.mkdir(parents=True, exist_ok=True)
        (out / "policy.zip").write_bytes(b"")

    monkeypatch.setattr(run_queue.subprocess, "run", run)


@pytest.mark.parametrize("training_seed", [0, 2])
def test_a_missing_run_is_trained_after_the_run_it_starts_from(
    tmp_path, monkeypatch, training_seed
):
    """A fine-tune trains its source first (the same training seed's), each by its
    command with --resume (an interrupted run continues), and nothing trains twice."""
    monkeypatch.chdir(tmp_path)
    calls = []
    _recording_trainer(monkeypatch, calls)
    gear = "models/tasks/variants/gear_incremental_nopush.yaml"
    run = reproduce.seeded_run(reproduce.RUNS["ppo_from_source_60_peg_gear"][gear], training_seed)
    source = reproduce.seeded_run(
        reproduce.RUNS["ppo_full_peg_gear"]["models/tasks/variants/peg_incremental.yaml"],
        training_seed,
    )
    reproduce.train_run(*run, training_seed)
    assert [argv[argv.index("--out") + 1] for argv in calls] == [source[0], run[0]]
    assert all(argv[-2:] == ["--resume", "--no-progress"] for argv in calls)
    assert calls[1][4:-2] == run[1].split()[2:]
    assert f"--seed {training_seed}" in " ".join(calls[0])
    reproduce.train_run(*run, training_seed)
    assert len(calls) == 2


def test_a_run_whose_source_cannot_be_trained_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    calls = []
    _recording_trainer(monkeypatch, calls)
    command = "rlfd train --task peg --algo ppo --episodes 60 --init-from runs/elsewhere/policy.zip"
    with pytest.raises(FileNotFoundError, match="runs/elsewhere/policy.zip"):
        reproduce.train_run("runs/peg_from_elsewhere", f"{command} --out runs/peg_from_elsewhere")
    with pytest.raises(ValueError, match="rlfd train"):
        reproduce.train_run("runs/x", "rlfd evaluate --task peg --out runs/x")
    assert calls == []


def test_train_missing_fills_the_rows_that_have_no_policy_and_no_stored_evaluation(
    tmp_path, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    calls = []
    _recording_trainer(monkeypatch, calls)
    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", _fake_evaluation)
    rows = {row["label"]: row["ours"] for row in reproduce.reproduce_table("6_peg_gear")["rows"]}
    assert (
        calls == []
        and rows["PPO, incremental: 60 episodes from the source, mean action"]["peg"]["status"]
        == "not run"
    )
    [data] = reproduce.reproduce_tables(["6_peg_gear"], train_missing=True)
    table = reproduce.TABLES["6_peg_gear"]
    keys = {row.source.removeprefix("run:") for row in table.rows if row.source.startswith("run:")}
    for row in data["rows"]:
        for column, cell in row["ours"].items():
            key = row["source"].removeprefix("run:")
            has_run = key not in keys or table.columns[column] in reproduce.RUNS[key]
            assert (cell["status"] == "measured") == has_run, (row["label"], column)
    trained = sorted(argv[argv.index("--out") + 1] for argv in calls)
    expected = {run[0] for key in keys for run in reproduce.RUNS[key].values()}
    assert trained == sorted(expected)


def test_tables_trained_together_train_each_missing_run_once_in_parallel(tmp_path, monkeypatch):
    """Two tables sharing a source run: surveyed first, every missing run (sources
    included) trained once with two at a time (logs beside the folders), then measured."""
    monkeypatch.chdir(tmp_path)
    calls = []
    _recording_trainer(monkeypatch, calls)
    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", _fake_evaluation)
    numbers = ["6_incremental_nopush", "6_peg_gear"]
    tables = reproduce.reproduce_tables(numbers, train_missing=True, parallel_runs=2)
    trained = [argv[argv.index("--out") + 1] for argv in calls]
    assert len(trained) == len(set(trained))
    keys = {
        row.source.removeprefix("run:")
        for number in numbers
        for row in reproduce.TABLES[number].rows
        if row.source.startswith("run:")
    }
    needed = {
        run[0]
        for number in numbers
        for row in reproduce.TABLES[number].rows
        if row.source.startswith("run:")
        for task in reproduce.TABLES[number].columns.values()
        if task in reproduce.RUNS[row.source.removeprefix("run:")]
        for run in [reproduce.RUNS[row.source.removeprefix("run:")][task]]
    }
    assert needed <= set(trained) <= {run[0] for k in keys for run in reproduce.RUNS[k].values()}
    for number, data in zip(numbers, tables, strict=True):
        for row, defined in zip(data["rows"], reproduce.TABLES[number].rows, strict=True):
            if row["source"].startswith("run:"):
                key = row["source"].removeprefix("run:")
                for column, cell in row["ours"].items():
                    task = reproduce.TABLES[number].columns[column]
                    # The quick budget leaves sampled actions to stored evaluations.
                    measured = task in reproduce.RUNS[key] and not defined.stochastic
                    assert (cell["status"] == "measured") == measured
    with pytest.raises(ValueError, match="parallel runs must be an integer >= 1, got 0"):
        reproduce.reproduce_tables(numbers, train_missing=True, parallel_runs=0)


def _trained_folders(calls) -> list[str]:
    return sorted(argv[argv.index("--out") + 1] for argv in calls)


def test_the_quick_budget_trains_the_short_missing_runs_and_lists_the_long_ones(
    tmp_path, monkeypatch
):
    """Without --train-missing the quick budget trains a missing run of at most
    QUICK_RUN_EPISODES episodes whose source is here or as short (6_peg_gear: both
    60-episode runs from scratch; a fine-tune of a 700-episode source only once that
    source's policy is here); the paper budget trains nothing it is not asked to."""
    monkeypatch.chdir(tmp_path)
    calls = []
    _recording_trainer(monkeypatch, calls)
    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", _fake_evaluation)
    peg = "models/tasks/variants/peg_incremental.yaml"
    gear = "models/tasks/variants/gear_incremental_nopush.yaml"
    runs = reproduce.RUNS
    reproduce.reproduce_tables(["6_peg_gear"], budget="paper")
    assert calls == []
    [data] = reproduce.reproduce_tables(["6_peg_gear"])
    scratch = sorted(run[0] for run in runs["ppo_scratch_60_peg_gear"].values())
    assert _trained_folders(calls) == scratch and len(scratch) == 2
    status = {
        (row["label"], column): cell["status"]
        for row in data["rows"]
        for column, cell in row["ours"].items()
    }
    assert status[("PPO, incremental: 60 episodes from scratch, mean action", "peg")] == "measured"
    assert (
        status[("PPO, incremental: full training on the target, mean action", "peg")] == "not run"
    )
    # The peg policy the gear fine-tune starts from is here now: that 60-episode run trains.
    source = Path(runs["ppo_full_peg_gear"][peg][0])
    source.mkdir(parents=True)
    (source / "policy.zip").write_bytes(b"")
    calls.clear()
    reproduce.reproduce_tables(["6_peg_gear"])
    assert _trained_folders(calls) == [runs["ppo_from_source_60_peg_gear"][gear][0]]
    calls.clear()
    reproduce.reproduce_tables(["6_peg_gear"])  # nothing missing is short any more
    assert calls == []


def test_a_commands_episodes_count_its_teachers_and_short_jobs_need_short_sources():
    command = "rlfd train --task peg --episodes 700 --imitate force_search --imitation-episodes 200"
    assert reproduce.command_episodes(command) == 900
    assert reproduce.command_episodes("rlfd train --task peg --episodes 60") == 60
    jobs = [
        run_queue.TrainingJob("runs/long", "rlfd train --episodes 700 --out runs/long"),
        run_queue.TrainingJob("runs/after_long", "rlfd train --episodes 60", "runs/long"),
        run_queue.TrainingJob("runs/short", "rlfd train --episodes 200 --out runs/short"),
        run_queue.TrainingJob("runs/after_short", "rlfd train --episodes 60", "runs/short"),
        run_queue.TrainingJob("runs/after_after", "rlfd train --episodes 60", "runs/after_long"),
    ]
    short = reproduce._short_jobs(jobs, 200)
    assert [job.folder for job in short] == ["runs/short", "runs/after_short"]
    assert reproduce._short_jobs(jobs, 199) == []


def test_the_training_plan_lists_every_run_a_table_rests_on_with_its_recorded_time(
    tmp_path, monkeypatch, capsys
):
    from rlfd_drake.cli import main

    monkeypatch.chdir(tmp_path)
    plan = reproduce.training_plan(["6_peg_gear"])
    folders = [run["folder"] for run in plan["runs"]]
    expected = {run[0] for run in reproduce._table_runs(["6_peg_gear"], (0,))}
    assert expected <= set(folders) and len(folders) == len(set(folders))
    for run in plan["runs"]:
        if run["after"] is not None:
            assert folders.index(run["after"]) < folders.index(run["folder"])
    assert plan["runs_without_record"] == len(folders) and plan["recorded_total_wall_time_s"] == 0
    # A kept log's training time counts; a policy here is reported as here.
    first, second = plan["runs"][0]["folder"], plan["runs"][1]["folder"]
    kept = tmp_path / "results" / f"train_{Path(first).name}"
    kept.mkdir(parents=True)
    (kept / "metrics.json").write_text(json.dumps({"wall_time_s": 120.0, "episodes": 700}))
    (tmp_path / second).mkdir(parents=True)
    (tmp_path / second / "policy.zip").write_bytes(b"")
    plan = reproduce.training_plan(["6_peg_gear"])
    assert plan["runs"][0]["recorded_wall_time_s"] == 120.0
    assert plan["runs"][0]["recorded_episodes"] == 700
    assert plan["recorded_total_wall_time_s"] == 120.0
    assert plan["runs_without_record"] == len(folders) - 1
    assert [run["policy_here"] for run in plan["runs"]][:2] == [False, True]
    assert main(["reproduce", "--table", "6_peg_gear", "6_peg_gear", "--plan"]) == 0
    assert "2.0 |" in capsys.readouterr().out
    stored = json.loads((tmp_path / "results/reproduce_plan_6_peg_gear.json").read_text())
    assert stored["data"]["runs"] == plan["runs"]
    assert main(["reproduce", "--table", "all", "1", "--plan"]) == 2
    assert "'all' stands alone" in capsys.readouterr().err
    assert main(["reproduce", "--table", "paper", "1", "--plan"]) == 2
    assert "'paper' stands alone" in capsys.readouterr().err
    # The default is the paper's tables; the plan says which runs the quick budget trains.
    assert main(["reproduce", "--plan"]) == 0
    assert (
        "the quick budget without it only those among the 10 short ones" in capsys.readouterr().out
    )
    paper = json.loads((tmp_path / "results/reproduce_plan_paper.json").read_text())["data"]
    assert paper["tables"] == list(reproduce.PAPER_TABLES)
    quick = {run["folder"] for run in paper["runs"] if run["quick_budget_trains"]}
    assert quick == {
        run["folder"]
        for run in paper["runs"]
        if reproduce.command_episodes(run["command"]) <= reproduce.QUICK_RUN_EPISODES
        and (run["after"] is None or run["after"] in quick)
    }
    assert "runs/peg_easy_sac_pure_e200_s0" in quick and "runs/peg_ppo_s0" not in quick
    with pytest.raises(ValueError, match="tables must name at least one table"):
        reproduce.training_plan([])


def test_train_run_trains_a_real_run_by_its_command(tmp_path, monkeypatch):
    """The subprocess is the user's rlfd train: two PPO episodes leave a policy."""
    monkeypatch.chdir(tmp_path)
    folder = "runs/peg_easy_ppo_tiny_s0"
    command = f"rlfd train --task peg_easy --algo ppo --episodes 2 --seed 0 --envs 1 --out {folder}"
    reproduce.train_run(folder, command)
    assert (tmp_path / folder / "policy.zip").stat().st_size > 0
    assert json.loads((tmp_path / folder / "metrics.json").read_text())["episodes"] >= 2


@pytest.mark.parametrize(("table", "budget"), [("9", "quick"), ("1", "huge")])
def test_reproduce_rejects_unknown_tables_and_budgets(table, budget):
    with pytest.raises(ValueError, match="table|budget"):
        reproduce.reproduce_table(table, budget=budget)


def test_insertion_time_and_force_tables_reuse_the_evaluations(tmp_path, monkeypatch):
    from PIL import Image

    monkeypatch.chdir(tmp_path)
    calls = []

    def counting(*args, **kwargs):
        calls.append(args[2])
        return _fake_evaluation(*args, **kwargs)

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", counting)
    monkeypatch.setattr(
        reproduce, "_baseline_run", lambda *a: tmp_path / "runs" / "x" / "baseline.npz"
    )
    reproduce.reproduce_table("5", budget="quick", seed=0, workers=1)
    markdown = (tmp_path / "results" / "table_5.md").read_text()
    assert "Insertion time, s" in markdown
    assert "| None / None | 7.0 | 6.0 | 8.1 | 6.0 | 10.0 | 6.0 | n/a |" in markdown
    reproduce.reproduce_table("forces", budget="quick", seed=0, workers=1)
    assert (
        "| A  DMP | n/a | 40 (30 / -); LP 20; 2.5 N m | n/a | 40 (30 / -); LP 20; 2.5 N m | n/a |"
        in (tmp_path / "results" / "table_forces.md").read_text()
    )
    with Image.open(tmp_path / "results" / "table_forces.png") as plot:  # bars per column
        assert plot.size[0] == 300 + 300 * len(reproduce.TABLES["forces"].columns)
    assert "](table_forces.png)" in (tmp_path / "results" / "table_forces.md").read_text()
    # Table V's evaluations are Table IV's: same result names.
    assert all(name.startswith("eval_") for name in calls)


def _fake_runs(tmp_path, *folders):
    for folder in folders:
        run = tmp_path / folder
        run.mkdir(parents=True)
        (run / "policy.zip").write_bytes(b"")
        (run / "metrics.json").write_text(json.dumps({"episodes": 60}))


def test_linear_random_row_splits_translation_and_orientation(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    calls = []

    def recording(*args, **kwargs):
        calls.append(args)
        return _fake_evaluation(*args, **kwargs)

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", recording)
    for function in ("_baseline_run", "_baseline_path"):
        monkeypatch.setattr(
            reproduce, function, lambda method, task, *a: Path(f"runs/{task}_{method}/baseline.npz")
        )
    reproduce.reproduce_table("4", budget="quick", seed=0, workers=1)
    # (A baseline not on disk is first looked up among the stored evaluations.)
    split = [c for c in calls if c[1].endswith("|random")]
    assert list(dict.fromkeys(c[0] for c in split)) == ["peg", "gear", "rj45"]
    assert split[0][1] == "runs/peg_linear/baseline.npz|random"
    assert all(c[3] == "full" for c in split)  # the composer runs both parts
    assert "random_orientation" in split[0][2]


def test_table_3_and_6_evaluate_their_runs_with_their_composition(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _fake_runs(
        tmp_path,
        "runs/peg_easy_sac_pure_e200_s0",
        "runs/gear_ppo_s0",
        "runs/gear_ppo_from_rj45_e60_s0",
    )
    calls = []

    def recording(*args, **kwargs):
        calls.append(args)
        return _fake_evaluation(*args, **kwargs)

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", recording)
    data = reproduce.reproduce_table("3", budget="quick", seed=0, workers=1)
    pure = {c[0]: c for c in calls if "pure" in c[1]}
    assert set(pure) == {"peg_easy", "peg_hard"}  # trained on easy, evaluated on both
    assert all(c[8] == "pure" for c in pure.values())
    hybrid = next(r for r in data["rows"] if r["label"].startswith("hybrid"))
    assert "--composition hybrid" in hybrid["ours"]["easy"]["reason"]
    calls.clear()
    data = reproduce.reproduce_table("6", budget="quick", seed=0, workers=1)
    rows = {r["label"]: r["ours"] for r in data["rows"]}
    # The RJ-45 column of "source as is" runs the gear policy on RJ-45.
    assert any(c[0] == "rj45" and c[1] == "runs/gear_ppo_s0/policy.zip" for c in calls)
    assert rows["60 episodes from the source"]["gear"]["training_episodes"] == 60
    reason = rows["60 episodes from the source"]["rj45"]["reason"]
    assert "--algo ppo" in reason and "--init-from runs/gear_ppo_s0/policy.zip" in reason


def test_stored_evaluations_with_other_residual_bounds_are_not_reused(tmp_path, monkeypatch):
    from rlfd_drake import evaluate as evaluate_module
    from rlfd_drake.results import write_result

    monkeypatch.chdir(tmp_path)
    fresh = []
    monkeypatch.setattr(
        evaluate_module, "evaluate", lambda *a, **k: fresh.append(a) or {"episodes": 40}
    )
    monkeypatch.setattr(evaluate_module, "write_evaluation", lambda *a: None)
    stored = {"episodes": 40, "seed": 0, "success_rate": 0.0, "policy": "random"}
    stored["residual_policy_from_activation"] = True
    write_result("eval_rj45_random_n40_s0", stored, seed=0)  # before bounds were stored
    reproduce.stored_or_new_evaluation(
        "rj45", "random", "eval_rj45_random_n40_s0", "full", 40, 0, 1
    )
    assert len(fresh) == 1  # RJ-45's bounds are no longer the old 1 cm
    write_result("eval_peg_random_n40_s0", stored, seed=0)
    reproduce.stored_or_new_evaluation("peg", "random", "eval_peg_random_n40_s0", "full", 40, 0, 1)
    assert len(fresh) == 1  # the peg's are
    # The force table needs figures older evaluations lack: those are measured again.
    reproduce.stored_or_new_evaluation(
        "peg",
        "random",
        "eval_peg_random_n40_s0",
        "full",
        40,
        0,
        1,
        required=("peak_joint_contact_torque_nm",),
    )
    assert len(fresh) == 2


def _record_fresh_evaluations(tmp_path, monkeypatch) -> list[str]:
    """Works in ``tmp_path``; every evaluation run anew is a fake one whose policy is
    appended to the list returned (nothing is written)."""
    from rlfd_drake import evaluate as evaluate_module

    monkeypatch.chdir(tmp_path)
    fresh = []

    def fake_evaluate(task, policy, episodes, seed, **kwargs):
        fresh.append(policy)
        return _fake_evaluation(task, policy, "", "", episodes, seed, 1)

    monkeypatch.setattr(evaluate_module, "evaluate", fake_evaluate)
    monkeypatch.setattr(evaluate_module, "write_evaluation", lambda *a: None)
    return fresh


def test_an_evaluation_that_called_its_policy_from_the_start_is_measured_again(
    tmp_path, monkeypatch
):
    """Evaluations stored before the policy was first called at the residual's
    activation are measured again where the policy is here; where it is not, they
    are kept and marked in the table. The DMP alone calls no policy: kept as is."""
    from rlfd_drake.results import write_result

    fresh = _record_fresh_evaluations(tmp_path, monkeypatch)
    bounds = reproduce._bounds("peg")
    for policy in ("dmp", "random"):  # stored before: no residual_policy_from_activation
        old = {"episodes": 40, "seed": 0, "success_rate": 0.4, "policy": policy}
        write_result(f"eval_peg_{policy}_n40_s0", {**old, "residual_bounds": bounds}, seed=0)
    args = ("full", 40, 0, 1)
    dmp = reproduce.stored_or_new_evaluation("peg", "dmp", "eval_peg_dmp_n40_s0", *args)
    assert dmp["success_rate"] == 0.4 and fresh == []
    name = "eval_peg_random_n40_s0"
    kept = reproduce.stored_or_new_evaluation("peg", "random", name, *args, available=False)
    assert kept["success_rate"] == 0.4 and fresh == []
    again = reproduce.stored_or_new_evaluation("peg", "random", name, *args)
    assert again["residual_policy_from_activation"] and fresh == ["random"]

    def stored_random(task, policy, *a, **k):
        result = _fake_evaluation(task, policy, *a, **{**k, "available": True})
        return {**result, "residual_policy_from_activation": policy != "random"}

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", stored_random)
    data = reproduce.reproduce_table("2", budget="quick", seed=0, workers=1)
    cells = {row["source"]: row["ours"]["easy"] for row in data["rows"]}
    assert cells["random"]["policy_called_from_start"]
    assert "policy_called_from_start" not in cells["force_search"]
    markdown = (tmp_path / "results" / "table_2.md").read_text()
    assert "| 60.0 +- 5.0 \u2020 |" in markdown and "| 70.0 +- 5.0 |" in markdown
    assert reproduce.CALLED_FROM_START_NOTE in markdown


def test_an_evaluation_of_an_earlier_file_at_the_policy_path_is_measured_again(
    tmp_path, monkeypatch
):
    """A run trained again at the same path has a new policy.zip: its stored evaluation
    records the old file's fingerprint and is measured again; one of the same file is
    reused; one stored before fingerprints (none recorded) is reused as before; where
    the file is not here, the stored one stays."""
    from rlfd_drake.evaluate import policy_fingerprint
    from rlfd_drake.results import write_result

    fresh = _record_fresh_evaluations(tmp_path, monkeypatch)
    policy = tmp_path / "runs" / "a" / "policy.zip"
    policy.parent.mkdir(parents=True)
    policy.write_bytes(b"first training")
    stored = {
        "episodes": 40,
        "seed": 0,
        "success_rate": 0.4,
        "policy": str(policy),
        "residual_bounds": reproduce._bounds("peg"),
        "residual_policy_from_activation": True,
    }
    name, args = "eval_peg_a_n40_s0", ("full", 40, 0, 1)
    write_result(name, {**stored, "policy_sha256": policy_fingerprint(str(policy))}, seed=0)
    same = reproduce.stored_or_new_evaluation("peg", str(policy), name, *args)
    assert same["success_rate"] == 0.4 and fresh == []
    policy.write_bytes(b"second training")
    kept = reproduce.stored_or_new_evaluation("peg", str(policy), name, *args, available=False)
    assert kept["success_rate"] == 0.4 and fresh == []
    reproduce.stored_or_new_evaluation("peg", str(policy), name, *args)
    assert fresh == [str(policy)]
    write_result(name, stored, seed=0)  # stored before fingerprints: cannot tell
    reproduce.stored_or_new_evaluation("peg", str(policy), name, *args)
    assert fresh == [str(policy)]


def test_a_policy_fingerprint_covers_every_file_of_the_spec(tmp_path):
    from rlfd_drake.evaluate import policy_fingerprint

    a, b = tmp_path / "a.zip", tmp_path / "b.zip"
    a.write_bytes(b"a")
    b.write_bytes(b"b")
    assert policy_fingerprint("dmp") is None
    assert policy_fingerprint("force_search|slope") is None
    one = policy_fingerprint(str(a))
    split = policy_fingerprint(f"{a}|slope")
    assert split == one and len(one) == 64
    pair = policy_fingerprint(f"{a}+{b}")
    assert pair != one and pair != policy_fingerprint(f"{b}+{a}")
    b.write_bytes(b"B")
    assert policy_fingerprint(f"{a}+{b}") != pair
    with pytest.raises(ValueError, match="does not exist"):
        policy_fingerprint(str(tmp_path / "missing.zip"))


def test_a_fresh_clone_keeps_the_stored_evaluations_of_runs_it_does_not_have(tmp_path, monkeypatch):
    """Run folders are local: without one, its stored evaluation and its training log
    in results/ still fill the row, and nothing is evaluated anew for it."""
    from rlfd_drake.results import write_result

    evaluated = _record_fresh_evaluations(tmp_path, monkeypatch)
    monkeypatch.setattr(
        reproduce, "_baseline_run", lambda *a: tmp_path / "runs" / "x" / "baseline.npz"
    )
    stored = _fake_evaluation("gear", "stored", "", "", 40, 0, 1)
    stored.update(success_rate=0.9, seed=0, residual_bounds=reproduce._bounds("gear"))
    write_result("eval_gear_gear_sac_te1_s0_n40_s0", stored, seed=0)
    train_log = tmp_path / "results" / "train_gear_sac_te1_s0"
    train_log.mkdir(parents=True)
    (train_log / "metrics.json").write_text(json.dumps({"episodes": 300}))
    data = reproduce.reproduce_table("4", budget="quick", seed=0, workers=1)
    rows = {row["label"]: row["ours"] for row in data["rows"]}
    gear = rows["SAC / SAC (rLfD), mean action"]["gear"]
    assert gear["status"] == "measured" and gear["training_episodes"] == 300
    assert gear["success_pct"] == pytest.approx(90.0)
    peg = rows["SAC / SAC (rLfD), mean action"]["peg"]
    assert peg["status"] == "not run" and "rlfd train --task peg" in peg["reason"]
    sampled = rows["SAC / SAC (rLfD), sampled actions"]["gear"]
    assert sampled == {"status": "not run", "reason": reproduce.PAPER_BUDGET_ONLY_REASON}
    assert not [policy for policy in evaluated if "sac_te1" in policy]


@pytest.mark.parametrize(
    "table, columns", [("2", ("easy", "hard")), ("4", ("peg", "gear", "rj45"))]
)
def test_named_policies_are_evaluated_by_name(tmp_path, monkeypatch, table, columns):
    monkeypatch.chdir(tmp_path)
    asked = []

    def recording_evaluation(task, policy, name, *args, **kwargs):
        asked.append((task, policy))
        return _fake_evaluation(task, policy, name, *args, **kwargs)

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", recording_evaluation)
    monkeypatch.setattr(
        reproduce, "_baseline_run", lambda *a, **k: tmp_path / "runs" / "x" / "baseline.npz"
    )
    # The paper does not have the reference: only the paper budget evaluates it anew.
    data = reproduce.reproduce_table(table, budget="paper", seed=0, workers=1)
    tasks = reproduce.TABLES[table].columns
    assert all((tasks[column], "force_search") in asked for column in columns)
    row = next(r for r in data["rows"] if r["label"].startswith("Force-guided search"))
    assert all(row["ours"][column]["success_pct"] == pytest.approx(70.0) for column in columns)
    assert "not in the paper" in (tmp_path / "results" / f"table_{table}.md").read_text()


def test_the_quick_budget_shows_rows_the_paper_lacks_only_from_stored_evaluations(
    tmp_path, monkeypatch
):
    """Quick budget: a sampled-action row, a reference or an earlier policy is read from a
    stored evaluation of its name and never evaluated anew (nor its baseline trained);
    the paper's rows are evaluated as before."""
    monkeypatch.chdir(tmp_path)
    asked = []
    stored = {"eval_peg_easy_force_search_n40_s0"}

    def recording_evaluation(task, policy, name, *args, available=True, **kwargs):
        asked.append((name, available))
        return _fake_evaluation(
            task, policy, name, *args, available=available or name in stored, **kwargs
        )

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", recording_evaluation)
    monkeypatch.setattr(
        reproduce, "_baseline_run", lambda *a, **k: tmp_path / "runs" / "x" / "baseline.npz"
    )
    data = reproduce.reproduce_table("2", budget="quick", seed=0, workers=1)
    rows = {row["label"]: row["ours"] for row in data["rows"]}
    search = rows["Force-guided search (hand-written reference)"]
    assert search["easy"]["status"] == "measured"  # stored
    assert search["hard"] == {"status": "not run", "reason": reproduce.PAPER_BUDGET_ONLY_REASON}
    sampled = rows["rLfD PPO (shipped), sampled actions"]
    assert all(cell["status"] == "not run" for cell in sampled.values())
    assert rows["rLfD PPO (shipped), mean action"]["hard"]["status"] == "measured"
    assert rows["Random"]["hard"]["status"] == "measured"
    # Those rows only looked for a stored file; the paper's rows were evaluated.
    looked = dict(asked)
    assert looked["eval_peg_hard_force_search_n40_s0"] is False
    assert looked["eval_peg_hard_random_n40_s0"] is True
    assert reproduce.paper_budget_only(reproduce.TABLES["1"].rows[6], "quick")
    assert not reproduce.paper_budget_only(reproduce.TABLES["1"].rows[6], "paper")
    assert not reproduce.paper_budget_only(reproduce.TABLES["1"].rows[0], "quick")


def test_the_shipped_full_pose_row_runs_each_policy_on_the_task_it_was_trained_on(
    tmp_path, monkeypatch
):
    """Table IV's shipped row: each column's shipped file, evaluated on the task its
    sidecar names (gear's no-push rate variant, peg and RJ-45 as shipped), under a name
    of that task and file, with the file's training episodes, and no training."""
    monkeypatch.chdir(tmp_path)
    asked = {}

    def recording_evaluation(task, policy, name, *args, **kwargs):
        asked[name] = (task, policy)
        return _fake_evaluation(task, policy, name, *args, **kwargs)

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", recording_evaluation)
    monkeypatch.setattr(
        reproduce, "_baseline_run", lambda *a, **k: tmp_path / "runs" / "x" / "baseline.npz"
    )
    monkeypatch.setattr(reproduce, "train_runs", lambda *a, **k: pytest.fail("no training"))
    data = reproduce.reproduce_table("4", budget="quick", seed=0, workers=1)
    for key in ("full_pose", "full_pose_phase_stop", "both_targets"):
        [row] = [r for r in data["rows"] if r["source"] == f"shipped:{key}"]
        for column, (task, file) in reproduce.SHIPPED_BY_TASK[key].items():
            name = f"eval_{Path(task).stem}_{Path(file).stem}_n40_s0"
            assert asked[name] == (task, str(models_dir() / file))
            cell = row["ours"][column]
            assert cell["result_file"] == f"{name}.json"
            assert cell["training_episodes"] == reproduce._SHIPPED_EPISODES[file]
    assert reproduce.SHIPPED_BY_TASK["full_pose"]["gear"][0].endswith(
        "gear_incremental_nopush.yaml"
    )
    shipped = reproduce.SHIPPED_BY_TASK
    assert shipped["full_pose_phase_stop"]["rj45"][0].endswith("rj45_phase_stop.yaml")
    assert {k: v for k, v in shipped["full_pose_phase_stop"].items() if k != "rj45"} == {
        k: v for k, v in shipped["full_pose"].items() if k != "rj45"
    }


@pytest.mark.parametrize(
    "key, column",
    [("full_pose", "peg"), ("full_pose", "gear"), ("full_pose", "rj45")]
    + [("full_pose_phase_stop", "rj45")]
    + [("both_targets", column) for column in reproduce.SHIPPED_BY_TASK["both_targets"]],
)
def test_each_shipped_full_pose_policy_was_trained_on_the_task_it_runs_on(key, column):
    """The shipped files behind Table IV's shipped rows: each sidecar names the task the
    row evaluates it on (peg's wide-error file: its training-only variant of that task)
    and the episodes the table reports, and one episode runs."""
    from rlfd_drake.evaluate import evaluate
    from rlfd_drake.policies import training_config_file

    task, file = reproduce.SHIPPED_BY_TASK[key][column]
    shipped = models_dir() / file
    config = json.loads(training_config_file(shipped).read_text())["config"]
    wide_error = "models/tasks/variants/peg_incremental_wide_error.yaml"
    trained_on = {reproduce.SHIPPED_PEG_INCREMENTAL_POLICY: wide_error}
    assert config["task"] == trained_on.get(file, task)
    assert config["episodes"] == reproduce._SHIPPED_EPISODES[file]
    result = evaluate(task, str(shipped), 1, 0, workers=1, progress=False)
    assert result["episodes"] == 1 and result["peak_force_n"] > 0


def test_half_noise_row_and_full_pose_forces(tmp_path, monkeypatch):
    """Table IV's half-noise row asks for sampled actions at noise scale 0.5 under its
    own file name; the full-pose force table takes Table IV's rows with their forces."""
    monkeypatch.chdir(tmp_path)
    asked = {}

    def recording_evaluation(task, policy, name, *args, **kwargs):
        asked[name] = (args[4] if len(args) > 4 else kwargs.get("stochastic"), kwargs)
        return _fake_evaluation(task, policy, name, *args, **kwargs)

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", recording_evaluation)
    monkeypatch.setattr(
        reproduce, "_baseline_run", lambda *a, **k: tmp_path / "runs" / "x" / "baseline.npz"
    )
    (tmp_path / "results").mkdir()
    for task in ("peg", "gear", "rj45"):  # stored training logs of the gs4 runs
        folder = tmp_path / "results" / f"train_{task}_sac_gs4_s0"
        folder.mkdir()
        (folder / "metrics.json").write_text('{"episodes": 300}')
    data = reproduce.reproduce_table("forces_full_pose", budget="quick", seed=0, workers=1)
    half = "eval_gear_gear_sac_gs4_s0_stochastic0.5_n40_s0"
    stochastic, options = asked[half]
    assert stochastic is True and options["noise_scale"] == 0.5
    assert asked["eval_gear_gear_sac_gs4_s0_stochastic_n40_s0"][1]["noise_scale"] == 1.0
    labels = [row["label"] for row in data["rows"]]
    assert labels == [row.label for row in reproduce.TABLES["4"].rows]
    markdown = (tmp_path / "results" / "table_forces_full_pose.md").read_text()
    assert "| None / None | n/a | 40 (30 / -); LP 20; 2.5 N m |" in markdown


def test_a_stored_evaluation_missing_new_figures_is_kept_when_its_policy_is_gone(
    tmp_path, monkeypatch
):
    """Run folders stay on the machine that trained them: an older stored evaluation
    without the low-passed force still gives its other figures (n/a for the new ones)
    instead of a "not run" cell; with the policy here it is evaluated again."""
    from rlfd_drake.results import write_result

    monkeypatch.chdir(tmp_path)
    old = {"episodes": 40, "seed": 0, "success_rate": 0.5, "peak_force_n": 120.0}
    write_result("eval_gear_old_n40_s0", old, seed=0)
    required = reproduce._METRIC_KEYS["peak_force"]
    args = ("gear", "runs/old/policy.zip", "eval_gear_old_n40_s0", "full", 40, 0, 1)
    kept = reproduce.stored_or_new_evaluation(*args, required=required, available=False)
    assert kept["peak_force_n"] == 120.0 and "peak_low_passed_force_n" not in kept
    other_seed = ("gear", "runs/old/policy.zip", "eval_gear_old_n40_s0", "full", 40, 1, 1)
    assert reproduce.stored_or_new_evaluation(*other_seed, available=False) is None
    cell = {
        "peak_force_n": 120.0,
        "peak_force_by_outcome_n": {},
        "peak_low_passed_force_n": None,
        "peak_joint_contact_torque_nm": None,
    }
    assert reproduce._format_metric(cell, "peak_force") == "120; LP n/a; n/a"


_SMOOTH_VARIANTS = {
    "peg": "peg_soft_wrist_smooth_rot2deg",
    "gear": "gear_soft_wrist_smooth_rot2deg",
    "rj45": "rj45_soft_wrist_smooth",
}


@pytest.mark.parametrize(
    "table, variants",
    [
        ("wrist", {t: f"{t}_soft_wrist" for t in ("peg", "gear", "rj45")}),
        ("wrist_smooth", _SMOOTH_VARIANTS),
    ],
)
def test_the_wrist_tables_evaluate_the_variants(tmp_path, monkeypatch, table, variants):
    """The soft-wrist tables' columns are task YAML paths: each evaluation gets the path
    and a file named by the variant (as ``rlfd evaluate`` names it); a run not trained
    here is "not run" with the command that trains it on the variant."""
    monkeypatch.chdir(tmp_path)
    asked = {}

    def recording_evaluation(task, policy, name, *args, **kwargs):
        asked[name] = task
        return _fake_evaluation(task, policy, name, *args, **kwargs)

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", recording_evaluation)
    (tmp_path / "results").mkdir()
    data = reproduce.reproduce_table(table, budget="quick", seed=0, workers=1)
    for variant in variants.values():
        path = f"models/tasks/variants/{variant}.yaml"
        assert asked[f"eval_{variant}_dmp_n40_s0"] == path
        assert asked[f"eval_{variant}_{variant}_sac_gs4_s0_n40_s0"] == path
    dmp, mean_action, _ = data["rows"]
    gear = variants["gear"]
    assert dmp["ours"]["gear"]["result_file"] == f"eval_{gear}_dmp_n40_s0.json"
    reason = mean_action["ours"]["gear"]["reason"]
    assert f"rlfd train --task models/tasks/variants/{gear}.yaml" in reason
    assert "--sac-gradient-steps 4" in reason


_SMOOTH_PATHS = {t: f"models/tasks/variants/{v}.yaml" for t, v in _SMOOTH_VARIANTS.items()}


@pytest.mark.parametrize(
    "suffix, full, table, tasks, label",
    [
        ("", "rlfd_gs4", "6", {"gear": "gear", "rj45": "rj45"}, "SAC, 4 updates per step"),
        (
            "_soft_wrist_smooth",
            "rlfd_gs4_soft_wrist_smooth",
            "6_wrist_smooth",
            {t: _SMOOTH_PATHS[t] for t in ("gear", "rj45")},
            "SAC, soft wrist, low-passed",
        ),
    ],
)
def test_the_sac_transfer_rows_fine_tune_the_other_tasks_policy(suffix, full, table, tasks, label):
    """Table VI's SAC rows (shipped tasks and soft-wrist variants): the source is the
    other task's 4-update SAC policy, its fine-tune warms up on 1000 steps of the copied
    policy, and every 60-episode run keeps the full run's recipe in its own folder."""
    runs = reproduce.RUNS
    for target, source in ((tasks["gear"], tasks["rj45"]), (tasks["rj45"], tasks["gear"])):
        source_folder, source_command = runs[full][source]
        assert runs[f"sac_source_as_is{suffix}"][target][0] == source_folder
        folder, command = runs[f"sac_from_source_60{suffix}"][target]
        assert f"--task {target} " in command and "--episodes 60 " in command
        assert f"--init-from {source_folder}/policy.zip" in command
        # RJ-45's 60 episodes are about 900 steps: its fine-tune must update before they end.
        warm_up = 1000 if target == tasks["gear"] else 300
        assert f"--sac-learning-starts {warm_up} " in command
        assert "--sac-gradient-steps 4" in command
        tag = "" if warm_up == 1000 else f"_ls{warm_up}"
        assert folder == f"runs/{Path(target).stem}_sac_gs4_from_{Path(source).stem}{tag}_e60_s0"
        scratch_folder, scratch = runs[f"sac_scratch_60{suffix}"][target]
        assert "--init-from" not in scratch and "--episodes 60 " in scratch
        assert scratch_folder == f"runs/{Path(target).stem}_sac_gs4_scratch_e60_s0"
        full_recipe = runs[full][target][1].split("--episodes")[1].split("--out")[0]
        assert full_recipe.replace(" 300 ", " 60 ").replace(" 500 ", " 60 ") in scratch
    labels = [row.label for row in reproduce.TABLES[table].rows]
    assert f"{label}: 60 episodes from the source, sampled actions" in labels


def test_the_incremental_ppo_transfer_rows_fine_tune_the_other_tasks_700_episode_policy():
    """Table VI between the incremental variants: each 60-episode run keeps its target's
    700-episode PPO recipe (RJ-45's force-limit penalty included); the fine-tune starts
    from the other task's full run and reads the observation as that source does (its
    torque scale is in the copied networks), the scratch run as its own full run."""
    runs = reproduce.RUNS
    tasks = {
        "gear": "models/tasks/variants/gear_incremental.yaml",
        "rj45": "models/tasks/variants/rj45_slow_insert_incremental.yaml",
    }
    torque = "--contact-torque-nm 0.05"
    assert torque in runs["ppo_full_incremental"][tasks["rj45"]][1]
    assert torque not in runs["ppo_full_incremental"][tasks["gear"]][1]
    for target, source in (("gear", "rj45"), ("rj45", "gear")):
        source_folder, source_command = runs["ppo_full_incremental"][tasks[source]]
        full_folder, full_command = runs["ppo_full_incremental"][tasks[target]]
        assert "--episodes 700 " in full_command and "--algo ppo " in full_command
        assert runs["ppo_source_as_is_incremental"][tasks[target]][0] == source_folder
        recipe = full_command.split("--envs 2 ")[1].split(" --out")[0]
        folder, command = runs["ppo_from_source_60_incremental"][tasks[target]]
        assert f"--task {tasks[target]} " in command and "--episodes 60 " in command
        assert f"--init-from {source_folder}/policy.zip --out {folder}" in command
        assert (torque in command) == (torque in source_command)
        for flag in recipe.replace(torque, "").split("--")[1:]:
            assert f"--{flag.strip()}" in command
        assert folder.endswith(f"_from_{Path(tasks[source]).stem}_e60_s0")
        scratch_folder, scratch = runs["ppo_scratch_60_incremental"][tasks[target]]
        assert "--init-from" not in scratch and f"{recipe} --out {scratch_folder}" in scratch
        assert scratch_folder == full_folder.replace("_e700_", "_scratch_e60_")
    assert "--force-limit-penalty 1" in runs["ppo_from_source_60_incremental"][tasks["rj45"]][1]
    # The gear full run is the incremental table's 700-episode row.
    assert (
        runs["ppo_full_incremental"][tasks["gear"]] == (runs["rlfd_ppo_incremental"][tasks["gear"]])
    )
    labels = [row.label for row in reproduce.TABLES["6_incremental"].rows]
    assert "PPO, incremental: 60 episodes from the source, mean action" in labels


@pytest.mark.parametrize(
    "suffix, rj45",
    [
        ("_incremental_nopush", "rj45_slow_insert_incremental_nopush"),
        ("_phase_stop_nopush", "rj45_phase_stop_incremental_nopush"),
    ],
)
def test_the_no_push_transfer_fine_tunes_the_other_tasks_falling_step_size_policy(suffix, rj45):
    """Table VI between the no-push variants (RJ-45's slow or phase-stopped one): full
    training is one 1,400-episode run with the linear schedule (gear's is the no-push
    table's row); each 60-episode run keeps the constant step and starts from the other
    task's full run, reading it as it does."""
    from rlfd_drake.cli import build_parser

    runs = reproduce.RUNS
    tasks = {
        "gear": "models/tasks/variants/gear_incremental_nopush.yaml",
        "rj45": f"models/tasks/variants/{rj45}.yaml",
    }
    parse = build_parser().parse_args
    assert (
        runs[f"ppo_full{suffix}"][tasks["gear"]]
        == runs["rlfd_ppo_incremental_nopush_lrlin_1400"][tasks["gear"]]
    )
    for target, source in (("gear", "rj45"), ("rj45", "gear")):
        full = parse(runs[f"ppo_full{suffix}"][tasks[target]][1].split()[1:])
        source_full = parse(runs[f"ppo_full{suffix}"][tasks[source]][1].split()[1:])
        assert (full.task, full.episodes, full.learning_rate_schedule) == (
            tasks[target],
            1400,
            "linear",
        )
        assert runs[f"ppo_source_as_is{suffix}"][tasks[target]][0] == source_full.out
        folder, command = runs[f"ppo_from_source_60{suffix}"][tasks[target]]
        fine_tune = parse(command.split()[1:])
        assert (fine_tune.task, fine_tune.episodes, fine_tune.out) == (tasks[target], 60, folder)
        assert fine_tune.init_from == f"{source_full.out}/policy.zip"
        assert fine_tune.learning_rate_schedule == "constant"
        assert fine_tune.contact_torque_nm == source_full.contact_torque_nm
        assert fine_tune.force_limit_penalty == full.force_limit_penalty
        scratch = parse(runs[f"ppo_scratch_60{suffix}"][tasks[target]][1].split()[1:])
        assert (scratch.init_from, scratch.episodes) == (None, 60)
        assert scratch.contact_torque_nm == full.contact_torque_nm
    labels = [row.label for row in reproduce.TABLES[f"6{suffix}"].rows]
    assert "PPO, incremental, no push: 60 episodes from the source, mean action" in labels


def test_the_imitation_transfer_changes_only_rj45s_full_run_and_the_fine_tune_from_it():
    """6_phase_stop_nopush_imitation: RJ-45's full run copies the search and slope (through
    the rate) before 700 falling-step episodes; gear's fine-tune starts from it under a
    folder of its own; every other run is 6_phase_stop_nopush's."""
    from rlfd_drake.cli import build_parser

    runs, new, old = reproduce.RUNS, "_phase_stop_nopush_imitation", "_phase_stop_nopush"
    gear = "models/tasks/variants/gear_incremental_nopush.yaml"
    rj45 = "models/tasks/variants/rj45_phase_stop_incremental_nopush.yaml"
    parse = build_parser().parse_args
    full = parse(runs[f"ppo_full{new}"][rj45][1].split()[1:])
    assert (full.task, full.episodes, full.learning_rate_schedule) == (rj45, 700, "linear")
    assert (full.imitate, full.imitation_episodes) == ("force_search_and_slope", 200)
    assert runs[f"ppo_full{new}"][gear] == runs[f"ppo_full{old}"][gear]
    assert runs[f"ppo_source_as_is{new}"][gear][0] == full.out
    folder, command = runs[f"ppo_from_source_60{new}"][gear]
    assert folder != runs[f"ppo_from_source_60{old}"][gear][0]
    assert parse(command.split()[1:]).init_from == f"{full.out}/policy.zip"
    assert runs[f"ppo_from_source_60{new}"][rj45] == runs[f"ppo_from_source_60{old}"][rj45]
    for task in (gear, rj45):
        assert runs[f"ppo_scratch_60{new}"][task] == runs[f"ppo_scratch_60{old}"][task]


def test_the_shipped_transfer_table_trains_only_its_60_episode_runs(tmp_path, monkeypatch):
    """6_shipped: full training is each task's shipped rate residual, "as is" the other
    task's shipped file on the column's task; only the 60-episode runs train: from
    scratch (6_phase_stop_nopush's) and from the other task's shipped file, reading the
    observation as that file does, with no source run trained first, and a fine-tune's
    training episodes count the shipped file's."""
    from rlfd_drake.cli import build_parser

    monkeypatch.chdir(tmp_path)
    runs, shipped = reproduce.RUNS, reproduce.SHIPPED_BY_TASK
    gear = "models/tasks/variants/gear_incremental_nopush.yaml"
    rj45 = "models/tasks/variants/rj45_phase_stop_incremental_nopush.yaml"
    files = {task: shipped["rate_nopush"][task][1] for task in (gear, rj45)}
    assert files == {
        gear: reproduce.SHIPPED_GEAR_POLICY,
        rj45: "policies/rj45_phase_stop_nopush_ppo_imitate.zip",
    }
    assert shipped["rate_nopush_other_task"] == {
        gear: (gear, files[rj45]),
        rj45: (rj45, files[gear]),
    }
    parse = build_parser().parse_args
    for target, source in ((gear, rj45), (rj45, gear)):
        args = parse(runs["ppo_from_shipped_60_phase_stop_nopush"][target][1].split()[1:])
        assert (args.task, args.episodes, args.init_from) == (target, 60, f"models/{files[source]}")
        assert args.contact_torque_nm == (0.05 if source == rj45 else None)
    calls = []
    _recording_trainer(monkeypatch, calls)
    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", _fake_evaluation)
    [data] = reproduce.reproduce_tables(["6_shipped"], train_missing=True)
    trained = sorted(argv[argv.index("--out") + 1] for argv in calls)
    fine_tunes = runs["ppo_from_shipped_60_phase_stop_nopush"]
    scratch = runs["ppo_scratch_60_phase_stop_nopush"]
    assert trained == sorted(run[0] for run in [*fine_tunes.values(), *scratch.values()])
    assert all(
        cell["status"] == "measured" for row in data["rows"] for cell in row["ours"].values()
    )
    folder = Path(fine_tunes[rj45][0])
    (folder / "config.json").write_text(
        json.dumps({"config": {"init_from": f"models/{files[gear]}"}})
    )
    (folder / "metrics.json").write_text(json.dumps({"episodes": 60}))
    assert reproduce._trained_episodes(folder) == 60 + reproduce._SHIPPED_EPISODES[files[gear]]


def test_the_peg_gear_transfer_fine_tunes_each_tasks_best_rate_policy_reading_as_it_does():
    """Table VI between peg and gear: full training is each task's falling-step run (peg
    700 episodes, gear 1,400 without push); the 60-episode runs keep the constant step,
    the fine-tunes start from the other task's full run, and neither reads RJ-45's torque
    scale (neither source does), on 200 test starts with the mean action only."""
    from rlfd_drake.cli import build_parser

    runs = reproduce.RUNS
    tasks = {
        "gear": "models/tasks/variants/gear_incremental_nopush.yaml",
        "peg": "models/tasks/variants/peg_incremental.yaml",
    }
    parse = build_parser().parse_args
    for target, source, episodes in (("gear", "peg", 1400), ("peg", "gear", 700)):
        full = parse(runs["ppo_full_peg_gear"][tasks[target]][1].split()[1:])
        source_full = parse(runs["ppo_full_peg_gear"][tasks[source]][1].split()[1:])
        assert (full.task, full.episodes, full.learning_rate_schedule) == (
            tasks[target],
            episodes,
            "linear",
        )
        assert runs["ppo_source_as_is_peg_gear"][tasks[target]][0] == source_full.out
        folder, command = runs["ppo_from_source_60_peg_gear"][tasks[target]]
        assert folder.endswith(f"_so_tt_from_{Path(tasks[source]).stem}_e60_s0")
        fine_tune = parse(command.split()[1:])
        assert (fine_tune.task, fine_tune.episodes, fine_tune.out) == (tasks[target], 60, folder)
        assert fine_tune.init_from == f"{source_full.out}/policy.zip"
        assert fine_tune.learning_rate_schedule == "constant"
        torque_scales = {
            fine_tune.contact_torque_nm,
            full.contact_torque_nm,
            source_full.contact_torque_nm,
        }
        assert len(torque_scales) == 1
        assert fine_tune.force_limit_penalty == full.force_limit_penalty == 0.0
        scratch = parse(runs["ppo_scratch_60_peg_gear"][tasks[target]][1].split()[1:])
        assert (scratch.task, scratch.init_from, scratch.episodes) == (tasks[target], None, 60)
    table = reproduce.TABLES["6_peg_gear"]
    assert table.columns == tasks and table.evaluation_episodes == 200
    assert not any(row.stochastic for row in table.rows)
    assert "PPO, incremental: 60 episodes from the source, mean action" in [
        row.label for row in table.rows
    ]


def test_the_imitation_table_evaluates_the_copy_and_both_stages_on_rj45s_whole_grid(
    tmp_path, monkeypatch
):
    """The RJ-45 imitation table asks for 160 starts whatever the budget, evaluates the
    step-0 checkpoint (the copy of the search before RL) under its run's name, and counts
    0, 700 and 1,400 training episodes from the runs' logs (the second stage through
    its --init-from)."""
    monkeypatch.chdir(tmp_path)
    asked = []

    def recording_evaluation(task, policy, name, mode, episodes, *args, **kwargs):
        asked.append((task, policy, name, episodes))
        return _fake_evaluation(task, policy, name, mode, episodes, *args, **kwargs)

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", recording_evaluation)
    runs = reproduce.RUNS
    slow = "models/tasks/variants/rj45_slow_insert.yaml"
    first, second = runs["ppo_imitate_fs"][slow][0], runs["ppo_imitate_fs_1400"][slow][0]
    assert "--imitate force_search --imitation-episodes 200" in runs["ppo_imitate_fs"][slow][1]
    assert f"--init-from {first}/policy.zip" in runs["ppo_imitate_fs_1400"][slow][1]
    for folder, init_from in ((first, None), (second, f"{first}/policy.zip")):
        Path(folder, "checkpoints").mkdir(parents=True)
        Path(folder, "policy.zip").write_bytes(b"")
        Path(folder, "metrics.json").write_text(json.dumps({"episodes": 700}))
        config = {"config": {"init_from": init_from}}
        Path(folder, "config.json").write_text(json.dumps(config))
    Path(first, "checkpoints", "policy_0_steps.zip").write_bytes(b"")
    data = reproduce.reproduce_table("rj45_imitation", budget="quick", seed=0, workers=1)
    assert {episodes for *_, episodes in asked} == {160}
    names = {name for task, _, name, _ in asked if task == slow}
    stem = Path(first).name
    assert f"eval_rj45_slow_insert_{stem}_policy_0_steps_n160_s0" in names
    assert f"eval_rj45_slow_insert_{stem}_n160_s0" in names
    rows = {row["label"]: row["ours"]["rj45 slow insert"] for row in data["rows"]}
    trained = [rows[label]["training_episodes"] for label in list(rows)[2:5]]
    assert trained == [0, 700, 1400]
    row = next(
        line
        for line in Path("results/table_rj45_imitation.md").read_text().splitlines()
        if line.startswith("| PPO's copy")
    )
    assert row.endswith("| 0 |")
    # The shipped task's runs are not here: their rows say what trains them.
    shipped = next(r for r in data["rows"] if r["label"].endswith("1,400 episodes"))["ours"]
    assert shipped["rj45"]["status"] == "not run"
    assert "--task rj45 " in shipped["rj45"]["reason"]
    # The one-run falling-step row is on the shipped task only.
    one_run = next(r for r in data["rows"] if r["label"].endswith("falling to zero"))["ours"]
    assert one_run["rj45 slow insert"]["status"] == "not run"
    assert "no ppo_imitate_fs_lrlin_1400 run" in one_run["rj45 slow insert"]["reason"]


@pytest.mark.parametrize(
    "run_key, path, episodes",
    [
        ("rlfd_ppo_incremental_lrlin", "models/tasks/variants/peg_incremental.yaml", 700),
        (
            "rlfd_ppo_incremental_lrlin",
            "models/tasks/variants/peg_incremental_slope_start.yaml",
            700,
        ),
        ("rlfd_ppo_incremental_lrlin_1400", "models/tasks/variants/peg_incremental.yaml", 1400),
        (
            "rlfd_ppo_incremental_nopush_lrlin_1400",
            "models/tasks/variants/gear_incremental_nopush.yaml",
            1400,
        ),
        (
            "rlfd_ppo_incremental_nopush_lrlin_2100",
            "models/tasks/variants/gear_incremental_nopush.yaml",
            2100,
        ),
        ("ppo_imitate_fs_lrlin_1400", "rj45", 1400),
        ("ppo_imitate_fs_slope_lrlin_1400", "rj45", 1400),
    ],
)
def test_the_falling_step_size_rows_train_in_one_run_with_a_linear_schedule(
    run_key, path, episodes
):
    """Section 15's rows: one run (no --init-from stage) of section 8's PPO recipe with the
    linear schedule, into the folder the row evaluates, as ``rlfd train`` parses it."""
    from rlfd_drake.cli import build_parser

    folder, command = reproduce.RUNS[run_key][path]
    args = build_parser().parse_args(command.split()[1:])
    assert args.learning_rate_schedule == "linear"
    assert (args.task, args.episodes, args.algo, args.out) == (path, episodes, "ppo", folder)
    assert args.init_from is None
    assert (args.log_std_init, args.scaled_observation, args.timeout_terminal) == (-2.0, True, True)


@pytest.mark.parametrize(
    ("run_key", "task", "table_name", "checkpoints"),
    [
        ("ppo_imitate_fs_slope_lrlin_1400", "rj45", "rj45_imitation", ["policy_0_steps", None]),
        ("ppo_imitate_fs_slope_lrlin", "peg", "peg_imitation", ["policy_0_steps", None]),
        ("ppo_imitate_fs_slope_lrlin_peak_cost", "peg", "peg_imitation", [None]),
    ],
)
def test_the_slope_teacher_rows_train_what_the_studies_ran(
    run_key, task, table_name, checkpoints, monkeypatch
):
    """rj45_study.md's last section and full_pose_study.md sections 24-26: the falling-step
    imitation recipe whose teacher is the search with the slope's turn (on peg also with a
    cost on the peak force); the row's command parses to the one its stored training log
    (results/train_<folder>/) records."""
    from rlfd_drake.cli import build_parser
    from rlfd_drake.run_log import run_log_file

    monkeypatch.chdir(Path(reproduce.__file__).parents[1])  # the checkout's results/
    folder, command = reproduce.RUNS[run_key][task]
    ran = json.loads(run_log_file(folder, "config.json").read_text())["command"]
    parser = build_parser()
    row = vars(parser.parse_args(command.split()[1:]))
    studied = vars(parser.parse_args(ran.split()[1:]))
    assert {k: v for k, v in row.items() if k != "no_progress"} == {
        k: v for k, v in studied.items() if k != "no_progress"
    }
    assert row["imitate"] == "force_search_and_slope" and row["task"] == task
    rows = reproduce.TABLES[table_name].rows
    assert "Force-guided search + the slope's constant turn" in [r.label for r in rows]
    assert [r.checkpoint for r in rows if r.source == f"run:{run_key}"] == checkpoints


@pytest.mark.parametrize(
    ("table_name", "column", "field", "value"),
    [
        ("rj45_residual_rate", "rj45, 20 Hz residual", "residual_period_s", 0.05),
        ("rj45_phase_stop", "rj45, phase-stopped DMP", "dmp_phase_stop_gain_per_m2", 1e5),
    ],
)
def test_the_rj45_variant_tables_train_the_slope_recipe_on_their_variant(
    table_name, column, field, value
):
    """rj45_study.md's last sections: the slope-teacher recipe, unchanged, on a variant
    of rj45; the variant's command differs from rj45's only in task and folder."""
    from rlfd_drake.cli import build_parser
    from rlfd_drake.tasks import load_task

    table = reproduce.TABLES[table_name]
    variant_task = table.columns[column]
    assert list(table.columns.values()) == ["rj45", variant_task]
    assert getattr(load_task(variant_task), field) == value
    runs = reproduce.RUNS["ppo_imitate_fs_slope_lrlin_1400"]
    parser = build_parser()
    shipped = vars(parser.parse_args(runs["rj45"][1].split()[1:]))
    variant = vars(parser.parse_args(runs[variant_task][1].split()[1:]))
    assert variant["task"] == variant_task and variant["out"] == runs[variant_task][0]
    assert runs[variant_task][0].startswith(f"runs/{Path(variant_task).stem}_ppo_")
    differ = {k for k in shipped if shipped[k] != variant[k]}
    assert differ == {"task", "out"}
    assert table.evaluation_episodes == 160


def test_the_wide_error_row_trains_on_its_training_variant_and_fills_the_peg_column():
    """Section 19's row: the falling-step recipe trained on the +-2.5 mm variant, its
    policy evaluated in the incremental table's peg column (peg_incremental)."""
    from rlfd_drake.cli import build_parser

    peg = "models/tasks/variants/peg_incremental.yaml"
    wide = "models/tasks/variants/peg_incremental_wide_error.yaml"
    folder, command = reproduce.RUNS["rlfd_ppo_incremental_wide_error_lrlin"][peg]
    args = build_parser().parse_args(command.split()[1:])
    assert (args.task, args.episodes, args.learning_rate_schedule) == (wide, 700, "linear")
    assert folder == "runs/peg_incremental_wide_error_ppo_std2_so_tt_lrlin_e700_s0" == args.out
    labels = [row.label for row in reproduce.TABLES["incremental"].rows]
    assert sum("+-2.5 mm of fixture error" in label for label in labels) == 2  # mean, sampled


def test_a_seeded_run_trains_with_its_seed_from_the_same_seeds_earlier_stage():
    """Every RUNS entry trains with seed 0; seeded_run gives seed 2's: its own folder and
    the --init-from stage it starts from both end in _s2, and rlfd parses the command."""
    from rlfd_drake.cli import build_parser

    gear = "models/tasks/variants/gear_incremental.yaml"
    run = reproduce.RUNS["rlfd_ppo_incremental_1400"][gear]
    assert reproduce.seeded_run(run, 0) == run
    folder, command = reproduce.seeded_run(run, 2)
    assert folder == run[0].removesuffix("_s0") + "_s2"
    args = build_parser().parse_args(command.split()[1:])
    assert (args.seed, args.out) == (2, folder)
    first_stage = reproduce.RUNS["rlfd_ppo_incremental"][gear][0]
    assert args.init_from == first_stage.removesuffix("_s0") + "_s2/policy.zip"
    for bad in (-1, True, 1.5):
        with pytest.raises(ValueError, match="training_seed"):
            reproduce.seeded_run(run, bad)


def test_a_table_over_training_seeds_reports_the_seeds_mean_and_spread(tmp_path, monkeypatch):
    """With training seeds 0-2 a run row is the mean +- sample std of the seeds whose
    policy is here (a missing seed is listed with the command that trains it); other
    rows are trained once; the seed-0 table is not overwritten."""
    import re

    monkeypatch.chdir(tmp_path)
    peg = "models/tasks/variants/peg_incremental.yaml"
    folder = reproduce.RUNS["rlfd_ppo_incremental_lrlin"][peg][0].removesuffix("_s0")
    for seed in (0, 1):
        run = tmp_path / f"{folder}_s{seed}"
        run.mkdir(parents=True)
        (run / "policy.zip").write_bytes(b"")
        if seed == 0:  # seed 1's log is elsewhere: the recipe's count is seed 0's
            (run / "metrics.json").write_text(json.dumps({"episodes": 700}))
    for seed, episodes in ((3, 700), (4, 701)):  # two env processes may overshoot by one
        run = tmp_path / f"{folder}_s{seed}"
        run.mkdir(parents=True)
        (run / "policy.zip").write_bytes(b"")
        (run / "metrics.json").write_text(json.dumps({"episodes": episodes}))
    rates = {"0": 0.98, "1": 0.96, "3": 0.9, "4": 0.9}

    def seeded_evaluation(task, policy, name, *args, **kwargs):
        result = _fake_evaluation(task, policy, name, *args, **kwargs)
        trained = re.search(r"lrlin_e700_s(\d)/policy.zip", policy)
        if result is not None and trained:
            result["success_rate"] = rates[trained.group(1)]
            result["peak_force_n"] = 100.0 + 10 * int(trained.group(1))
        return result

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", seeded_evaluation)
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "table_incremental.md").write_text("seed 0's table\n")
    data = reproduce.reproduce_table("incremental", training_seeds=(0, 1, 2), workers=1)
    rows = {row["label"]: row["ours"] for row in data["rows"]}
    label = "PPO / PPO (rLfD), incremental, step size falling to 0, 700 episodes, mean action"
    cell = rows[label]["peg"]
    assert cell["success_pct"] == pytest.approx(97.0)
    assert cell["success_std_pct"] == pytest.approx(2**0.5)
    assert cell["peak_force_n"] == pytest.approx(105.0)
    assert cell["training_seeds"] == [0, 1]
    assert cell["training_episodes"] == 700
    both = reproduce.reproduce_table("incremental", training_seeds=(3, 4), workers=1)
    overshoot = next(row for row in both["rows"] if row["label"] == label)["ours"]["peg"]
    assert overshoot["training_episodes"] == "700-701"
    assert "--seed 2 " in cell["missing_seeds"]["2"]
    assert f"{folder}_s2" in cell["missing_seeds"]["2"]
    assert "training_seeds" not in rows["None / None (DMP alone)"]["peg"]
    markdown = (tmp_path / "results" / "table_incremental_training_seeds_0_1_2.md").read_text()
    assert "97.0 +- 1.4 (2 of 3 seeds)" in markdown
    assert "training seeds 0, 1, 2" in markdown
    assert "--seed 2 " in markdown.split("Not run:")[1]
    assert (tmp_path / "results" / "table_incremental.md").read_text() == "seed 0's table\n"


@pytest.mark.parametrize("seeds", [(), (0, 0), (-1,), (0, "1")])
def test_reproduce_refuses_bad_training_seeds(seeds):
    with pytest.raises(ValueError, match="training_seed"):
        reproduce.reproduce_table("incremental", training_seeds=seeds)


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        ({"seed": -1}, "seed \\(the evaluation seed\\) must be an integer >= 0, got -1"),
        ({"seed": True}, "seed \\(the evaluation seed\\) must be an integer >= 0, got True"),
        ({"workers": 0}, "workers must be an integer >= 1, got 0"),
        ({"budget": "slow"}, "budget must be one of \\['paper', 'quick'\\], got 'slow'"),
    ],
)
def test_reproduce_refuses_a_bad_argument_before_it_trains_or_evaluates(
    tmp_path, monkeypatch, arguments, message
):
    """Checked up front, so a quick budget never trains its short runs first and then
    fails in an evaluation's worker pool."""
    monkeypatch.chdir(tmp_path)
    calls = []
    _recording_trainer(monkeypatch, calls)

    def evaluation(*args, **kwargs):
        raise AssertionError("evaluated despite a bad argument")

    monkeypatch.setattr(reproduce, "stored_or_new_evaluation", evaluation)
    for measure in (reproduce.reproduce_tables, reproduce.reproduce_table):
        with pytest.raises(ValueError, match=message):
            measure(["3"] if measure is reproduce.reproduce_tables else "3", **arguments)
    assert calls == [] and not (tmp_path / "results").exists()
