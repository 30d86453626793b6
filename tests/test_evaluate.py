"""The evaluation harness and the random baseline."""

from __future__ import annotations

import json
import re

import gymnasium as gym
import numpy as np
import pytest

from rlfd_drake.baselines.random_policy import RandomResidualPolicy, ZeroPolicy
from rlfd_drake.episode import make_episode_specs
from rlfd_drake.evaluate import (
    RESULT_KEYS,
    _success_curve,
    evaluate,
    evaluation_markdown,
    fixture_direction_deg,
    make_policy,
    result_from_json,
    shared_evaluation_workers,
    success_by_fixture_error,
    write_evaluation,
)
from rlfd_drake.policies import (
    DeployedPolicy,
    _sb3_kind_from_zip,
    check_residual_mode,
    load_sb3_model,
)
from rlfd_drake.systems.observer import OBSERVATION_SIZE
from rlfd_drake.tasks import load_task


@pytest.fixture(scope="module")
def dmp_result() -> dict:
    return evaluate("peg_easy", "dmp", episodes=4, seed=0, workers=1, progress=False)


def test_evaluate_returns_the_documented_keys(dmp_result):
    r = dmp_result
    assert set(RESULT_KEYS) <= set(r)
    assert r["episodes"] == 4 and r["task"] == "peg_easy" and r["policy"] == "dmp"
    assert r["policy_sha256"] is None  # no file
    assert 0.0 <= r["success_rate"] <= 1.0
    assert r["success_std_kind"].startswith("binomial")  # the uniform box has one bin
    p = r["success_rate"]
    assert r["success_std"] == pytest.approx(np.sqrt(p * (1 - p) / 4))
    assert len(r["per_bin"]) == 1 and r["per_bin"][0]["n"] == 4
    # Uniform +-12 cm box: the mean offset norm is about 12 cm; no rotation.
    assert 0.02 < r["per_bin"][0]["position_offset_m"] < 0.21
    assert r["per_bin"][0]["rotation_offset_deg"] == 0.0
    n_success = sum(r["episode_table"]["success"])
    assert sum(r["failures"].values()) == 4 - n_success
    if n_success:
        assert 0.0 < r["insertion_time_s"] < 10.0
    assert r["peak_force_n"] >= r["mean_force_n"] >= 0.0
    # The insertion touches the fixture: the arm's joints feel the contact.
    assert r["peak_joint_contact_torque_nm"] > 0.0
    torques = r["episode_table"]["peak_joint_contact_torque_nm"]
    assert np.mean(torques) == pytest.approx(r["peak_joint_contact_torque_nm"], abs=0.01)
    # Low-passing can only lower a peak.
    assert 0.0 < r["peak_low_passed_force_n"] <= r["peak_force_n"]
    # Each episode dates its peak, within the simulated time, at a distance to the goal.
    table = r["episode_table"]
    specs = make_episode_specs(load_task("peg_easy"), 4, 0, grid=True)
    assert table["fixture_error_direction_deg"] == [
        round(fixture_direction_deg(s.fixture_dp), 1) for s in specs
    ]
    for when, distance in zip(
        table["peak_force_time_s"], table["peak_force_distance_mm"], strict=True
    ):
        assert 0.0 <= when <= 10.0 and 0.0 <= distance < 400.0
    assert r["wall_time_s"] > 0.0
    json.dumps(r)  # JSON-serialisable as is


def test_evaluate_is_the_same_in_worker_processes(dmp_result):
    """Two spawned workers reproduce the first two episodes of the in-process run."""
    r = evaluate("peg_easy", "dmp", episodes=2, seed=0, workers=2, progress=False)
    for key in ("success", "insertion_time_s", "final_distance_mm", "failure"):
        assert r["episode_table"][key] == dmp_result["episode_table"][key][:2]


def test_evaluations_share_one_pool_of_workers_inside_the_block(dmp_result):
    """Inside shared_evaluation_workers two evaluations of different policies run in one
    pool (spawned once), each episode as in a pool of its own and as in-process."""
    import rlfd_drake.evaluate as evaluate_module

    with shared_evaluation_workers(2):
        pool = evaluate_module._SHARED_POOL["pool"]
        with shared_evaluation_workers(2):  # nested: the same pool
            assert evaluate_module._SHARED_POOL["pool"] is pool
        first = evaluate("peg_easy", "dmp", episodes=2, seed=0, workers=2, progress=False)
        second = evaluate("peg_easy", "random", episodes=2, seed=0, workers=2, progress=False)
        assert evaluate_module._SHARED_POOL["pool"] is pool
    assert evaluate_module._SHARED_POOL == {}
    alone = evaluate("peg_easy", "random", episodes=2, seed=0, workers=2, progress=False)
    for key in ("success", "insertion_time_s", "final_distance_mm", "peak_force_n"):
        assert first["episode_table"][key] == dmp_result["episode_table"][key][:2]
        assert second["episode_table"][key] == alone["episode_table"][key]
    with pytest.raises(ValueError, match="workers must be an integer >= 1, got 0"):
        with shared_evaluation_workers(0):
            pass


def test_a_policy_file_saved_again_at_its_path_is_loaded_again(tmp_path):
    """The per-process model cache follows the file: a run retrained at the same path
    (a long-lived worker) acts with the new policy, not the one read first."""
    from stable_baselines3 import PPO

    path = tmp_path / "policy.zip"
    obs = np.linspace(-1, 1, OBSERVATION_SIZE).astype(np.float32)
    actions = []
    for seed in (0, 1):
        PPO("MlpPolicy", _ResidualEnv(), device="cpu", seed=seed).save(path)
        policy = make_policy(str(path))
        policy.reset()
        actions.append(policy(obs))
    assert not np.allclose(actions[0], actions[1])
    PPO("MlpPolicy", _ResidualEnv(), device="cpu", seed=0).save(path)
    policy = make_policy(str(path))
    policy.reset()
    np.testing.assert_allclose(policy(obs), actions[0], atol=1e-6)


def test_write_evaluation(dmp_result, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    paths = write_evaluation(dmp_result, "eval_test", command="rlfd evaluate test")
    record = json.loads(paths["json"].read_text())
    assert record["command"] == "rlfd evaluate test" and record["seed"] == 0
    assert record["data"]["success_rate"] == dmp_result["success_rate"]
    markdown = paths["md"].read_text()
    assert "| task | policy | success % |" in markdown and "peg_easy" in markdown
    assert "| unseen fixture error mm | n | success % |" in markdown
    assert "| peak force felt | n | mean peak N | median time s |" in markdown
    # Evaluations stored before episodes dated their peaks still render, without it.
    old = {**dmp_result, "episode_table": dict(dmp_result["episode_table"])}
    del old["episode_table"]["peak_force_time_s"], old["episode_table"]["peak_force_distance_mm"]
    assert "peak force felt" not in evaluation_markdown(old)
    assert set(paths) == {"json", "episodes", "md"}  # no plot unless asked
    # The per-episode table lives compressed beside the JSON, and reads back joined.
    assert "episode_table" not in record["data"]
    assert paths["episodes"].name == "eval_test.episodes.json.gz"
    assert result_from_json(paths["json"]) == json.loads(json.dumps(dmp_result))
    # An evaluation stored with its table inside the JSON (before it had its own file)
    # still reads back whole, and a missing table file is named in a ValueError.
    record["data"]["episode_table"] = dmp_result["episode_table"]
    del record["data"]["episode_table_file"]
    old_layout = tmp_path / "results" / "eval_old.json"
    old_layout.write_text(json.dumps(record))
    assert result_from_json(old_layout) == json.loads(json.dumps(dmp_result))
    paths["episodes"].unlink()
    with pytest.raises(ValueError, match="eval_test.episodes.json.gz"):
        result_from_json(paths["json"])
    assert not (tmp_path / "results" / "eval_test.png").exists()
    paths = write_evaluation(dmp_result, "eval_test", command="rlfd evaluate test", plot=True)
    assert paths["png"].read_bytes()[:4] == b"\x89PNG"
    assert all(p.stat().st_size < 100_000 for p in paths.values())
    from PIL import Image

    with Image.open(paths["png"]) as plot:  # a palette image: results/ stays small
        assert plot.mode == "P" and plot.size == (500, 340)


def test_force_figure_draws_old_evaluations_and_refuses_empty_panels(dmp_result, tmp_path):
    """An evaluation stored before the low-passed peak existed draws its one-step bar
    only; a panel without evaluations is refused with the panel named."""
    from rlfd_drake.evaluate import plot_peak_forces

    old = {k: v for k, v in dmp_result.items() if k != "peak_low_passed_force_n"}
    path = plot_peak_forces({"easy": [("new", dmp_result), ("old", old)]}, tmp_path / "f.png")
    assert path.read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(ValueError, match=re.escape("got {'easy': 1, 'hard': 0}")):
        plot_peak_forces({"easy": [("new", dmp_result)], "hard": []}, tmp_path / "g.png")


def test_success_curve_of_binned_results():
    result = {
        "per_bin": [
            {
                "bin": b,
                "n": 20,
                "success_rate": 1.0 - 0.1 * b,
                "position_offset_m": 0.01,
                "rotation_offset_deg": 2.5 + 5 * b,
            }
            for b in range(8)
        ]
    }
    x, p, std, n, label = _success_curve(result)
    np.testing.assert_allclose(x, 2.5 + 5 * np.arange(8))
    np.testing.assert_allclose(p, 1.0 - 0.1 * np.arange(8))
    np.testing.assert_allclose(std, np.sqrt(p * (1 - p) / 20))
    assert "rotation" in label and list(n) == [20] * 8


def test_success_by_fixture_error_groups_the_episodes():
    result = {
        "episode_table": {
            "fixture_error_mm": [0.5, 0.9, 1.5, 2.5, 2.9, 4.0],
            "success": [1, 1, 0, 1, 0, 0],
        }
    }
    groups = success_by_fixture_error(result)
    assert [(g["from_mm"], g["n"], g["success_rate"]) for g in groups] == [
        (0.0, 2, 1.0),
        (1.0, 1, 0.0),
        (2.0, 2, 0.5),
        (3.0, 1, 0.0),
    ]
    assert len(success_by_fixture_error(result, (0.0, 1.0))) == 1  # the rest left out
    with pytest.raises(ValueError, match="edges_mm"):
        success_by_fixture_error(result, (0.0, 2.0, 1.0))


def test_random_policy_masks_and_seed():
    obs = np.zeros(OBSERVATION_SIZE, dtype=np.float32)
    full = RandomResidualPolicy(seed=5)
    actions = np.array([full(obs) for _ in range(200)])
    assert actions.shape == (200, 6)
    assert np.all(np.abs(actions) <= 1.0) and np.all(np.abs(actions).max(axis=0) > 0.9)
    assert abs(actions.mean()) < 0.1  # uniform in [-1, 1]
    again = RandomResidualPolicy(seed=5)
    np.testing.assert_array_equal(np.array([again(obs) for _ in range(200)]), actions)
    assert not np.array_equal(RandomResidualPolicy(seed=6)(obs), actions[0])

    translation = np.array([RandomResidualPolicy(1, orientation=False)(obs) for _ in range(50)])
    assert np.all(translation[:, 3:] == 0.0) and np.all(translation[:, :3] != 0.0)
    orientation = np.array([RandomResidualPolicy(1, translation=False)(obs) for _ in range(50)])
    assert np.all(orientation[:, :3] == 0.0) and np.all(orientation[:, 3:] != 0.0)
    assert np.all(ZeroPolicy()(obs) == 0.0)


def test_make_policy_from_spec_strings():
    assert make_policy("dmp") is None
    policy = make_policy("random", residual_mode="translation", episode_seed=7)
    assert isinstance(policy, RandomResidualPolicy)
    assert policy.translation and not policy.orientation and policy.seed == 7
    with pytest.raises(ValueError, match="does not exist"):
        make_policy("/nonexistent/model.zip")


@pytest.mark.parametrize("spec", ["force_search_towards", "force_search|slop"])
def test_an_unknown_policy_name_is_refused_before_any_episode(spec):
    with pytest.raises(ValueError, match=r"is neither a named policy \(dmp, random, force_search"):
        evaluate("gear", spec, episodes=2, seed=0, workers=2, progress=False)


@pytest.mark.parametrize("spec", ["{missing}", "{missing}+{missing}", "dmp|{missing}"])
def test_a_missing_policy_file_is_refused_before_any_episode(tmp_path, spec):
    spec = spec.format(missing=tmp_path / "none.zip")
    with pytest.raises(ValueError, match=r"policy file '.*none\.zip' does not exist"):
        evaluate("gear", spec, episodes=2, seed=0, workers=2, progress=False)


class _ResidualEnv(gym.Env):
    """Spaces of the residual: observation (26,), action (6,) in [-1, 1]."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (OBSERVATION_SIZE,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (6,), np.float32)

    def reset(self, *, seed=None, options=None):
        return np.zeros(OBSERVATION_SIZE, np.float32), {}

    def step(self, action):
        return np.zeros(OBSERVATION_SIZE, np.float32), 0.0, True, False, {}


@pytest.mark.parametrize(
    ("module", "name", "kind"),
    [
        ("stable_baselines3", "PPO", "ppo"),
        ("stable_baselines3", "SAC", "sac"),
        ("sb3_contrib", "RecurrentPPO", "recurrent_ppo"),
    ],
)
def test_saved_sb3_models_become_residual_policies(module, name, kind, tmp_path):
    import importlib

    cls = getattr(importlib.import_module(module), name)
    policy_name = "MlpLstmPolicy" if kind == "recurrent_ppo" else "MlpPolicy"
    model = cls(policy_name, _ResidualEnv(), device="cpu", seed=0)
    path = tmp_path / f"{kind}.zip"
    model.save(path)
    assert _sb3_kind_from_zip(path) == kind
    loaded, loaded_kind = load_sb3_model(str(path))
    assert loaded_kind == kind and type(loaded).__name__ == name
    policy = make_policy(str(path))
    assert isinstance(policy, DeployedPolicy)
    obs = np.linspace(-1, 1, OBSERVATION_SIZE).astype(np.float32)
    policy.reset()
    first = policy(obs)
    assert first.shape == (6,) and np.all(np.isfinite(first)) and np.all(np.abs(first) <= 1.0)
    policy.reset()
    np.testing.assert_allclose(policy(obs), first)  # deterministic after a reset


def test_a_process_keeps_only_its_most_recently_used_models(tmp_path, monkeypatch):
    """A worker of rlfd reproduce meets some sixty policy files: it keeps the
    ``_MODEL_CACHE_SIZE`` it used last, not every model it ever loaded."""
    import stable_baselines3

    import rlfd_drake.evaluate as evaluate_module

    monkeypatch.setattr(evaluate_module, "_MODEL_CACHE_SIZE", 2)
    monkeypatch.setattr(evaluate_module, "_MODEL_CACHE", evaluate_module.OrderedDict())
    model = stable_baselines3.PPO("MlpPolicy", _ResidualEnv(), device="cpu", seed=0)
    paths = [str(tmp_path / f"{name}.zip") for name in "abc"]
    for path in paths:
        model.save(path)

    def held() -> list[str]:
        return [key[0] for key in evaluate_module._MODEL_CACHE]

    first = make_policy(paths[0]).model
    make_policy(paths[1])
    assert make_policy(paths[0]).model is first  # used again: not read again
    make_policy(paths[2])
    assert held() == [paths[0], paths[2]]  # b, the least recently used, went
    assert make_policy(paths[1]).model is not None and held() == [paths[2], paths[1]]


@pytest.mark.parametrize("name", ["SAC", "PPO"])
def test_noise_scale_scales_the_sampling_spread(name):
    """--noise-scale s samples with s times the policy's standard deviation: a small s
    gives the mean action, 0.5 half the spread of the trained distribution."""
    import stable_baselines3

    model = getattr(stable_baselines3, name)("MlpPolicy", _ResidualEnv(), device="cpu", seed=0)
    if name == "PPO":
        model.policy.log_std.data.fill_(np.log(0.2))
    obs = np.linspace(-0.5, 0.5, OBSERVATION_SIZE).astype(np.float32)
    mean_action = DeployedPolicy(model)(obs)

    def samples(scale: float) -> np.ndarray:
        actions = []
        for seed in range(300):
            policy = DeployedPolicy(model, deterministic=False, seed=seed, noise_scale=scale)
            actions.append(policy(obs))
        return np.array(actions)

    np.testing.assert_allclose(samples(1e-6)[:5], [mean_action] * 5, atol=1e-5)

    # Spread of the Gaussian: SAC's tanh is inverted; PPO's clip to [-1, 1] is rare
    # at the std of 0.2 set here.
    def spread(actions: np.ndarray) -> np.ndarray:
        if name == "SAC":
            actions = np.arctanh(np.clip(actions, -0.999999, 0.999999))
        return actions.std(axis=0)

    half, full = spread(samples(0.5)), spread(samples(1.0))
    np.testing.assert_allclose(half / full, 0.5, rtol=0.15)
    # Reproducible per episode seed.
    again = DeployedPolicy(model, deterministic=False, seed=4, noise_scale=0.5)
    np.testing.assert_array_equal(again(obs), samples(0.5)[4])


def test_noise_scale_is_validated(tmp_path):
    from stable_baselines3 import SAC, TD3

    sac = SAC("MlpPolicy", _ResidualEnv(), device="cpu", seed=0)
    for bad in (0.0, -1.0, float("nan"), "half"):
        with pytest.raises(ValueError, match="noise_scale"):
            DeployedPolicy(sac, deterministic=False, noise_scale=bad)
    td3 = TD3("MlpPolicy", _ResidualEnv(), device="cpu", seed=0)
    with pytest.raises(ValueError, match="noise_scale 0.5 needs a SAC or PPO policy"):
        DeployedPolicy(td3, deterministic=False, noise_scale=0.5)
    with pytest.raises(ValueError, match="needs sampled actions"):
        evaluate("peg_easy", "dmp", episodes=1, seed=0, workers=1, noise_scale=0.5)
    with pytest.raises(ValueError, match="needs a saved policy"):
        evaluate("peg_easy", "random", 1, 0, workers=1, deterministic=False, noise_scale=0.5)
    path = tmp_path / "td3.zip"
    td3.save(path)
    with pytest.raises(ValueError, match="SAC or PPO"):  # before any worker starts
        evaluate("peg_easy", str(path), 1, 0, workers=2, deterministic=False, noise_scale=0.5)


def test_an_ensemble_spec_acts_with_the_mean_of_its_members_mean_actions(tmp_path):
    """ "a.zip+b.zip" runs each saved policy with its own history and averages their mean
    actions; its file stem names both; what cannot be averaged is refused by name."""
    from stable_baselines3 import PPO

    from rlfd_drake.evaluate import policy_stem, trained_mode
    from rlfd_drake.policies import MeanOfPolicies

    paths = []
    for seed in (0, 1):
        run = tmp_path / f"run_s{seed}"
        run.mkdir()
        PPO("MlpPolicy", _ResidualEnv(), device="cpu", seed=seed).save(run / "policy.zip")
        (run / "config.json").write_text(json.dumps({"config": {"residual_mode": "full"}}))
        paths.append(str(run / "policy.zip"))
    spec = "+".join(paths)
    policy = make_policy(spec)
    assert isinstance(policy, MeanOfPolicies)
    obs = np.linspace(-1, 1, OBSERVATION_SIZE).astype(np.float32)
    members = [make_policy(path) for path in paths]
    policy.reset()
    expected = (members[0](obs) + members[1](obs)) / 2
    assert not np.allclose(members[0](obs), members[1](obs))  # two different networks
    np.testing.assert_allclose(policy(obs), expected, atol=1e-7)
    assert policy_stem(spec) == "run_s0_plus_run_s1"
    assert trained_mode(spec) == "full"

    with pytest.raises(ValueError, match="at least 2 policies"):
        MeanOfPolicies([members[0]])
    with pytest.raises(ValueError, match="two or more saved policies"):
        make_policy(f"{paths[0]}+random")
    with pytest.raises(ValueError, match="mean actions"):
        make_policy(spec, deterministic=False)
    with pytest.raises(ValueError, match="mean action only"):  # before any worker starts
        evaluate("peg_easy", spec, 1, 0, workers=2, deterministic=False)
    (tmp_path / "run_s1" / "config.json").write_text(
        json.dumps({"config": {"residual_mode": "translation"}})
    )
    with pytest.raises(ValueError, match="residual modes"):
        make_policy(spec)
    (tmp_path / "run_s1" / "config.json").write_text(
        json.dumps({"config": {"residual_mode": "full", "base_correction": "force_search"}})
    )
    with pytest.raises(ValueError, match="trained on a rule"):
        make_policy(spec)


def test_split_spec_takes_translation_and_orientation_from_different_policies():
    """Table IV's "translation / orientation" rows, e.g. Linear / Random."""
    from rlfd_drake.baselines.split import SplitResidualPolicy

    obs = np.zeros(OBSERVATION_SIZE, np.float32)
    policy = make_policy("dmp|random", episode_seed=3)
    assert isinstance(policy, SplitResidualPolicy) and policy.translation is None
    actions = np.array([policy(obs) for _ in range(20)])
    assert np.all(actions[:, :3] == 0.0) and np.all(actions[:, 3:] != 0.0)
    both = SplitResidualPolicy(lambda o: np.full(6, 0.25), lambda o: np.full(6, -0.5))
    np.testing.assert_array_equal(both(obs), [0.25] * 3 + [-0.5] * 3)
    with pytest.raises(ValueError, match="translation\\|orientation"):
        make_policy("dmp|random|random")
    with pytest.raises(ValueError, match="needs the task"):
        make_policy("runs/x/baseline.npz|random")


def test_a_translation_only_policy_is_refused_in_full_mode(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    policy = run / "policy.zip"
    policy.write_bytes(b"")
    (run / "config.json").write_text(json.dumps({"config": {"residual_mode": "translation"}}))
    with pytest.raises(ValueError, match="trained with residual_mode 'translation'"):
        evaluate("peg_easy", str(policy), 1, 0, workers=1, residual_mode="full")
    with pytest.raises(ValueError, match="orientation"):
        check_residual_mode(policy, "orientation")
    check_residual_mode(policy, "translation")
    check_residual_mode(policy, "off")
    with pytest.raises(ValueError, match="residual_mode must be one of"):
        check_residual_mode(policy, "sideways")
    # Without a run folder's config there is nothing to check against.
    (run / "config.json").unlink()
    check_residual_mode(policy, "full")
