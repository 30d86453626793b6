"""ResidualIntegrator: the incremental residual (the action is a rate)."""

from __future__ import annotations

import numpy as np
import pytest

from rlfd_drake.control_math import integrate_residual
from rlfd_drake.systems.residual_integrator import ResidualIntegrator, ResidualIntegratorConfig


def test_integrate_residual_clips_the_rate_and_the_offset():
    offset = np.array([0.0, 0.95, -0.5, 0.0, 0.0, 0.0])
    rate = np.array([0.5, 1.0, 3.0, -4.0, 0.0, np.float64(-0.2)])
    out = integrate_residual(offset, rate, 0.1)
    np.testing.assert_allclose(out, [0.05, 1.0, -0.4, -0.1, 0.0, -0.02])


def test_a_held_rate_ramps_the_offset_from_the_activation_and_saturates(sample_output):
    """Zero before activation; then rate * elapsed time per unit of action, the rate
    clipped to [-1, 1]; the offset stops at the residual's range."""
    activation, rate_per_s = 0.2, 2.0
    config = ResidualIntegratorConfig(
        rate_per_s=rate_per_s, period_s=0.002, activation_time_s=activation
    )
    rate = np.array([1.0, -0.5, 3.0, 0.25, 0.0, -1.0])
    samples = sample_output(ResidualIntegrator(config), rate, activation + 0.3)
    for t, y in samples:
        if t < activation - 1e-9:
            assert np.all(y == 0.0), t
    t_end, y_end = samples[-1]
    updates = round((t_end - activation) / config.period_s)
    elapsed = updates * config.period_s
    expected = np.clip(np.clip(rate, -1.0, 1.0) * rate_per_s * elapsed, -1.0, 1.0)
    np.testing.assert_allclose(y_end, expected, rtol=1e-9, atol=1e-12)
    assert y_end[0] == pytest.approx(0.6)  # 2 per s for 0.3 s
    # Past the range the offset holds at 1.
    late = sample_output(ResidualIntegrator(config), rate, activation + 1.0)[-1][1]
    assert late[0] == 1.0 and late[5] == -1.0


def test_non_finite_rate_is_refused(sample_output):
    config = ResidualIntegratorConfig(activation_time_s=0.0)
    with pytest.raises(RuntimeError, match="non-finite value on port 'residual_rate'"):
        sample_output(ResidualIntegrator(config), np.array([0.0, np.inf, 0.0, 0.0, 0.0, 0.0]), 0.01)


@pytest.mark.parametrize(
    ("field", "value"), [("rate_per_s", 0.0), ("rate_per_s", float("nan")), ("period_s", -1.0)]
)
def test_bad_config_names_the_field(field, value):
    with pytest.raises(ValueError, match=rf"{field} must be a positive number, got"):
        ResidualIntegrator(ResidualIntegratorConfig(**{field: value}))
    with pytest.raises(ValueError, match="activation_time_s must be a non-negative"):
        ResidualIntegrator(ResidualIntegratorConfig(activation_time_s=-1.0))


def test_the_offset_starts_where_it_is_told_and_integrates_from_there(sample_output):
    """``start_offset``: held before activation, the rate added to it after."""
    activation = 0.1
    start = np.array([0.0, 0.0, 0.0, 0.0, 0.2, 0.0])
    config = ResidualIntegratorConfig(
        rate_per_s=1.0, period_s=0.002, activation_time_s=activation, start_offset=tuple(start)
    )
    rate = np.array([0.5, 0.0, 0.0, 0.0, -1.0, 0.0])
    samples = sample_output(ResidualIntegrator(config), rate, activation + 0.1)
    for t, y in samples:
        if t < activation - 1e-9:
            np.testing.assert_array_equal(y, start)
    t_end, y_end = samples[-1]
    elapsed = round((t_end - activation) / config.period_s) * config.period_s
    np.testing.assert_allclose(y_end, start + np.clip(rate, -1, 1) * elapsed, atol=1e-12)


@pytest.mark.parametrize(
    "start", [(0.0,) * 5, (0.0, 0.0, 0.0, 0.0, 1.5, 0.0), (0.0, 0.0, 0.0, 0.0, float("nan"), 0.0)]
)
def test_a_bad_start_offset_is_refused(start):
    with pytest.raises(ValueError, match="start_offset must be 6 numbers in \\[-1, 1\\]"):
        ResidualIntegrator(ResidualIntegratorConfig(start_offset=start))
