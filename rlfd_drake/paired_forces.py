"""Stored evaluations' contact forces against a baseline's on the same starts.

#6's force target is "rLfD's peak contact force is not above the DMP's". Comparing two
means over episodes hides which episodes differ; evaluations with the same seed share
their starts and fixture errors, so each episode of a policy has a twin of the baseline
(the DMP alone) and the comparison can be paired: per start, is the policy's peak above
the baseline's? A two-sided sign test over the starts says whether the difference is
more than the run-to-run scatter (the instantaneous peak of a contact-rich episode
moves by about 1 % between equal runs; the 20 ms low-passed peak by less).

The same pairing counts the starts each policy inserts that the baseline does not
(gained) and the reverse (lost), with the same sign test: two success rates a point
apart are noise on 200 starts unless the starts that differ mostly go one way.

Like :mod:`rlfd_drake.breakdown` it runs nothing: it reads the episode tables that
``rlfd evaluate`` stored and copies their commands.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from rlfd_drake.breakdown import evaluation_labels, load_evaluation
from rlfd_drake.results import new_result_path, results_dir, utc_now, write_result

__all__ = ["FORCE_SIGNALS", "paired_forces", "paired_forces_markdown", "sign_test_p"]

#: The episode table's force columns compared, by the name used in the result.
FORCE_SIGNALS = {"peak": "peak_force_n", "low_passed": "peak_low_passed_force_n"}
#: Episode-table columns that identify a start; equal in paired evaluations.
_START_COLUMNS = ("position_offset_mm", "rotation_offset_deg", "fixture_error_mm")


def sign_test_p(n_above: int, n_below: int) -> float:
    """Two-sided exact sign test: the probability, if above and below were equally
    likely, of a split at least as uneven as ``n_above`` : ``n_below`` (ties dropped)."""
    if n_above < 0 or n_below < 0:
        raise ValueError(f"counts must be >= 0, got n_above={n_above}, n_below={n_below}")
    n = n_above + n_below
    if n == 0:
        return 1.0
    # Integer numerator and denominator: 2.0**n overflows a float beyond n = 1023 starts.
    tail = sum(math.comb(n, i) for i in range(min(n_above, n_below) + 1)) / 2**n
    return min(1.0, 2.0 * tail)


def _paired(policy: np.ndarray, baseline: np.ndarray) -> dict:
    above, below = int(np.sum(policy > baseline)), int(np.sum(policy < baseline))
    return {
        "mean_n": float(np.mean(policy)),
        "baseline_mean_n": float(np.mean(baseline)),
        "mean_difference_n": float(np.mean(policy - baseline)),
        "median_ratio": float(np.median(policy / baseline)),
        "n_above": above,
        "n_below": below,
        "sign_test_p": sign_test_p(above, below),
    }


def _outcomes(table: dict, base_table: dict) -> dict | None:
    """Starts the policy inserts and the baseline does not (gained), the reverse (lost),
    and the sign test over the two; None if either table has no success column."""
    if "success" not in table or "success" not in base_table:
        return None
    policy = np.asarray(table["success"], dtype=bool)
    baseline = np.asarray(base_table["success"], dtype=bool)
    gained, lost = int(np.sum(policy & ~baseline)), int(np.sum(~policy & baseline))
    return {"gained": gained, "lost": lost, "sign_test_p": sign_test_p(gained, lost)}


def _column(table: dict, key: str, path: str | Path) -> np.ndarray:
    if key not in table:
        raise ValueError(f"evaluations: {str(path)!r} has no episode column {key!r}")
    return np.asarray(table[key], dtype=float)


def _recorded_packages(record: dict) -> dict | None:
    """The package versions an evaluation was made with (None: not recorded, before
    2026-12-02)."""
    return (record.get("machine") or {}).get("packages")


def package_note(data: dict) -> str:
    """A sentence on whether the compared evaluations share their package versions: a
    learned policy's force peaks move with them, so a ratio across environments mixes
    the two."""
    entries = [("baseline", data["baseline"])] + [(c["label"], c) for c in data["columns"]]
    unrecorded = [label for label, entry in entries if entry.get("packages") is None]
    versions = {json.dumps(e["packages"], sort_keys=True) for _, e in entries if e.get("packages")}
    if not unrecorded and len(versions) == 1:
        shared = entries[0][1]["packages"]
        listed = ", ".join(f"{name} {version}" for name, version in shared.items())
        return f"All evaluations were made with the same packages ({listed})."
    problems = []
    if unrecorded:
        problems.append(f"no package versions recorded for: {', '.join(unrecorded)}")
    if len(versions) > 1:
        problems.append("the recorded package versions differ")
    return (
        f"Caution: {'; '.join(problems)}. The same policy and starts in another "
        "environment kept their outcomes but not their force peaks "
        "(results.RECORDED_PACKAGES), so these ratios may mix the policy's effect with "
        "the environment's."
    )


def paired_forces(
    baseline: str | Path,
    evaluations: list[str | Path],
    labels: list[str] | None = None,
    name: str | None = None,
    overwrite: bool = False,
) -> dict:
    """Each evaluation's peak and low-passed peak contact forces against ``baseline``'s
    on the same starts; with ``name``, writes ``results/paired_forces_<name>.{json,md}``.

    Returns:
        {"task", "episodes", "baseline": {"file", "command", "packages", "success_rate"},
        "columns": [{"label", "file", "command", "packages", "seed", "success_rate",
        "outcomes", "peak", "low_passed"}]}, "outcomes" as {"gained", "lost",
        "sign_test_p"} (None where an episode table has no success column), "peak" and
        "low_passed" as {"mean_n", "baseline_mean_n", "mean_difference_n", "median_ratio",
        "n_above", "n_below", "sign_test_p"}; "packages" is the versions the evaluation
        recorded (None: not recorded).

    Raises:
        ValueError: no evaluation, labels not one per file, a file that is not an
            evaluation, another task, or starts that differ from the baseline's.
        FileExistsError: the result exists and ``overwrite`` is False.
    """
    labels = evaluation_labels(evaluations, labels)
    if name is not None:
        new_result_path(f"paired_forces_{name}", overwrite)
    base_record, base = load_evaluation(baseline)
    base_table = base["episode_table"]
    base_starts = [_column(base_table, key, baseline) for key in _START_COLUMNS]
    columns = []
    for label, path in zip(labels, evaluations, strict=True):
        record, result = load_evaluation(path)
        if result.get("task") != base.get("task"):
            raise ValueError(
                f"evaluations: {str(path)!r} is of task {result.get('task')!r}, the "
                f"baseline of {base.get('task')!r} (evaluate the baseline on the same task "
                "or variant)"
            )
        table = result["episode_table"]
        starts = [_column(table, key, path) for key in _START_COLUMNS]
        pairs = zip(starts, base_starts, strict=True)
        if any(a.shape != b.shape or not np.allclose(a, b) for a, b in pairs):
            raise ValueError(
                f"evaluations: {str(path)!r} has other starts than the baseline "
                f"{str(baseline)!r} (evaluate both with the same --episodes and --seed)"
            )
        columns.append(
            {
                "label": label,
                "file": str(path),
                "command": record.get("command"),
                "packages": _recorded_packages(record),
                "seed": record.get("seed"),
                "success_rate": result.get("success_rate"),
                "outcomes": _outcomes(table, base_table),
                **{
                    signal: _paired(_column(table, key, path), _column(base_table, key, baseline))
                    for signal, key in FORCE_SIGNALS.items()
                },
            }
        )
    data = {
        "task": base.get("task"),
        "episodes": len(base_starts[0]),
        "baseline": {
            "file": str(baseline),
            "command": base_record.get("command"),
            "packages": _recorded_packages(base_record),
            "success_rate": base.get("success_rate"),
        },
        "columns": columns,
    }
    if name is not None:
        write_result(f"paired_forces_{name}", data, seed=None)
        (results_dir() / f"paired_forces_{name}.md").write_text(paired_forces_markdown(data))
    return data


def paired_forces_markdown(data: dict) -> str:
    """One row per evaluation: success, the starts gained / lost against the baseline
    with their sign test, then for the peak and the low-passed peak the
    means (policy / baseline), the median per-start ratio, the starts above / below the
    baseline and the sign test's p."""
    header = [
        "policy",
        "success",
        "gained / lost (p)",
        "peak, N (policy / baseline)",
        "median ratio",
        "above / below",
        "p",
        "low-passed peak, N",
        "median ratio",
        "above / below",
        "p",
    ]
    lines = [
        f"# {data['task']}: contact forces against the baseline on the same "
        f"{data['episodes']} starts",
        "",
        f"{utc_now()[:10]}. Baseline: `{data['baseline']['file']}` "
        f"({100 * data['baseline']['success_rate']:.1f} %). Per start, the policy's peak "
        "against the baseline's; gained / lost: starts the policy inserts and the baseline "
        "does not, and the reverse; p is the two-sided sign test (ties dropped). Regrouped "
        "from the stored evaluations below; nothing was run.",
        "",
        package_note(data),
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
    ]
    for column in data["columns"]:
        outcomes = column.get("outcomes")
        cells = [
            column["label"],
            f"{100 * column['success_rate']:.1f} %",
            "-"
            if outcomes is None
            else f"{outcomes['gained']} / {outcomes['lost']} ({outcomes['sign_test_p']:.2g})",
        ]
        for signal in FORCE_SIGNALS:
            s = column[signal]
            cells += [
                f"{s['mean_n']:.0f} / {s['baseline_mean_n']:.0f}",
                f"{s['median_ratio']:.2f}",
                f"{s['n_above']} / {s['n_below']}",
                f"{s['sign_test_p']:.2g}",
            ]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "Evaluations (each file holds its command, seed and date):", ""]
    lines.append(f"- baseline: `{data['baseline']['file']}`: `{data['baseline']['command']}`")
    lines += [f"- {c['label']}: `{c['file']}`: `{c['command']}`" for c in data["columns"]]
    return "\n".join(lines) + "\n"
