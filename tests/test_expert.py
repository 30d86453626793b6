"""The scripted expert: smooth, seeded, and it really inserts the part."""

from __future__ import annotations

import numpy as np

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
