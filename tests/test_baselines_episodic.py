"""Episodic baselines on the simulator: returns, DMP parameters, the coupling term,
a training smoke run and its evaluation through the harness."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from rlfd_drake.baselines.episodic import (
    BaselineConfig,
    episode_return,
    load_baseline,
    phase_features,
    train_baseline,
)
from rlfd_drake.diagram import BuildRlfdDiagram, RlfdDiagramConfig, SetEpisodeStart
from rlfd_drake.episode import EpisodeResult, demo_start_pose, load_task_dmp
from rlfd_drake.evaluate import evaluate
from rlfd_drake.tasks import load_task


def _result(success: bool, insertion_time_s: float) -> EpisodeResult:
    return EpisodeResult(
        success=success,
        insertion_time_s=insertion_time_s,
        final_distance_m=0.0,
        final_angle_deg=0.0,
        peak_force_n=1.0,
        mean_force_n=1.0,
        peak_joint_contact_torque_nm=0.0,
        peak_low_passed_force_n=1.0,
        force_limit_broken=False,
        failure_reason=None if success else "missed: test",
        sim_time_s=10.0,
        wall_time_s=1.0,
        bin_index=-1,
    )


def test_episode_return_is_the_normalised_time_inserted(peg_easy):
    assert episode_return(_result(True, 6.0), peg_easy) == pytest.approx(0.4)
    assert episode_return(_result(False, math.nan), peg_easy) == 0.0
    # An earlier insertion earns more.
    assert episode_return(_result(True, 5.5), peg_easy) > episode_return(
        _result(True, 9.0), peg_easy
    )


def test_phase_features_are_a_normalised_basis_plus_bias():
    for phase in (0.0, 0.3, 1.0):
        phi = phase_features(phase, 6)
        assert phi.shape == (7,)
        assert phi[:6].sum() == pytest.approx(1.0)
        assert phi[6] == 1.0
    # The basis peaks where the phase is.
    assert np.argmax(phase_features(1.0, 6)[:6]) == 5
    assert np.argmax(phase_features(0.0, 6)[:6]) == 0


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("method", "cma", "method"),
        ("task", "nope", "task"),
        ("episodes", 0, "episodes"),
        ("enac_sigma", -1.0, "enac_sigma"),
        ("residual_mode", "off", "residual_mode"),
    ],
)
def test_baseline_config_rejects_bad_values(field, value, match):
    with pytest.raises(ValueError, match=match):
        BaselineConfig(**{field: value})


def test_unit_coupling_moves_the_dmp_rest_point_by_the_residual_bound(peg_easy, dmp):
    """C_t = alpha_z beta_z * max_translation_m on x shifts the DMP's end point by that much
    along x."""
    config = RlfdDiagramConfig(log_period_s=None)
    ends = {}
    for label, action in (("zero", np.zeros(6)), ("unit_x", np.array([1.0, 0, 0, 0, 0, 0]))):
        rlfd = BuildRlfdDiagram(
            peg_easy, dmp, config, coupling_policy=lambda obs, a=action: a.copy()
        )
        simulator = Simulator(rlfd.diagram)
        context = simulator.get_mutable_context()
        rlfd.diagram.GetInputPort("residual").FixValue(context, np.zeros(6))
        SetEpisodeStart(rlfd, context, demo_start_pose(dmp))
        simulator.Initialize()
        simulator.AdvanceTo(peg_easy.episode_time_s)
        ends[label] = rlfd.dmp.GetOutputPort("X_WE_desired").Eval(
            rlfd.dmp.GetMyContextFromRoot(context)
        )[:3]
    shift = ends["unit_x"] - ends["zero"]
    bound = config.residual_bounds(peg_easy)[0]
    np.testing.assert_allclose(shift, [bound, 0.0, 0.0], atol=1e-3)


def test_linear_baseline_trains_saves_and_evaluates(tmp_path, peg_easy, dmp):
    out = tmp_path / "linear"
    config = BaselineConfig(task="peg_easy", method="linear", episodes=2, workers=2, seed=3)
    metrics = train_baseline(config, out, progress=False)
    assert metrics["episodes"] == 2
    saved = json.loads((out / "config.json").read_text())
    assert saved["config"]["method"] == "linear" and "command" in saved
    rows = (out / "episodes.csv").read_text().splitlines()
    assert len(rows) == 3  # header + 2 episodes
    kit = load_baseline(out / "baseline.npz", peg_easy, dmp)
    assert kit.coupling_policy is None and kit.dmp is dmp
    assert kit.policy.deterministic
    # A rewarded episode moved theta off zero; an unrewarded pair leaves it at zero.
    if metrics["training_success_mean"] > 0:
        assert np.abs(kit.policy.theta).max() > 0
    with pytest.raises(FileExistsError, match="already holds"):
        train_baseline(config, out, progress=False)
    result = evaluate("peg_easy", str(out / "baseline.npz"), 1, 0, workers=1, progress=False)
    assert result["episodes"] == 1 and 0.0 <= result["success_rate"] <= 1.0


def test_weight_search_baseline_replaces_the_dmp(tmp_path, peg_easy, dmp):
    out = tmp_path / "power"
    config = BaselineConfig(task="peg_easy", method="power", episodes=2, workers=2, seed=0)
    train_baseline(config, out, progress=False)
    kit = load_baseline(out / "baseline.npz", peg_easy, dmp)
    assert kit.policy is None and kit.coupling_policy is None
    assert kit.dmp.weights_translation.shape == dmp.weights_translation.shape
    # Trained on easy, evaluated on hard: the learnt weights drive the hard task's DMP.
    hard = load_task("peg_hard")
    hard_dmp = load_task_dmp(hard)
    on_hard = load_baseline(out / "baseline.npz", hard, hard_dmp)
    np.testing.assert_array_equal(on_hard.dmp.weights_translation, kit.dmp.weights_translation)
    np.testing.assert_array_equal(on_hard.dmp.g, hard_dmp.g)
    with pytest.raises(ValueError, match="not a baseline file"):
        np.savez(tmp_path / "other.npz", theta=np.zeros(3))
        load_baseline(tmp_path / "other.npz", peg_easy, dmp)
