"""The results writer: what it stores reads back unchanged, and stays small."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rlfd_drake.results import check_result_name, format_json, invoked_command, write_result


def test_format_json_reads_back_the_same_value_with_scalar_lists_on_one_line():
    value = {
        "episodes": {"success": [1, 0, 1], "failure": [None, "force_limit: 31 N", None]},
        "per_bin": [{"bin": 0, "n": 2}, {"bin": 1, "n": 1}],
        "bounds": [0.003, 0.052],
        "empty": {"list": [], "dict": {}},
        "nested": [[1, 2], [3]],
        "flag": True,
    }
    text = format_json(value)
    assert json.loads(text) == value
    lines = text.splitlines()
    assert '    "success": [1, 0, 1],' in lines
    assert '  "bounds": [0.003, 0.052],' in lines
    # Lists of objects or lists keep one item per line, as json.dumps(indent=2) does.
    assert '  "per_bin": [' in lines
    assert "    [1, 2]," in lines


def test_per_episode_columns_take_fewer_bytes_than_indent_2():
    rng = np.random.default_rng(0)
    columns = {"peak_force_n": rng.uniform(0, 200, 200).round(2).tolist()}
    compact, indented = format_json(columns), json.dumps(columns, indent=2)
    assert json.loads(compact) == json.loads(indented)
    assert len(compact) < 0.8 * len(indented)


def test_write_result_stores_command_seed_date_and_data(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = write_result("eval_x", {"success": np.array([1, 0])}, seed=3, command="rlfd x")
    record = json.loads(path.read_text())
    assert path == tmp_path / "results" / "eval_x.json"
    assert (record["command"], record["seed"], record["data"]) == (
        "rlfd x",
        3,
        {"success": [1, 0]},
    )
    assert record["date"].startswith("20")


@pytest.mark.parametrize(
    "argv0",
    [".venv/bin/rlfd", "rlfd", "/tmp/clone/rlfd_drake/cli.py"],  # the last: python -m
)
def test_the_stored_command_reads_as_the_rlfd_command_however_it_was_started(argv0, monkeypatch):
    monkeypatch.setattr("sys.argv", [argv0, "train", "--task", "peg", "--out", "runs/a b"])
    assert invoked_command() == "rlfd train --task peg --out 'runs/a b'"


def test_a_stored_command_of_another_program_keeps_its_name(monkeypatch):
    monkeypatch.setattr("sys.argv", ["scripts/study.py", "--seed", "1"])
    assert invoked_command() == "scripts/study.py --seed 1"


@pytest.mark.parametrize("name", ["", "../eval_x", "sub/eval_x", ".hidden"])
def test_result_names_that_are_not_plain_file_stems_are_refused(name):
    with pytest.raises(ValueError, match="plain file stem"):
        check_result_name(name)


def test_capped_stem_keeps_short_names_and_hashes_long_ones():
    from rlfd_drake.results import capped_stem

    assert capped_stem("eval_peg_dmp_s0", 40) == "eval_peg_dmp_s0"
    long_a, long_b = "x" * 50 + "a", "x" * 50 + "b"
    assert len(capped_stem(long_a, 40)) == 40
    assert capped_stem(long_a, 40).startswith("x" * 27 + "_")
    assert capped_stem(long_a, 40) != capped_stem(long_b, 40)
    with pytest.raises(ValueError, match="limit must leave room"):
        capped_stem(long_a, 10)
