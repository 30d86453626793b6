"""Episodes: specs, DMP-only success, determinism, failures turned into results."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import rlfd_drake.episode as episode_module
from rlfd_drake.baselines.random_policy import ZeroPolicy
from rlfd_drake.diagram import RlfdDiagramConfig
from rlfd_drake.dmp import get_weights, with_weights
from rlfd_drake.episode import (
    FAILURE_KINDS,
    EpisodeResult,
    EpisodeSpec,
    load_task_dmp,
    make_episode_specs,
    run_episode,
)
from rlfd_drake.tasks import load_task


@pytest.fixture(scope="module")
def nominal_result(peg_easy, dmp) -> EpisodeResult:
    """DMP alone from the demonstration start, no fixture error."""
    return run_episode(peg_easy, dmp, EpisodeSpec())


def _comparable(result: EpisodeResult) -> dict:
    """Every field but the wall time, nan written out (nan != nan)."""
    values = dataclasses.asdict(result)
    values.pop("wall_time_s")
    return {k: "nan" if isinstance(v, float) and math.isnan(v) else v for k, v in values.items()}


def test_load_task_dmp_is_cached(peg_easy, dmp):
    assert load_task_dmp(peg_easy) is dmp
    assert dmp.tau == pytest.approx(7.59, abs=0.05)  # the committed demo lasts 7.59 s


def test_dmp_alone_inserts_from_the_demo_start(peg_easy, nominal_result):
    r = nominal_result
    assert r.success, r
    assert r.failure_reason is None and r.failure_kind is None
    # The demonstration inserts at about 6.4 s; the episode stops 0.5 s after success.
    assert 5.0 < r.insertion_time_s < 7.5
    assert r.sim_time_s < peg_easy.episode_time_s
    assert r.sim_time_s == pytest.approx(r.insertion_time_s + 0.5, abs=0.15)
    assert r.final_distance_m <= peg_easy.kappa_m
    assert r.final_angle_deg < 1.0
    assert r.peak_force_n > 1.0  # the peg touched the hole floor
    # ... and that is where the peak was felt: at the bottom, after reaching kappa.
    assert r.insertion_time_s <= r.peak_force_time_s <= r.sim_time_s
    assert r.peak_force_distance_m < 1e-3
    assert 0.0 <= r.mean_force_n <= r.peak_force_n
    assert r.peak_joint_contact_torque_nm > 0.0
    assert not r.force_limit_broken
    assert r.bin_index == -1


def test_same_spec_same_result(peg_easy, dmp, nominal_result):
    again = run_episode(peg_easy, dmp, EpisodeSpec())
    assert _comparable(again) == _comparable(nominal_result)


def test_zero_policy_object_equals_dmp_alone(peg_easy, dmp, nominal_result):
    """The in-diagram policy path with a zero residual reproduces the fixed zero input."""
    with_policy = run_episode(peg_easy, dmp, EpisodeSpec(), policy=ZeroPolicy())
    assert with_policy.success
    assert with_policy.insertion_time_s == nominal_result.insertion_time_s
    assert with_policy.final_distance_m == pytest.approx(nominal_result.final_distance_m, abs=1e-9)


def test_the_in_diagram_policy_runs_at_the_tasks_residual_period(peg_easy, dmp):
    """The policy system ticks once per the task's residual period from the residual's
    activation: twice as often at 20 Hz as at the paper's 10 Hz over the same episode."""
    counts = {}
    for period_s in (0.1, 0.05):
        calls = []

        def counting_policy(observation, calls=calls):
            calls.append(observation)
            return np.zeros(6)

        task = dataclasses.replace(peg_easy, episode_time_s=7.5, residual_period_s=period_s)
        spec = EpisodeSpec(fixture_dp=(0.01, 0.0, 0.0))  # fails: runs to the time limit
        r = run_episode(task, dmp, spec, policy=counting_policy)
        assert r.sim_time_s == pytest.approx(7.5)
        counts[period_s] = len(calls)
    acting_s = 7.5 - peg_easy.residual_activation_s
    assert counts[0.1] == pytest.approx(acting_s / 0.1, abs=2)
    assert abs(counts[0.05] - 2 * counts[0.1]) <= 2, counts


def test_large_fixture_error_fails_on_the_entrance(peg_easy, dmp):
    # 1 cm off: the 30 mm peg lands on the wall around the 32 mm hole.
    spec = EpisodeSpec(fixture_dp=(0.01, 0.0, 0.0))
    task = dataclasses.replace(peg_easy, episode_time_s=7.5)  # the DMP ends at 7.6 s
    r = run_episode(task, dmp, spec)
    assert not r.success
    assert math.isnan(r.insertion_time_s)
    assert r.failure_kind == "on_entrance", r.failure_reason
    assert r.failure_kind in FAILURE_KINDS
    assert r.final_distance_m > 0.03  # resting on top of a 40 mm deep hole
    assert r.sim_time_s == pytest.approx(7.5)
    assert r.peak_force_n > 1.0
    assert r.peak_force_distance_m > 0.03  # the peak was the landing on the wall


def test_when_peaked_dates_the_first_sample_holding_the_final_peak():
    times = np.array([0.0, 0.01, 0.02, 0.03])
    running_peak = np.array([0.0, 5.0, 9.0, 9.0])
    distances = np.array([0.04, 0.03, 0.02, 0.01])
    assert episode_module._when_peaked(times, running_peak, 9.0, times, distances) == (
        0.02,
        0.02,
    )
    # Felt after the last sample: dated at the last sample.
    assert episode_module._when_peaked(times, running_peak, 12.0, times, distances) == (
        0.03,
        0.01,
    )
    nan_time, nan_distance = episode_module._when_peaked(
        np.array([]), np.array([]), 1.0, np.array([]), np.array([])
    )
    assert math.isnan(nan_time) and math.isnan(nan_distance)
    no_contact = episode_module._when_peaked(times, np.zeros(4), 0.0, times, distances)
    assert all(map(math.isnan, no_contact))


def test_force_limit_stops_and_fails(peg_easy, dmp):
    # The nominal insertion touches the hole floor with tens of N (peak 68 N).
    task = dataclasses.replace(peg_easy, force_limit_n=5.0)
    r = run_episode(task, dmp, EpisodeSpec())
    assert not r.success and r.force_limit_broken
    assert r.failure_kind == "force_limit", r.failure_reason
    assert r.peak_force_n > 5.0
    assert r.sim_time_s < peg_easy.episode_time_s - 2.0  # stopped at the first touch


def test_solver_failure_is_a_failed_episode(peg_easy, dmp, monkeypatch):
    real_make_simulator = episode_module.MakeSimulator

    class FailingSimulator:
        def __init__(self, simulator):
            self._simulator = simulator

        def __getattr__(self, name):
            return getattr(self._simulator, name)

        def AdvanceTo(self, t: float) -> None:
            if t > 0.25:
                raise RuntimeError("SAP solver failed to converge\nmore details")
            self._simulator.AdvanceTo(t)

    monkeypatch.setattr(
        episode_module, "MakeSimulator", lambda rlfd: FailingSimulator(real_make_simulator(rlfd))
    )
    r = run_episode(peg_easy, dmp, EpisodeSpec())
    assert not r.success
    assert r.failure_reason == "solver: SAP solver failed to converge"
    assert r.sim_time_s == pytest.approx(0.2)


def test_unreachable_start_is_an_ik_failure(peg_easy, dmp):
    r = run_episode(peg_easy, dmp, EpisodeSpec(start_dp=(2.0, 0.0, 0.0)))
    assert not r.success
    assert r.failure_kind == "ik", r.failure_reason
    assert r.sim_time_s == 0.0


def test_bad_policy_action_is_a_policy_failure(peg_easy, dmp):
    r = run_episode(peg_easy, dmp, EpisodeSpec(), policy=lambda obs: np.full(6, np.nan))
    assert not r.success
    assert r.failure_kind == "policy", r.failure_reason


def test_episode_spec_validates():
    with pytest.raises(ValueError, match="start_dq must be a unit quaternion"):
        EpisodeSpec(start_dq=(1.0, 1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="fixture_dp must be 3 finite numbers"):
        EpisodeSpec(fixture_dp=(0.0, 0.0))
    spec = EpisodeSpec(start_dp=np.array([0.03, 0.04, 0.0]))
    assert spec.start_dp == (0.03, 0.04, 0.0)
    assert spec.start_position_offset_m == pytest.approx(0.05)
    assert spec.start_rotation_offset_deg == 0.0


def test_make_episode_specs_is_seeded(peg_easy):
    a = make_episode_specs(peg_easy, 6, seed=3, grid=True)
    assert a == make_episode_specs(peg_easy, 6, seed=3, grid=True)
    assert a != make_episode_specs(peg_easy, 6, seed=4, grid=True)
    assert all(s.bin_index == 0 for s in a)
    # Fixture errors are independent of the start distribution: same with grid=False.
    b = make_episode_specs(peg_easy, 6, seed=3, grid=False)
    assert [s.fixture_dp for s in b] == [s.fixture_dp for s in a]
    assert all(s.bin_index == -1 for s in b)
    bound = np.array(peg_easy.fixture_error.position_bound_m)
    for s in a + b:
        assert np.all(np.abs(s.start_dp) <= peg_easy.start.half_extent_m)
        assert np.all(np.abs(s.fixture_dp) <= bound + 1e-12)
        angle = 2 * math.degrees(math.acos(min(1.0, abs(s.fixture_dq[0]))))
        assert angle <= peg_easy.fixture_error.rotation_bound_deg + 1e-9
    with pytest.raises(ValueError, match="n must be positive"):
        make_episode_specs(peg_easy, 0, seed=0)


def test_make_episode_specs_follow_the_orientation_bins():
    gear = load_task("gear")
    specs = make_episode_specs(gear, 16, seed=0, grid=True)
    assert [s.bin_index for s in specs] == [b for b in range(8) for _ in range(2)]
    width = gear.start.max_angle_deg / gear.start.n_bins
    for s in specs:
        assert (
            s.bin_index * width <= s.start_rotation_offset_deg <= (s.bin_index + 1) * width + 1e-9
        )
        assert np.all(np.abs(s.start_dp) <= gear.start.half_extent_m)
        # The table slope (1 deg) is part of every fixture error.
        angle = 2 * math.degrees(math.acos(min(1.0, abs(s.fixture_dq[0]))))
        assert angle <= gear.fixture_error.rotation_bound_deg + 1.0 + 1e-9


def test_record_html_needs_meshcat(peg_easy, dmp, tmp_path):
    with pytest.raises(ValueError, match="record_html needs a meshcat"):
        run_episode(peg_easy, dmp, EpisodeSpec(), record_html=tmp_path / "episode.html")


class _CallCountingPolicy:
    """A policy with memory: its action depends on how often it was called since its
    last reset, so an episode that skipped the reset would act otherwise."""

    def __init__(self) -> None:
        self.calls = 0
        self.resets = 0

    def reset(self) -> None:
        self.calls = 0
        self.resets += 1

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        self.calls += 1
        phase = 0.7 * self.calls
        return 0.5 * np.array([math.sin(phase), math.cos(phase), -0.2, 0.0, 0.0, 0.3])


@pytest.fixture(scope="module")
def offset_spec(peg_easy) -> EpisodeSpec:
    """A start from which the DMP alone is still out of the hole at the activation."""
    return make_episode_specs(peg_easy, 3, 0)[1]


def test_an_episode_resumed_from_a_stored_first_half_is_the_same_episode(
    peg_easy, dmp, offset_spec
):
    """The DMP-only first half is kept per process and resumed from, bit for bit: by the
    DMP alone and by a policy with memory (reset on resuming), from a first half
    simulated without any policy."""
    alone = run_episode(peg_easy, dmp, offset_spec, reuse_prefix=False)
    fresh_policy = _CallCountingPolicy()
    with_policy = run_episode(peg_easy, dmp, offset_spec, policy=fresh_policy, reuse_prefix=False)
    assert episode_module.prefix_cache_stats() == {"hits": 0, "stored": 0, "held": 0}
    stored = run_episode(peg_easy, dmp, offset_spec)
    assert episode_module.prefix_cache_stats() == {"hits": 0, "stored": 1, "held": 1}
    resumed_alone = run_episode(peg_easy, dmp, offset_spec)
    resumed_policy = _CallCountingPolicy()
    resumed = run_episode(peg_easy, dmp, offset_spec, policy=resumed_policy)
    assert episode_module.prefix_cache_stats() == {"hits": 2, "stored": 1, "held": 1}
    assert _comparable(stored) == _comparable(alone)
    assert _comparable(resumed_alone) == _comparable(alone)
    assert _comparable(resumed) == _comparable(with_policy)
    assert resumed_policy.resets == 1 and resumed_policy.calls == fresh_policy.calls > 0
    assert resumed.final_distance_m != alone.final_distance_m  # the policy did act


def test_an_episode_start_is_not_reused_where_the_policy_acts_before_the_activation(
    peg_easy, dmp, offset_spec
):
    """A policy called from the start, or another episode (another start, task or
    stopping rule), neither stores into nor resumes from the first half of this one."""
    run_episode(peg_easy, dmp, offset_spec)
    from_start = RlfdDiagramConfig(residual_policy_from_activation=False)
    run_episode(peg_easy, dmp, offset_spec, policy=ZeroPolicy(), diagram_config=from_start)
    run_episode(peg_easy, dmp, offset_spec, stop_after_success_s=None)
    assert episode_module.prefix_cache_stats() == {"hits": 0, "stored": 2, "held": 2}


def test_the_loop_resumes_at_the_last_chunk_half_a_chunk_before_the_activation():
    ends = episode_module._chunk_ends(10.0, 0.1)
    assert len(ends) == 100 and ends[-1] == pytest.approx(10.0)  # sums of 0.1, as ever
    index = episode_module._last_chunk_before(ends, 5.0, 0.1)
    assert index == 48 and ends[index] == pytest.approx(4.9)
    assert episode_module._last_chunk_before(ends, 0.0, 0.1) is None


def test_episode_keys_tell_apart_what_changes_the_first_half(peg_easy, dmp, offset_spec):
    config = RlfdDiagramConfig()
    key = episode_module._prefix_key(peg_easy, dmp, offset_spec, config, 0.1, 0.5)
    translation = dataclasses.replace(config, residual_mode="translation")
    assert episode_module._prefix_key(peg_easy, dmp, offset_spec, translation, 0.1, 0.5) == key
    other_start = dataclasses.replace(offset_spec, start_dp=(0.0, 0.0, 0.001))
    stiffer = dataclasses.replace(peg_easy, translational_stiffness_N_per_m=2500.0)
    slower = dataclasses.replace(config, dmp_period_s=0.02)
    assert (
        len(
            {
                key,
                episode_module._prefix_key(peg_easy, dmp, other_start, config, 0.1, 0.5),
                episode_module._prefix_key(stiffer, dmp, offset_spec, config, 0.1, 0.5),
                episode_module._prefix_key(peg_easy, dmp, offset_spec, slower, 0.1, 0.5),
                episode_module._prefix_key(peg_easy, dmp, offset_spec, config, 0.1, None),
            }
        )
        == 5
    )
    with pytest.raises(TypeError, match="cannot fingerprint a object"):
        episode_module._fingerprint_parts(object(), [])


def test_a_kept_diagram_runs_the_same_episodes_as_a_new_one(peg_easy, dmp):
    """Episodes reuse one diagram per task, configuration and kind of policy: the
    fixture moved by its context parameter, the policy and the DMP's forcing weights
    swapped in. Each episode is the one a diagram built for it runs."""
    specs = make_episode_specs(peg_easy, 3, 0)
    assert len({tuple(s.fixture_dp) for s in specs}) == 3
    policy_a, policy_b = _CallCountingPolicy(), _CallCountingPolicy()
    reweighted = with_weights(dmp, 1.05 * get_weights(dmp))
    runs = [
        (specs[0], dmp, None),
        (specs[1], dmp, policy_a),
        (specs[2], dmp, policy_b),
        (specs[1], dmp, None),
        (specs[2], reweighted, None),
    ]
    kept = [run_episode(peg_easy, m, s, policy=p, reuse_prefix=False) for s, m, p in runs]
    assert episode_module.diagram_cache_stats() == {"built": 2, "reused": 3, "held": 2}
    # Between episodes only the diagram run last may hold a policy: the policy diagram,
    # followed by DMP-only episodes, has let policy_b go.
    policy_diagram = next(d for d in episode_module._DIAGRAM_CACHE.values() if d.residual_policy)
    assert policy_diagram.residual_policy._policy_object is None
    for (spec, model, policy), result in list(zip(runs, kept, strict=True))[2:]:
        episode_module.clear_diagram_cache()
        fresh_policy = None if policy is None else _CallCountingPolicy()
        new = run_episode(peg_easy, model, spec, policy=fresh_policy, reuse_prefix=False)
        assert episode_module.diagram_cache_stats()["built"] == 1
        assert _comparable(result) == _comparable(new)
    assert kept[2].final_distance_m != kept[1].final_distance_m
    assert kept[4].peak_force_n != kept[3].peak_force_n  # the weights did change the DMP
