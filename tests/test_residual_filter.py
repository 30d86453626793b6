"""ResidualFilter: the first-order low-pass on the residual action."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rlfd_drake.control_math import low_pass_gain
from rlfd_drake.systems.residual_filter import ResidualFilter, ResidualFilterConfig


def test_low_pass_gain_is_the_exact_step_of_the_continuous_filter():
    assert low_pass_gain(0.002, 0.1) == pytest.approx(1.0 - math.exp(-0.02), rel=1e-12)
    assert low_pass_gain(1e-9, 1.0) == pytest.approx(1e-9, rel=1e-6)  # no cancellation


def test_step_response_follows_one_minus_exp(sample_output):
    """A held step of 1 reaches 1 - exp(-t / tau) after activation; the clipped 3 stays
    at 1, the composer's limit, and the negative step mirrors it."""
    tau, activation = 0.1, 0.5
    config = ResidualFilterConfig(time_constant_s=tau, period_s=0.002, activation_time_s=activation)
    step = np.array([1.0, -1.0, 3.0, 0.5, 0.0, -0.25])
    samples = sample_output(ResidualFilter(config), step, activation + 0.3)
    for t, y in samples:
        if t < activation - 1e-9:
            assert np.all(y == 0.0), t
    t_end, y_end = samples[-1]
    # Updates at activation, activation + 2 ms, ... up to (not including) t_end.
    updates = round((t_end - activation) / config.period_s)
    expected = (1.0 - math.exp(-updates * config.period_s / tau)) * np.clip(step, -1.0, 1.0)
    np.testing.assert_allclose(y_end, expected, rtol=1e-9, atol=1e-12)
    assert 0.94 < y_end[0] < 0.96  # about 3 tau


def test_non_finite_residual_is_refused(sample_output):
    config = ResidualFilterConfig(activation_time_s=0.0)
    with pytest.raises(RuntimeError, match="non-finite value on port 'residual'"):
        sample_output(ResidualFilter(config), np.array([0.0, np.nan, 0.0, 0.0, 0.0, 0.0]), 0.01)


@pytest.mark.parametrize(
    ("field", "value"),
    [("time_constant_s", 0.0), ("time_constant_s", float("nan")), ("period_s", -0.002)],
)
def test_bad_config_names_the_field(field, value):
    with pytest.raises(ValueError, match=rf"{field} must be a positive number of seconds"):
        ResidualFilter(ResidualFilterConfig(**{field: value}))
    with pytest.raises(ValueError, match="activation_time_s must be a non-negative"):
        ResidualFilter(ResidualFilterConfig(activation_time_s=-1.0))
