"""The hand-written force-guided search (a reference, not a paper baseline)."""

from __future__ import annotations

import numpy as np
import pytest

from rlfd_drake.baselines.force_guided import ForceGuidedSearch
from rlfd_drake.env import RlfdEnv
from rlfd_drake.evaluate import make_policy
from rlfd_drake.systems.observer import (
    OBSERVATION_SIZE,
    OBSERVATION_WRIST_FORCE,
    OBSERVATION_WRIST_TORQUE,
    ObserverConfig,
)


def _observation(force_n, torque_nm) -> np.ndarray:
    units = ObserverConfig()
    obs = np.zeros(OBSERVATION_SIZE)
    obs[OBSERVATION_WRIST_FORCE] = np.asarray(force_n) / units.force_scale_N
    obs[OBSERVATION_WRIST_TORQUE] = np.asarray(torque_nm) / units.torque_scale_Nm
    return obs


def test_free_motion_gives_no_correction():
    # The part hanging from the hand: its weight pulls the wrist down (F_z > 0 here).
    np.testing.assert_array_equal(ForceGuidedSearch()(_observation([0, 0, 1.5], [0, 0, 0])), 0.0)


def test_in_contact_it_lifts_and_moves_away_from_the_centre_of_pressure():
    search = ForceGuidedSearch()
    # 80 N down with its centre of pressure 10 mm toward -x of the wrist:
    # tau = r x F = (r_y F_z, -r_x F_z, 0) = (0, -0.8, 0).
    r, f_z = np.array([-0.01, 0.0, -0.1]), -80.0
    torque = np.cross(r, [0.0, 0.0, f_z])
    action = search(_observation([0, 0, f_z], torque))
    np.testing.assert_allclose(action, [1.0, 0.0, 1.0, 0, 0, 0], atol=1e-12)
    # Centred (no lateral torque): lift only.
    np.testing.assert_allclose(search(_observation([0, 0, -80], [0, 0, 0])), [0, 0, 1, 0, 0, 0])


def test_its_mirror_image_moves_toward_the_centre_of_pressure():
    """A hole going onto a shaft rests on the shaft where they overlap: the shaft is on
    the centre of pressure's side, so the mirror search pushes that way."""
    r, f_z = np.array([-0.01, 0.02, -0.1]), -80.0
    pressed = _observation([0, 0, f_z], np.cross(r, [0.0, 0.0, f_z]))
    away = ForceGuidedSearch()(pressed)
    toward = make_policy("force_search_toward")(pressed)
    np.testing.assert_allclose(away[:2], -r[:2] / np.linalg.norm(r[:2]), atol=1e-12)
    np.testing.assert_allclose(toward, [-away[0], -away[1], 1.0, 0, 0, 0], atol=1e-12)
    assert "toward_pressure=True" in repr(make_policy("force_search_toward"))


def test_bad_settings_are_named():
    with pytest.raises(ValueError, match="contact_force_n must be a positive number, got -1"):
        ForceGuidedSearch(contact_force_n=-1.0)
    with pytest.raises(ValueError, match=r"push must be in \[0, 1\], got 2"):
        ForceGuidedSearch(push=2.0)


def test_it_finds_a_hole_the_dmp_misses():
    """3.5 mm of unseen fixture error: the DMP rests the peg on the entrance, held by
    friction (80 N down); the rule slides it in."""
    env = RlfdEnv("peg_easy", residual_mode="translation")
    options = dict(
        start_dp=np.zeros(3),
        fixture_dp=np.array([0.0035, 0.0, 0.0]),
        fixture_dq=np.array([1.0, 0.0, 0.0, 0.0]),
    )
    outcomes = {}
    for name, policy in (("dmp", lambda obs: np.zeros(6)), ("search", make_policy("force_search"))):
        obs, _ = env.reset(seed=1, options=options)
        for _ in range(50):
            obs, _, terminated, truncated, info = env.step(policy(obs).astype(np.float32))
            if terminated or truncated:
                break
        outcomes[name] = bool(info["success"])
    assert outcomes == {"dmp": False, "search": True}
