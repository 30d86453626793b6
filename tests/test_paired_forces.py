"""Contact forces against a baseline on the same starts (rlfd paired-forces)."""

from __future__ import annotations

import json
import math

import pytest

from rlfd_drake.cli import main
from rlfd_drake.paired_forces import paired_forces, paired_forces_markdown, sign_test_p


def _evaluation(
    task: str,
    peaks: list[float],
    offsets: list[float] | None = None,
    success: list[bool] | None = None,
) -> dict:
    n = len(peaks)
    table = {} if success is None else {"success": success}
    return {
        "task": task,
        "episodes": n,
        "success_rate": 0.5,
        "episode_table": {
            "position_offset_mm": offsets if offsets is not None else [float(i) for i in range(n)],
            "rotation_offset_deg": [1.0] * n,
            "fixture_error_mm": [0.5] * n,
            "peak_force_n": peaks,
            "peak_low_passed_force_n": [p / 2 for p in peaks],
            **table,
        },
    }


def _write(path, result: dict) -> str:
    path.write_text(json.dumps({"command": "rlfd evaluate ...", "seed": 0, "data": result}))
    return str(path)


def test_sign_test_matches_the_binomial_tails():
    # 10 of 10 above: 2 / 2^10.
    assert sign_test_p(10, 0) == pytest.approx(2 / 1024)
    # 8 : 2 -> 2 * (1 + 10 + 45) / 1024.
    assert sign_test_p(8, 2) == pytest.approx(2 * 56 / 1024)
    assert sign_test_p(2, 8) == sign_test_p(8, 2)
    assert sign_test_p(5, 5) == 1.0 and sign_test_p(0, 0) == 1.0
    # Pooled over seeds, thousands of starts: no float overflow, and the normal
    # approximation's p (z = 106 / sqrt(1200) = 3.06 -> 0.0022) within rounding.
    assert sign_test_p(653, 547) == pytest.approx(0.0025, abs=3e-4)
    assert sign_test_p(1500, 1500) == 1.0 and 0.0 <= sign_test_p(3000, 0) < 1e-300
    with pytest.raises(ValueError, match="counts must be >= 0"):
        sign_test_p(-1, 3)


def test_paired_forces_compares_start_by_start(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    base_success = [False] * 5 + [True] * 5
    baseline = _write(tmp_path / "dmp.json", _evaluation("peg", [100.0] * 10, success=base_success))
    # Above the baseline on 8 starts, below on 1, equal on 1; inserts 4 of the
    # baseline's 5 failures and loses 1 of its 5 successes.
    peaks = [110.0] * 8 + [90.0, 100.0]
    success = [True] * 4 + [False, False] + [True] * 4
    policy = _write(tmp_path / "policy.json", _evaluation("peg", peaks, success=success))
    data = paired_forces(baseline, [policy], ["rLfD"], name="toy")
    (column,) = data["columns"]
    peak = column["peak"]
    assert (peak["n_above"], peak["n_below"]) == (8, 1)
    assert peak["mean_difference_n"] == pytest.approx(7.0)
    assert peak["median_ratio"] == pytest.approx(1.1)
    assert peak["sign_test_p"] == pytest.approx(2 * (1 + 9) / 2**9)
    assert column["low_passed"]["mean_n"] == pytest.approx(53.5)
    assert column["outcomes"] == {"gained": 4, "lost": 1, "sign_test_p": sign_test_p(4, 1)}
    assert sign_test_p(4, 1) == pytest.approx(2 * 6 / 32)
    stored = json.loads((tmp_path / "results" / "paired_forces_toy.json").read_text())
    assert stored["data"]["baseline"]["file"] == baseline
    markdown = (tmp_path / "results" / "paired_forces_toy.md").read_text()
    assert "| rLfD | 50.0 % | 4 / 1 (0.38) | 107 / 100 | 1.10 | 8 / 1 |" in markdown
    # Episode tables without a success column: no outcomes, a dash in the table.
    old_base = _write(tmp_path / "old_dmp.json", _evaluation("peg", [100.0] * 10))
    old = paired_forces(old_base, [policy], ["rLfD"])
    assert old["columns"][0]["outcomes"] is None
    assert "| rLfD | 50.0 % | - | 107 / 100 |" in paired_forces_markdown(old)
    with pytest.raises(FileExistsError, match="pass --overwrite"):
        paired_forces(baseline, [policy], name="toy")
    assert math.isclose(
        paired_forces(baseline, [policy], name="toy", overwrite=True)["columns"][0]["peak"][
            "mean_n"
        ],
        107.0,
    )


def test_paired_forces_refuses_other_tasks_and_other_starts(tmp_path, capsys):
    baseline = _write(tmp_path / "dmp.json", _evaluation("peg", [100.0] * 4))
    gear = _write(tmp_path / "gear.json", _evaluation("gear", [100.0] * 4))
    moved = _write(tmp_path / "moved.json", _evaluation("peg", [100.0] * 4, [0.0, 1.0, 2.0, 9.0]))
    shorter = _write(tmp_path / "short.json", _evaluation("peg", [100.0] * 3))
    with pytest.raises(ValueError, match="is of task 'gear', the baseline of 'peg'"):
        paired_forces(baseline, [gear])
    for other in (moved, shorter):
        with pytest.raises(ValueError, match="has other starts than the baseline"):
            paired_forces(baseline, [other])
    with pytest.raises(ValueError, match="labels: one per evaluation file"):
        paired_forces(baseline, [moved], ["a", "b"])
    with pytest.raises(ValueError, match="give at least one evaluation"):
        paired_forces(baseline, [])
    args = ["paired-forces", "--baseline", str(tmp_path / "none.json"), gear, "--name", "x"]
    assert main(args) == 2
    assert "no evaluation file at" in capsys.readouterr().err


def test_paired_forces_says_whether_the_package_versions_match(tmp_path, monkeypatch):
    """A policy's force peaks move with the installed versions: the note names
    evaluations without recorded versions or with other ones."""
    monkeypatch.chdir(tmp_path)

    def write(name: str, packages: dict | None) -> str:
        record = {"command": "rlfd evaluate ...", "seed": 0, "data": _evaluation("peg", [1.0])}
        if packages is not None:
            record["machine"] = {"packages": packages}
        (tmp_path / name).write_text(json.dumps(record))
        return str(tmp_path / name)

    here = {"drake": "1.51.1", "torch": "2.13.0"}
    baseline = write("dmp.json", here)
    same = write("same.json", here)
    other = write("other.json", {"drake": "1.50.0", "torch": "2.13.0"})
    old = write("old.json", None)
    paired_forces(baseline, [same], ["rLfD"], name="same")
    markdown = (tmp_path / "results" / "paired_forces_same.md").read_text()
    assert "same packages (drake 1.51.1, torch 2.13.0)" in markdown
    assert "Caution" not in markdown
    paired_forces(baseline, [other, old], ["other", "old"], name="mixed")
    markdown = (tmp_path / "results" / "paired_forces_mixed.md").read_text()
    assert "Caution: no package versions recorded for: old; the recorded package" in markdown


def test_results_record_the_package_versions(tmp_path, monkeypatch):
    from importlib.metadata import version

    from rlfd_drake.results import RECORDED_PACKAGES, write_result

    monkeypatch.chdir(tmp_path)
    stored = json.loads(write_result("toy", {"x": 1}, seed=0).read_text())
    packages = stored["machine"]["packages"]
    assert set(packages) == set(RECORDED_PACKAGES)
    assert packages["drake"] == version("drake") and packages["numpy"] == version("numpy")
