"""rlfd bench evaluate: this code's evaluations against another commit's, side by side."""

from __future__ import annotations

import subprocess

import pytest

from rlfd_drake.bench import evaluate_speed


def _in_a_git_checkout() -> bool:
    root = evaluate_speed._checkout_root()
    done = subprocess.run(
        ["git", "-C", str(root), "rev-parse", "--verify", "HEAD"], capture_output=True
    )
    return done.returncode == 0 and (root / ".git").exists()


@pytest.mark.skipif(not _in_a_git_checkout(), reason="needs the package in a git checkout")
def test_the_benchmark_times_both_codes_on_the_same_episodes():
    """Against HEAD's own code (extracted apart, run by its own path) on one cell of
    two starts: both codes time the same episodes (the runs' physics is deterministic)."""
    data = evaluate_speed.run(
        against="HEAD", repeats=1, episodes=2, cells=(("peg_easy", "dmp", "full"),)
    )
    assert data["same_episodes"] is True
    assert data["success_pct"]["this"] == data["success_pct"]["against"]
    assert len(data["success_pct"]["this"]) == 1 and 0 <= data["success_pct"]["this"][0] <= 100
    assert set(data["wall_s"]) == {"this", "against"} and min(data["wall_s"].values()) > 0
    assert data["speedup"] == pytest.approx(data["wall_s"]["against"] / data["wall_s"]["this"])
    assert len(data["against_commit"]) == 40 and data["samples_s"]["this"] == [
        data["wall_s"]["this"]
    ]
    assert data["per_episode_s"]["this"] == pytest.approx(data["wall_s"]["this"] / 2)
    # A worker holds Drake and torch: far above 100 MB, far below the machine's memory.
    for code in ("this", "against"):
        assert 100 < data["worker_max_rss_mb"][code] < 8000
        assert data["worker_max_rss_mb_samples"][code] == [data["worker_max_rss_mb"][code]]


@pytest.mark.parametrize(
    ("arguments", "match"),
    [
        ({"repeats": 0}, "repeats must be an integer >= 1, got 0"),
        ({"episodes": 2.5}, "episodes must be an integer >= 1, got 2.5"),
        ({"seed": -1}, "seed must be an integer >= 0, got -1"),
        ({"against": "no-such-revision"}, "against: 'no-such-revision' is not a commit"),
    ],
)
def test_bad_benchmark_settings_are_refused(arguments, match):
    with pytest.raises(ValueError, match=match):
        evaluate_speed.run(**arguments)
