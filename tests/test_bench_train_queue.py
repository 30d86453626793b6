"""rlfd bench train-queue: real short runs, one at a time and two at a time."""

from __future__ import annotations

import pytest

from rlfd_drake.bench import train_queue


def test_the_benchmark_trains_every_setting_and_compares_it_with_one_at_a_time():
    data = train_queue.run(repeats=1, runs=2, episodes=1, parallel=(1, 2))
    assert set(data["wall_s"]) == {"1", "2"} and all(w > 0 for w in data["wall_s"].values())
    assert data["speedup_over_one_at_a_time"]["1"] == 1.0
    ratio = data["wall_s"]["1"] / data["wall_s"]["2"]
    assert data["speedup_over_one_at_a_time"]["2"] == pytest.approx(ratio)
    assert data["samples_s"]["2"] == [data["wall_s"]["2"]]


@pytest.mark.parametrize(
    ("arguments", "match"),
    [
        ({"repeats": 0}, "repeats must be an integer >= 1, got 0"),
        ({"runs": 1.5}, "runs must be an integer >= 1, got 1.5"),
        ({"episodes": -1}, "episodes must be an integer >= 1, got -1"),
        ({"parallel": ()}, r"parallel must be integers >= 1, got \[\]"),
        ({"parallel": (1, 0)}, r"parallel must be integers >= 1, got \[1, 0\]"),
    ],
)
def test_bad_benchmark_settings_are_refused(arguments, match):
    with pytest.raises(ValueError, match=match):
        train_queue.run(**arguments)
