"""Constant rotations that undo the table slope or the whole fixture rotation."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from rlfd_drake.baselines.orientation_reference import (
    ConstantRotationResidual,
    fixture_rotation_residual,
    slope_residual,
)
from rlfd_drake.evaluate import make_policy
from rlfd_drake.geometry import quat_from_angle_axis
from rlfd_drake.tasks import PoseSpec, load_task

OBS = np.zeros(26)


def test_the_slope_residual_undoes_the_tables_constant_tilt():
    task = load_task("rj45")  # 1 deg about y, a residual of 1 turns 0.052 rad
    action = slope_residual(task)(OBS)
    np.testing.assert_allclose(action[:3], 0.0)
    np.testing.assert_allclose(action[3:], [0.0, np.radians(1.0) / 0.052, 0.0], atol=1e-12)


def test_the_oracle_turns_the_fixtures_error_into_world_axes():
    # A fixture yawed 90 deg about world z: its x axis is the world's y.
    task = replace(load_task("rj45"), X_WFixture=PoseSpec((0.5, 0.0, 0.15), (0.0, 0.0, 90.0)))
    dq = quat_from_angle_axis(np.radians(2.0), np.array([1.0, 0.0, 0.0]))
    action = fixture_rotation_residual(task, dq)(OBS)
    np.testing.assert_allclose(action[3:], [0.0, np.radians(2.0) / 0.052, 0.0], atol=1e-9)
    big = fixture_rotation_residual(task, quat_from_angle_axis(0.2, np.array([0.0, 0.0, 1.0])))
    assert big.clipped and big(OBS)[5] == 1.0


def test_bad_input_is_refused_by_name():
    task = load_task("rj45")
    with pytest.raises(ValueError, match="fixture_dq must be a unit quaternion"):
        fixture_rotation_residual(task, [1.0, 1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="rotation_vector_rad"):
        ConstantRotationResidual([0.0, np.nan, 0.0], 0.05)
    with pytest.raises(ValueError, match="max_rotation_rad"):
        ConstantRotationResidual([0.0, 0.0, 0.0], 0.0)
    with pytest.raises(ValueError, match="fixture_oracle needs the episode's fixture error"):
        make_policy("fixture_oracle", "orientation", task=task)
    with pytest.raises(ValueError, match="needs the task"):
        make_policy("slope", "orientation")


def test_on_rj45_the_rotation_is_what_the_search_misses():
    """A start whose socket is 2.3 deg off (slope included): the force-guided search
    breaks the plug, the same search with the fixture's rotation undone inserts it."""
    from rlfd_drake.episode import load_task_dmp, make_episode_specs, run_episode

    task = load_task("models/tasks/variants/rj45_slow_insert.yaml")
    spec = make_episode_specs(task, 160, 0, grid=True)[12]
    assert spec.fixture_rotation_error_deg > 2.0
    dmp = load_task_dmp(task)
    alone = run_episode(task, dmp, spec, policy=make_policy("force_search", task=task))
    both = make_policy("force_search|fixture_oracle", task=task, fixture_dq=spec.fixture_dq)
    oracle = run_episode(task, dmp, spec, policy=both)
    assert not alone.success and alone.failure_kind == "force_limit"
    assert oracle.success
