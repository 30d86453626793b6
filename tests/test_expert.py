"""The scripted expert: smooth, seeded, and it really inserts the part."""

from __future__ import annotations

import numpy as np
import pytest

from rlfd_drake.demonstration import load_demonstration
from rlfd_drake.diagram import NominalGoal
from rlfd_drake.expert import ExpertConfig, expert_path, minimum_jerk, record_demonstration
from rlfd_drake.tasks import load_task


def test_minimum_jerk_profile_endpoints_and_slope():
    value, slope = minimum_jerk(np.array([0.0, 0.5, 1.0]))
    np.testing.assert_allclose(value, [0.0, 0.5, 1.0])
    np.testing.assert_allclose(slope[[0, 2]], 0.0)
    assert slope[1] == 1.875


def test_expert_path_is_seeded_and_velocities_match_positions():
    task = load_task("peg")
    goal = NominalGoal(task)
    a = expert_path(goal, task.fixture.depth_m, ExpertConfig(), np.random.default_rng(3))
    b = expert_path(goal, task.fixture.depth_m, ExpertConfig(), np.random.default_rng(3))
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    times, positions, quats, twists = a
    numeric = np.gradient(positions, times, axis=0)
    assert np.max(np.abs(numeric - twists[:, 3:])) < 2e-3  # m/s, finite-difference error
    np.testing.assert_allclose(np.linalg.norm(quats, axis=1), 1.0, atol=1e-12)


def test_recorded_demo_inserts_and_matches_the_committed_one():
    task = load_task("peg_easy")
    demo = record_demonstration(task, seed=0)
    assert np.linalg.norm(demo.positions[-1] - NominalGoal(task).translation()) < task.kappa_m
    committed = load_demonstration(task.demo_path())
    np.testing.assert_allclose(demo.positions, committed.positions, atol=1e-6)


def test_a_longer_insert_phase_descends_proportionally_slower():
    task = load_task("rj45")
    goal = NominalGoal(task)
    speeds = []
    for insert_s in (2.6, 5.2):
        config = ExpertConfig(insert_s=insert_s, timing_variation=0.0)
        times, _, _, twists = expert_path(
            goal, task.fixture.depth_m, config, np.random.default_rng(0)
        )
        descent = times > config.approach_s + config.pause_s
        speeds.append(np.max(np.abs(twists[descent, 5])))
    assert speeds[1] == pytest.approx(speeds[0] / 2.0, rel=1e-3)


@pytest.mark.parametrize(
    "field, value",
    [
        ("insert_s", 0.0),
        ("approach_s", -1.0),
        ("record_period_s", float("nan")),
        ("push_depth_m", -0.001),
        ("variation_m", float("inf")),
    ],
)
def test_bad_expert_config_names_the_field(field, value):
    with pytest.raises(ValueError, match=rf"^{field}: .*{value!r}"):
        ExpertConfig(**{field: value})
