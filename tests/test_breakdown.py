"""Stored evaluations regrouped by the unseen fixture error (rlfd breakdown)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rlfd_drake.breakdown import breakdown, breakdown_markdown
from rlfd_drake.cli import main
from rlfd_drake.episode import make_episode_specs
from rlfd_drake.evaluate import fixture_direction_deg, success_by_group
from rlfd_drake.tasks import load_task


def _evaluation(task: str, degrees: list[float], success: list[bool], failure: list) -> dict:
    return {
        "task": task,
        "episodes": len(success),
        "success_rate": sum(success) / len(success),
        "episode_table": {
            "fixture_error_mm": [0.5] * len(success),
            "fixture_error_deg": degrees,
            "success": success,
            "failure": failure,
        },
    }


def _write(path, result: dict) -> str:
    path.write_text(json.dumps({"command": "rlfd evaluate ...", "seed": 0, "data": result}))
    return str(path)


DEGREES = [0.2, 0.8, 1.2, 1.7, 2.2, 3.0]
SUCCESS = [True, True, False, False, False, False]
FAILURE = [
    None,
    None,
    "jammed: 10.0 mm deep of 14 mm",
    "force_limit: 31 N",
    "on_entrance: 1.5 mm off axis",
    "solver: did not converge",
]


def test_success_by_group_counts_successes_and_failure_kinds_per_rotation_group():
    groups = success_by_group(_evaluation("rj45", DEGREES, SUCCESS, FAILURE), "fixture_rotation")
    assert [(g["from"], g["n"], g["success_rate"]) for g in groups] == [
        (0.0, 2, 1.0),
        (1.0, 1, 0.0),
        (1.5, 1, 0.0),
        (2.0, 1, 0.0),
        (2.5, 1, 0.0),
    ]
    assert groups[0]["failures"] == {}
    assert groups[1]["failures"] == {"jammed": 1}
    assert groups[4]["failures"] == {"solver": 1}
    # Custom edges: everything at or above 2 deg in one group, the rest left out.
    (group,) = success_by_group(
        _evaluation("rj45", DEGREES, SUCCESS, FAILURE), "fixture_rotation", (2.0, 10.0)
    )
    assert group["n"] == 2 and group["failures"] == {"on_entrance": 1, "solver": 1}


def test_success_by_group_refuses_bad_groupings_edges_and_old_tables():
    result = _evaluation("rj45", DEGREES, SUCCESS, FAILURE)
    with pytest.raises(ValueError, match="by must be one of"):
        success_by_group(result, "start_rotation")
    with pytest.raises(ValueError, match="edges must increase"):
        success_by_group(result, "fixture_rotation", (1.0, 1.0))
    del result["episode_table"]["fixture_error_deg"]
    with pytest.raises(ValueError, match="fixture_error_deg"):
        success_by_group(result, "fixture_rotation")


def test_breakdown_writes_the_evaluations_side_by_side(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    a = _write(tmp_path / "a.json", _evaluation("rj45", DEGREES, SUCCESS, FAILURE))
    b = _write(tmp_path / "b.json", _evaluation("rj45", DEGREES, [True] * 6, [None] * 6))
    assert main(["breakdown", a, b, "--labels", "DMP", "search", "--name", "toy"]) == 0
    data = json.loads((tmp_path / "results" / "breakdown_toy.json").read_text())["data"]
    assert [c["label"] for c in data["columns"]] == ["DMP", "search"]
    assert data["columns"][0]["command"] == "rlfd evaluate ..."
    markdown = (tmp_path / "results" / "breakdown_toy.md").read_text()
    assert "| 1 to 1.5 | 1 | 0.0 % (0 / 0 / 1) | 100.0 % (0 / 0 / 0) |" in markdown
    assert "| 2.5 to inf | 1 | 0.0 % (0 / 0 / 0, other 1) | 100.0 % (0 / 0 / 0) |" in markdown
    # Nothing the user saved is overwritten without asking.
    with pytest.raises(FileExistsError, match="--overwrite"):
        breakdown([a], name="toy")
    breakdown([a], name="toy", overwrite=True)


def test_breakdown_refuses_bad_input_naming_it(tmp_path):
    a = _write(tmp_path / "a.json", _evaluation("rj45", DEGREES, SUCCESS, FAILURE))
    gear = _write(tmp_path / "gear.json", _evaluation("gear", DEGREES, SUCCESS, FAILURE))
    (tmp_path / "junk.json").write_text("{}")
    with pytest.raises(ValueError, match="at least one"):
        breakdown([])
    with pytest.raises(ValueError, match="no evaluation file"):
        breakdown([str(tmp_path / "missing.json")])
    with pytest.raises(ValueError, match="not an evaluation JSON"):
        breakdown([str(tmp_path / "junk.json")])
    with pytest.raises(ValueError, match="labels: one per evaluation"):
        breakdown([a], labels=["x", "y"])
    with pytest.raises(ValueError, match="one task"):
        breakdown([a, gear])
    with pytest.raises(ValueError, match="by must be one of"):
        breakdown([a], by="bin")


def test_fixture_direction_names_the_side_of_the_hole():
    assert fixture_direction_deg((1.0, 0.0, 0.0)) == 0.0
    assert fixture_direction_deg((0.0, 2.0, 0.0)) == 90.0
    assert fixture_direction_deg((-1.0, 0.0, 0.0)) == 180.0
    assert fixture_direction_deg((0.0, -1.0, 0.0)) == 270.0
    assert fixture_direction_deg((1.0, -1.0, 0.0)) == pytest.approx(-45.0)  # +x's first edge
    assert fixture_direction_deg((1.0, -1.01, 0.0)) == pytest.approx(314.7, abs=0.1)


def _stored_grid_evaluation(tmp_path, command: str, sizes_shift: float = 0.0) -> tuple[str, list]:
    """An evaluation stored as before the direction column: 12 starts of peg's grid,
    seed 3, the starts on +x and -y failed."""
    specs = make_episode_specs(load_task("peg"), 12, 3, grid=True)
    directions = [fixture_direction_deg(s.fixture_dp) for s in specs]
    success = [not (-45 <= d < 45 or 225 <= d < 315) for d in directions]
    result = {
        "task": "peg",
        "episodes": 12,
        "seed": 3,
        "grid": True,
        "success_rate": sum(success) / 12,
        "episode_table": {
            "fixture_error_mm": [
                round(1e3 * float(np.linalg.norm(s.fixture_dp)) + sizes_shift, 2) for s in specs
            ],
            "success": success,
            "failure": [None if ok else "on_entrance: 2 mm off axis" for ok in success],
        },
    }
    path = tmp_path / f"eval_{len(command)}_{sizes_shift}.json"
    path.write_text(json.dumps({"command": command, "seed": 3, "data": result}))
    return str(path), directions


def test_breakdown_by_side_draws_an_old_evaluations_starts_again(tmp_path):
    command = "rlfd evaluate --task peg --policy dmp --episodes 12 --seed 3"
    path, directions = _stored_grid_evaluation(tmp_path, command)
    data = breakdown([path], by="fixture_direction", labels=["DMP"])
    groups = {g["from"]: g for g in data["columns"][0]["groups"]}
    for low, side_rate in ((-45.0, 0.0), (45.0, 1.0), (135.0, 1.0), (225.0, 0.0)):
        inside = [low <= d < low + 90 for d in directions]
        if any(inside):
            assert groups[low]["n"] == sum(inside) and groups[low]["success_rate"] == side_rate
    markdown = breakdown_markdown(data)
    for low, side in ((-45.0, "+x"), (45.0, "+y"), (135.0, "-x"), (225.0, "-y")):
        if low in groups:
            assert f"| {low:g} to {low + 90:g} ({side}) | {groups[low]['n']} |" in markdown
    assert len(groups) >= 3  # twelve starts reach most sides
    moved, _ = _stored_grid_evaluation(tmp_path, command, sizes_shift=0.5)
    with pytest.raises(ValueError, match="are not the stored ones"):
        breakdown([moved], by="fixture_direction")
    nameless, _ = _stored_grid_evaluation(tmp_path, "rlfd evaluate --policy dmp")
    with pytest.raises(ValueError, match="names no --task"):
        breakdown([nameless], by="fixture_direction")
