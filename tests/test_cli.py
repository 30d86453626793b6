"""The `rlfd` command: listing, fitting, and clear errors."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from rlfd_drake.cli import main
from rlfd_drake.paths import model_path


def test_tasks_json_lists_every_task(capsys):
    assert main(["tasks", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert set(rows) == {"peg_easy", "peg_hard", "peg", "gear", "rj45"}


def test_fit_writes_parameters_and_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "dmp.npz"
    demo = str(model_path("demos/peg.csv"))
    assert main(["fit", "--demo", demo, "--out", str(out)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["position_rmse_mm"] < 1.0 and report["orientation_rmse_deg"] < 0.5
    assert out.exists()
    assert main(["fit", "--demo", demo, "--out", str(out)]) == 2
    assert "exists; pass --overwrite" in capsys.readouterr().err


def test_bad_input_is_a_one_line_error(tmp_path, capsys):
    assert (
        main(["fit", "--demo", str(tmp_path / "none.csv"), "--out", str(tmp_path / "x.npz")]) == 2
    )
    assert "rlfd: error" in capsys.readouterr().err
    assert main(["train", "--task", "peg_huge", "--episodes", "1"]) == 2
    assert "task must be one of" in capsys.readouterr().err
    assert main(["reproduce", "--table", "6", "--train-missing", "--parallel-runs", "0"]) == 2
    assert "parallel runs must be an integer >= 1, got 0" in capsys.readouterr().err
    out = tmp_path / "shaped"
    args = ["train", "--distance-shaping", "-1", "--episodes", "1", "--out", str(out)]
    assert main(args) == 2
    assert "distance_shaping must be a number >= 0, got -1.0" in capsys.readouterr().err
    assert not out.exists()
    with pytest.raises(SystemExit):
        main(["train", "--algo", "dqn"])
    assert main(["demo", "--episodes", "0"]) == 2  # refused before the DMP is fitted
    captured = capsys.readouterr()
    assert "episodes must be >= 1, got 0" in captured.err and "[1/4]" not in captured.out


def test_demo_record_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "demo.csv"
    out.write_text("precious\n")
    assert main(["demo", "record", "--task", "peg_easy", "--out", str(out)]) == 2
    assert out.read_text() == "precious\n"
    fresh = tmp_path / "fresh.csv"
    assert main(["demo", "record", "--task", "rj45", "--insert-s", "0", "--out", str(fresh)]) == 2
    assert "insert_s: must be a positive duration" in capsys.readouterr().err
    assert not fresh.exists()


def test_evaluation_file_names_of_policy_specs():
    from rlfd_drake.evaluate import policy_stem

    assert policy_stem("runs/peg_linear_s0/baseline.npz") == "peg_linear_s0"
    assert policy_stem("runs/peg_sac_s0/policy.zip") == "peg_sac_s0"
    assert policy_stem("sac:runs/peg_sac_s0/policy.zip") == "peg_sac_s0"
    assert policy_stem("models/policies/peg_easy_sac.zip") == "peg_easy_sac"
    assert policy_stem("runs/peg_linear_s0/baseline.npz|random") == "peg_linear_s0_and_random"
    # Every run names its checkpoints alike: the run folder keeps them apart.
    checkpoint = "runs/peg_ppo_s0/checkpoints/policy_2000_steps.zip"
    assert policy_stem(checkpoint) == "peg_ppo_s0_policy_2000_steps"
    assert policy_stem("runs/peg_ppo_s0/eval/best_model.zip") == "peg_ppo_s0_best_model"
    from rlfd_drake.evaluate import evaluation_name

    stem = "runs/peg_sac_s0/policy.zip"
    assert evaluation_name("peg", stem, "full", True, 0) == "eval_peg_peg_sac_s0_stochastic_s0"
    assert (
        evaluation_name("peg", stem, "full", True, 0, noise_scale=0.5)
        == "eval_peg_peg_sac_s0_stochastic0.5_s0"
    )
    # A variant given by path is named by its file stem, with the episode count as
    # rlfd reproduce names its evaluations.
    variant = "models/tasks/variants/gear_soft_wrist.yaml"
    assert (
        evaluation_name(variant, "dmp", "full", False, 0, episodes=40)
        == "eval_gear_soft_wrist_dmp_n40_s0"
    )


def test_an_ensemble_of_many_runs_gets_an_evaluation_name_a_file_can_have():
    """The policy part of a default evaluation name is capped (start and hash), and
    what follows it (mode, count, seed) is kept, so reproduce still finds it."""
    from rlfd_drake.evaluate import POLICY_STEM_MAX, evaluation_name

    members = [
        f"runs/peg_incremental_ppo_std2_so_tt_lrlin_e700_s{seed}/policy.zip" for seed in range(5)
    ]
    name = evaluation_name("peg_incremental", "+".join(members), "full", True, 0, episodes=200)
    stem = name.removeprefix("eval_peg_incremental_").removesuffix("_stochastic_n200_s0")
    assert len(stem) == POLICY_STEM_MAX
    assert stem.startswith("peg_incremental_ppo_std2_so_tt_lrlin_e700_s0_plus_")
    assert len(name + ".episodes.json.gz") < 255
    fewer = evaluation_name("peg_incremental", "+".join(members[:4]), "full", True, 0, episodes=200)
    assert fewer != name  # the hash tells the ensembles apart
    two = "+".join(members[:2])
    assert evaluation_name("peg", two, "full", False, 0) == (
        "eval_peg_peg_incremental_ppo_std2_so_tt_lrlin_e700_s0_plus_"
        "peg_incremental_ppo_std2_so_tt_lrlin_e700_s1_s0"
    )  # short enough: unchanged


def test_evaluate_checks_its_result_name_before_running(tmp_path, monkeypatch, capsys):
    import rlfd_drake.evaluate

    monkeypatch.chdir(tmp_path)

    def must_not_run(*args, **kwargs):
        raise AssertionError("evaluated before the name was checked")

    monkeypatch.setattr(rlfd_drake.evaluate, "evaluate", must_not_run)
    argv = ["evaluate", "--policy", "dmp", "--episodes", "1", "--name", "sub/dir"]
    assert main(argv) == 2
    assert "result name must be a plain file stem, got 'sub/dir'" in capsys.readouterr().err


def test_evaluate_defaults_to_the_task_grid(tmp_path, monkeypatch, capsys):
    """Without --episodes the evaluation runs the task's grid (it crashed on None)."""
    import rlfd_drake.evaluate

    monkeypatch.chdir(tmp_path)
    calls = {}

    def record(task, policy, episodes, **kwargs):
        calls["episodes"] = episodes
        raise ValueError("stop here")

    monkeypatch.setattr(rlfd_drake.evaluate, "evaluate", record)
    assert main(["evaluate", "--task", "rj45", "--policy", "dmp"]) == 2
    assert calls["episodes"] == 160
    assert main(["evaluate", "--task", "peg_easy", "--policy", "dmp"]) == 2
    assert calls["episodes"] == 500


def test_noise_scale_needs_stochastic(capsys):
    assert main(["evaluate", "--policy", "dmp", "--noise-scale", "0.5", "--episodes", "1"]) == 2
    assert "--noise-scale 0.5 needs --stochastic" in capsys.readouterr().err


def test_evaluate_refuses_to_overwrite_a_stored_result(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    stored = tmp_path / "results" / "eval_peg_easy_dmp_translation_n1_s0.json"
    stored.parent.mkdir()
    stored.write_text("{}")
    argv = ["evaluate", "--policy", "dmp", "--episodes", "1", "--residual-mode", "translation"]
    assert main(argv) == 2
    assert "exists; pass --overwrite" in capsys.readouterr().err
    assert stored.read_text() == "{}"


def test_saved_policies_run_in_the_residual_mode_they_were_trained_with(tmp_path):
    from rlfd_drake.evaluate import trained_mode

    run = tmp_path / "run"
    run.mkdir()
    (run / "policy.zip").write_bytes(b"")
    assert trained_mode(str(run / "policy.zip")) == "full"  # unknown
    (run / "config.json").write_text(json.dumps({"config": {"residual_mode": "translation"}}))
    assert trained_mode(str(run / "policy.zip")) == "translation"
    assert trained_mode(f"sac:{run / 'policy.zip'}") == "translation"
    assert trained_mode("dmp") == "full"


def test_the_shipped_policy_records_its_translation_only_training():
    from rlfd_drake.evaluate import trained_mode
    from rlfd_drake.paths import SHIPPED_POLICY, models_dir
    from rlfd_drake.policies import training_config_file

    shipped = models_dir() / SHIPPED_POLICY
    assert trained_mode(str(shipped)) == "translation"  # what make demo runs it in
    command = json.loads(training_config_file(shipped).read_text())["command"]
    assert "--residual-mode translation" in command and "--task peg_easy" in command


def test_the_shipped_rj45_policy_reads_the_torque_as_trained_and_runs_alone():
    """models/policies/rj45_slow_insert_ppo_imitate.zip (results/rj45_study.md): PPO
    started from a copy of the force search; its networks read the wrist torque at
    0.05 N m per unit (a buffer of the copied feature extractor), its sidecar names the
    run it continued, and an evaluation episode runs the network with no rule beside it."""
    import numpy as np

    from rlfd_drake.evaluate import evaluate
    from rlfd_drake.observation_scaling import contact_scales
    from rlfd_drake.paths import SHIPPED_RJ45_POLICY, models_dir
    from rlfd_drake.policies import load_sb3_model, training_config_file

    shipped = models_dir() / SHIPPED_RJ45_POLICY
    model, kind = load_sb3_model(shipped)
    assert kind == "ppo"
    per_step = np.asarray(contact_scales(0.05), dtype=np.float32)
    scales = model.policy.features_extractor.scales.numpy()
    assert np.array_equal(scales, np.tile(per_step, scales.size // per_step.size))
    config = json.loads(training_config_file(shipped).read_text())["config"]
    assert config["task"].endswith("rj45_slow_insert.yaml") and config["base_correction"] is None
    assert "imitate_fs" in config["init_from"]
    result = evaluate(
        "models/tasks/variants/rj45_slow_insert.yaml", str(shipped), 1, 0, workers=1, progress=False
    )
    assert result["episodes"] == 1 and result["peak_force_n"] > 0
    # The file it ran, fingerprinted (a policy retrained at the path is measured again).
    assert result["policy_sha256"] == hashlib.sha256(shipped.read_bytes()).hexdigest()


def test_the_shipped_full_pose_peg_policy_was_trained_on_the_wide_error_and_runs_on_peg():
    """models/policies/peg_incremental_ppo_wide_error.zip (results/full_pose_study.md,
    section 19): PPO trained on the +-2.5 mm training variant, its sidecar says so, and
    it runs on peg_incremental, whose policies read the incremental residual's rate."""
    from rlfd_drake.evaluate import evaluate
    from rlfd_drake.paths import SHIPPED_PEG_INCREMENTAL_POLICY, models_dir
    from rlfd_drake.policies import load_sb3_model, training_config_file

    shipped = models_dir() / SHIPPED_PEG_INCREMENTAL_POLICY
    model, kind = load_sb3_model(shipped)
    assert kind == "ppo"
    config = json.loads(training_config_file(shipped).read_text())["config"]
    assert config["task"].endswith("peg_incremental_wide_error.yaml")
    assert (config["seed"], config["episodes"], config["learning_rate_schedule"]) == (
        1,
        700,
        "linear",
    )
    result = evaluate(
        "models/tasks/variants/peg_incremental.yaml", str(shipped), 1, 0, workers=1, progress=False
    )
    assert result["episodes"] == 1 and result["peak_force_n"] > 0


def test_the_shipped_from_zero_peg_policy_is_the_seed_validation_chose_and_runs_on_peg():
    """models/policies/peg_incremental_ppo_best_of_seven.zip (results/full_pose_study.md,
    sections 38-39): the paper's recipe from a zero residual, no teacher, training seed 1
    of seven; the stored fresh-start evaluation ran these very bytes."""
    from rlfd_drake.evaluate import evaluate
    from rlfd_drake.paths import SHIPPED_PEG_FROM_ZERO_POLICY, models_dir
    from rlfd_drake.policies import load_sb3_model, training_config_file

    shipped = models_dir() / SHIPPED_PEG_FROM_ZERO_POLICY
    model, kind = load_sb3_model(shipped)
    assert kind == "ppo"
    config = json.loads(training_config_file(shipped).read_text())["config"]
    assert config["task"] == "models/tasks/variants/peg_incremental.yaml"
    assert (config["seed"], config["episodes"], config["learning_rate"]) == (1, 700, 6e-4)
    assert config["init_from"] is None and config.get("imitate") is None
    stored = Path(__file__).resolve().parents[1] / "results"
    fresh = stored / "eval_peg_incremental_peg_incremental_ppo_best_of_seven_n200_s2.json"
    record = json.loads(fresh.read_text())["data"]
    assert record["policy_sha256"] == hashlib.sha256(shipped.read_bytes()).hexdigest()
    result = evaluate(
        "models/tasks/variants/peg_incremental.yaml", str(shipped), 1, 0, workers=1, progress=False
    )
    assert result["episodes"] == 1 and result["peak_force_n"] > 0


def test_the_shipped_peg_copy_policy_records_its_teacher_and_cost_and_runs_on_peg():
    """models/policies/peg_ppo_imitate_peak_cost.zip (results/full_pose_study.md, section
    26): PPO from a copy of the search with the slope's turn, charged for the one-step
    peak above 116 N; its sidecar says so, and the network runs alone on the shipped peg."""
    from rlfd_drake.evaluate import evaluate
    from rlfd_drake.paths import SHIPPED_PEG_IMITATION_POLICY, models_dir
    from rlfd_drake.policies import load_sb3_model, training_config_file

    shipped = models_dir() / SHIPPED_PEG_IMITATION_POLICY
    model, kind = load_sb3_model(shipped)
    assert kind == "ppo"
    config = json.loads(training_config_file(shipped).read_text())["config"]
    assert (config["task"], config["imitate"], config["seed"]) == (
        "peg",
        "force_search_and_slope",
        2,
    )
    assert (config["peak_force_cost"], config["peak_force_threshold_n"]) == (0.5, 116.0)
    assert config["peak_force_signal"] == "one_step" and config["base_correction"] is None
    result = evaluate("peg", str(shipped), 1, 0, workers=1, progress=False)
    assert result["episodes"] == 1 and result["peak_force_n"] > 0


def test_the_shipped_rj45_rate_policy_records_its_rate_teacher_and_runs_on_its_task():
    """models/policies/rj45_phase_stop_nopush_ppo_imitate.zip (results/full_pose_study.md,
    section 30): PPO from a copy of the search taught through the rate on RJ-45's
    phase-stopped no-push rate variant; its sidecar says so, and the network runs alone
    there with the rate residual's observation (the held offset is part of it)."""
    from rlfd_drake.evaluate import evaluate
    from rlfd_drake.paths import SHIPPED_RJ45_PHASE_STOP_RATE_POLICY, models_dir
    from rlfd_drake.policies import load_sb3_model, training_config_file

    shipped = models_dir() / SHIPPED_RJ45_PHASE_STOP_RATE_POLICY
    _, kind = load_sb3_model(shipped)
    assert kind == "ppo"
    config = json.loads(training_config_file(shipped).read_text())["config"]
    assert config["task"].endswith("rj45_phase_stop_incremental_nopush.yaml")
    assert (config["imitate"], config["seed"], config["episodes"]) == (
        "force_search_and_slope",
        1,
        700,
    )
    assert config["base_correction"] is None
    result = evaluate(config["task"], str(shipped), 1, 0, workers=1, progress=False)
    assert result["episodes"] == 1 and result["peak_force_n"] > 0


def test_plot_draws_stored_evaluations_and_refuses_bad_input(tmp_path, capsys):
    """rlfd plot: the stored evaluations, one panel per task, without running anything."""
    from PIL import Image

    results = Path(__file__).resolve().parents[1] / "results"
    stored = [str(results / f"eval_{name}_n40_s0.json") for name in ("gear_dmp", "rj45_dmp")]
    stored.append(str(results / "eval_rj45_force_search_n40_s0.json"))
    out = tmp_path / "cmp.png"
    assert main(["plot", *stored, "--out", str(out)]) == 0
    with Image.open(out) as plot:  # gear and rj45: two panels
        assert plot.size == (1000, 340)
    before = out.read_bytes()
    assert main(["plot", *stored, "--out", str(out)]) == 2
    assert "exists; pass --overwrite" in capsys.readouterr().err
    assert out.read_bytes() == before
    forces = tmp_path / "forces.png"
    assert main(["plot", *stored, "--kind", "forces", "--out", str(forces)]) == 0
    assert forces.read_bytes()[:4] == b"\x89PNG"
    for argv, message in (
        ([*stored, "--labels", "a", "b"], "--labels: one per result file (3), got 2"),
        ([str(results / "table_1.json")], "is not an evaluation JSON"),
        ([str(tmp_path / "none.json")], "results: no evaluation file at"),
    ):
        assert main(["plot", *argv, "--out", str(tmp_path / "x.png")]) == 2
        assert message in capsys.readouterr().err
    assert main(["plot", stored[0], "--out", str(tmp_path / "x.svg")]) == 2
    assert "--out must name a .png file, got" in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists()


@pytest.fixture
def dmp_evaluation_files(tmp_path, monkeypatch, capsys):
    """results/eval_show.json and .md as `rlfd evaluate` writes them: the DMP on two
    peg_easy starts, in a scratch working directory."""
    monkeypatch.chdir(tmp_path)
    argv = ["evaluate", "--task", "peg_easy", "--policy", "dmp", "--episodes", "2"]
    assert main([*argv, "--seed", "0", "--workers", "1", "--name", "eval_show"]) == 0
    capsys.readouterr()
    return tmp_path / "results" / "eval_show.json", tmp_path / "results" / "eval_show.md"


def test_show_prints_what_evaluate_wrote_beside_the_json(dmp_evaluation_files, capsys):
    """rlfd show: git tracks each evaluation's JSON, not its Markdown rendering
    (results/eval_*.md is ignored), so show must make the same text again from the
    JSON and its per-start table, and name a file it cannot read."""
    json_path, md_path = dmp_evaluation_files
    assert main(["show", str(json_path)]) == 0
    assert capsys.readouterr().out == md_path.read_text()
    assert main(["show", str(json_path), str(json_path)]) == 0
    assert capsys.readouterr().out == md_path.read_text() + "\n" + md_path.read_text()
    table = Path(__file__).resolve().parents[1] / "results" / "table_1.json"
    for path, message in (
        (table, "is not an evaluation JSON"),
        (json_path.with_name("none.json"), "results: no evaluation file at"),
    ):
        assert main(["show", str(json_path), str(path)]) == 2
        captured = capsys.readouterr()
        assert message in captured.err and str(path) in captured.err
        assert captured.out == ""  # nothing printed before the bad file was found


def test_bench_tasks_only_for_the_diagram_benchmark(capsys):
    assert main(["bench", "sim", "--tasks", "peg"]) == 2
    assert "--tasks: only the diagram benchmark takes tasks, not 'sim'" in capsys.readouterr().err
    assert main(["bench", "dmp", "--queue-episodes", "5"]) == 2
    assert "only the train-queue benchmark takes them, not 'dmp'" in capsys.readouterr().err
    assert main(["bench", "evaluate"]) == 2
    assert "--against REV: the evaluate benchmark needs it" in capsys.readouterr().err
    assert main(["bench", "sim", "--against", "HEAD"]) == 2
    assert "got 'HEAD' for 'sim'" in capsys.readouterr().err
    assert main(["bench", "sim", "--cell", "peg", "dmp"]) == 2
    assert "--cell/--starts: only the evaluate benchmark takes them, not 'sim'" in (
        capsys.readouterr().err
    )
    assert main(["bench", "evaluate", "--against", "HEAD", "--cell", "peg"]) == 2
    assert "--cell takes TASK POLICY [MODE], got 'peg'" in capsys.readouterr().err


def test_bench_evaluate_names_runs_by_their_folder_and_stays_a_file_name():
    from rlfd_drake.cli import _BENCH_NAME_MAX, bench_evaluate_name

    commit = "0123456789abcdef"
    assert bench_evaluate_name(commit, None) == "bench_evaluate_vs_0123456"
    cells = [("peg", "runs/peg_ppo_s0/policy.zip", "full"), ("gear", "dmp", "full")]
    assert (
        bench_evaluate_name(commit, cells) == "bench_evaluate_vs_0123456_peg_peg_ppo_s0__gear_dmp"
    )
    many = [
        ("peg", f"runs/peg_ppo_std2_so_tt_e700_s{seed}/policy.zip", "full") for seed in range(9)
    ]
    long_name = bench_evaluate_name(commit, many)
    assert len(long_name) == _BENCH_NAME_MAX
    assert long_name.startswith("bench_evaluate_vs_0123456_peg_peg_ppo_std2_so_tt_e700_s0__")
    assert long_name != bench_evaluate_name(commit, many[:8])  # the hash tells sets apart


def test_train_flags_reach_the_training_configuration(monkeypatch, capsys):
    """`rlfd train`'s exploration and PPO rollout flags land in the TrainConfig it
    trains, and a bad one is a named error (exit 2), not a crash."""
    import rlfd_drake.train as train_module

    seen = {}

    def record(config, out, **_):
        seen["c"] = config
        return {}

    monkeypatch.setattr(train_module, "train", record)
    ppo = ["train", "--task", "peg_easy", "--algo", "ppo", "--log-std-init", "-4"]
    recurrent = ["train", "--task", "peg_easy", "--algo", "recurrent_ppo"]
    sac = ["train", "--task", "peg_easy", "--algo", "sac"]
    assert main([*ppo, "--out", "unused"]) == 0  # the defaults live in TrainConfig
    defaults = seen["c"]
    assert (defaults.ppo_n_steps, defaults.ppo_gae_lambda, defaults.ppo_epochs) == (256, 0.95, 10)
    assert defaults.log_std_final is None and defaults.log_std_init == -4.0
    assert defaults.ppo_hidden_layers == (64, 64) and defaults.self_imitation_batches == 0
    assert defaults.ppo_actor_layers is None
    accepted = [
        (ppo, ["--ppo-sde-sample-steps", "20"], "ppo_sde_sample_steps", 20),
        (ppo, ["--ppo-history", "4"], "ppo_history", 4),
        (ppo, ["--ppo-n-steps", "512"], "ppo_n_steps", 512),
        (recurrent, ["--ppo-n-steps", "128"], "ppo_n_steps", 128),
        (ppo, ["--ppo-gae-lambda", "0.99"], "ppo_gae_lambda", 0.99),
        (recurrent, ["--ppo-gae-lambda", "1"], "ppo_gae_lambda", 1.0),
        (ppo, ["--ppo-epochs", "5"], "ppo_epochs", 5),
        (ppo, ["--log-std-final", "-3"], "log_std_final", -3.0),
        (ppo, ["--ppo-hidden-layers", "256", "256"], "ppo_hidden_layers", (256, 256)),
        (recurrent, ["--ppo-hidden-layers", "32"], "ppo_hidden_layers", (32,)),
        (ppo, ["--ppo-actor-layers"], "ppo_actor_layers", ()),
        (recurrent, ["--ppo-actor-layers", "16"], "ppo_actor_layers", (16,)),
        (ppo, ["--self-imitation-batches", "8"], "self_imitation_batches", 8),
        (ppo, ["--mirror-symmetry"], "mirror_symmetry", True),
        (sac, ["--sac-critic-burn-in", "8000"], "sac_critic_burn_in", 8000),
        (ppo, ["--lateral-log-std-init", "-1.5"], "lateral_log_std_init", -1.5),
        (
            [*ppo, "--scaled-observation"],
            ["--hide-observation", "0", "1", "20", "21"],
            "hidden_observation",
            (0, 1, 20, 21),
        ),
    ]
    for command, flags, field, value in accepted:
        assert main([*command, *flags, "--out", "unused"]) == 0, flags
        assert getattr(seen["c"], field) == value, flags
    refused = [
        (
            ppo,
            ["--ppo-sde-sample-steps", "-3"],
            "ppo_sde_sample_steps must be an integer >= 0, got -3",
        ),
        (ppo, ["--ppo-n-steps", "0"], "ppo_n_steps must be >= 1, got 0"),
        (sac, ["--ppo-n-steps", "512"], "ppo_n_steps=512 needs algo 'ppo', got 'sac'"),
        (ppo, ["--ppo-gae-lambda", "1.5"], "ppo_gae_lambda must be in (0, 1], got 1.5"),
        (sac, ["--ppo-gae-lambda", "0.99"], "ppo_gae_lambda=0.99 needs algo 'ppo', got 'sac'"),
        (ppo, ["--ppo-epochs", "0"], "ppo_epochs must be >= 1, got 0"),
        (sac, ["--ppo-epochs", "5"], "ppo_epochs=5 needs algo 'ppo', got 'sac'"),
        (
            sac,
            ["--log-std-final", "-3"],
            "log_std_final=-3.0 needs algo 'ppo' or 'recurrent_ppo', got 'sac'",
        ),
        (
            ppo,
            ["--ppo-sde-sample-steps", "20", "--log-std-final", "-3"],
            "cannot schedule gSDE's noise (ppo_sde_sample_steps=20)",
        ),
        (ppo, ["--ppo-history", "0"], "ppo_history must be >= 1, got 0"),
        (
            sac,
            ["--lateral-log-std-init", "-1.5"],
            "lateral_log_std_init=-1.5 cannot go with algo 'sac' (needs 'ppo')",
        ),
        (
            ppo,
            ["--lateral-log-std-init", "-1.5", "--residual-mode", "orientation"],
            "lateral_log_std_init=-1.5 cannot go with residual_mode 'orientation'",
        ),
        (
            ppo,
            ["--lateral-log-std-init", "-1.5", "--log-std-final", "-3"],
            "lateral_log_std_init=-1.5 cannot go with log_std_final -3.0",
        ),
        (
            ppo,
            ["--lateral-log-std-init", "-1.5", "--ppo-sde-sample-steps", "20"],
            "lateral_log_std_init=-1.5 cannot go with ppo_sde_sample_steps 20",
        ),
        (ppo, ["--lateral-log-std-init", "nan"], "lateral_log_std_init must be finite, got nan"),
        (
            ppo,
            ["--ppo-hidden-layers", "64", "0"],
            "ppo_hidden_layers must be one or more integer widths >= 1, got (64, 0)",
        ),
        (
            sac,
            ["--ppo-hidden-layers", "256", "256"],
            "ppo_hidden_layers=(256, 256) needs algo 'ppo', got 'sac'",
        ),
        (sac, ["--ppo-actor-layers"], "ppo_actor_layers=() needs algo 'ppo', got 'sac'"),
        (
            ppo,
            ["--ppo-actor-layers", "0"],
            "ppo_actor_layers must be zero or more integer widths >= 1, got (0,)",
        ),
        (
            recurrent,
            ["--self-imitation-batches", "4"],
            "self_imitation_batches=4 cannot go with algo 'recurrent_ppo'",
        ),
        (sac, ["--mirror-symmetry"], "mirror_symmetry cannot go with algo 'sac'"),
        (ppo, ["--sac-critic-burn-in", "10"], "sac_critic_burn_in=10 needs algo 'sac'"),
        (ppo, ["--hide-observation", "0"], "hidden_observation=(0,) cannot go with scaled_obs"),
        (
            [*ppo, "--scaled-observation"],
            ["--hide-observation", "26"],
            "hidden observation entries must be distinct integers in [0, 26), got (26,)",
        ),
        (
            ppo,
            ["--mirror-symmetry", "--privileged-critic"],
            "mirror_symmetry cannot go with privileged_critic set",
        ),
    ]
    for command, flags, message in refused:
        assert main([*command, *flags, "--out", "unused"]) == 2, flags
        assert message in capsys.readouterr().err, flags
