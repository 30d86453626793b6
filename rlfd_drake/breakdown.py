"""Stored evaluations side by side, their episodes grouped by what the robot could not
see (the fixture's position or rotation error): which errors a policy handles.

It runs nothing: it regroups the episode tables that ``rlfd evaluate`` stored, so a
breakdown is as reproducible as the evaluations it reads (their commands and seeds are
copied into it).
"""

from __future__ import annotations

import json
from pathlib import Path

from rlfd_drake.evaluate import (
    EPISODE_GROUPINGS,
    FIXTURE_SIDES,
    joined_evaluation,
    stored_fixture_directions,
    success_by_group,
)
from rlfd_drake.results import new_result_path, results_dir, utc_now, write_result

__all__ = ["breakdown", "breakdown_markdown", "evaluation_labels", "load_evaluation"]

#: Failure kinds shown in a breakdown's cells, in this order (the others are summed).
_SHOWN_FAILURES = ("force_limit", "on_entrance", "jammed")
#: The default groups of "fixture_direction": the four sides of the hole, named in rows.
_SIDE_EDGES = EPISODE_GROUPINGS["fixture_direction"][2]


def load_evaluation(path: str | Path, field: str = "evaluations") -> tuple[dict, dict]:
    """(the stored record, the evaluation with its episode table) of an evaluation JSON;
    a ValueError names ``field`` (the argument it came from) and a missing file or one
    that is not an evaluation."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{field}: no evaluation file at {str(path)!r}")
    try:
        record = json.loads(path.read_text())
        result = joined_evaluation(record, path)
        result["episode_table"]  # noqa: B018 (an evaluation has one)
    except (ValueError, KeyError, TypeError, OSError, EOFError) as error:
        raise ValueError(f"{field}: {str(path)!r} is not an evaluation JSON ({error})") from error
    return record, result


def evaluation_labels(evaluations: list[str | Path], labels: list[str] | None) -> list[str]:
    """One label per evaluation file (default: the file stems); a ValueError when there
    is no file or the labels do not match them one to one."""
    if not evaluations:
        raise ValueError("evaluations: give at least one evaluation JSON file")
    labels = list(labels) if labels else [Path(p).stem for p in evaluations]
    if len(labels) != len(evaluations):
        raise ValueError(
            f"labels: one per evaluation file ({len(evaluations)}), got {len(labels)}: {labels}"
        )
    return labels


def breakdown(
    evaluations: list[str | Path],
    by: str = "fixture_rotation",
    edges: tuple[float, ...] | None = None,
    labels: list[str] | None = None,
    name: str | None = None,
    overwrite: bool = False,
) -> dict:
    """Groups each stored evaluation's episodes by ``by`` (one of
    :data:`rlfd_drake.evaluate.EPISODE_GROUPINGS`) and, with ``name``, writes
    ``results/breakdown_<name>.json`` and ``.md``.

    Returns:
        {"by", "unit", "edges", "columns": [{"label", "file", "command", "seed",
        "episodes", "success_rate", "groups"}]}, groups as in
        :func:`rlfd_drake.evaluate.success_by_group`.

    Raises:
        ValueError: no evaluation, a file that is not an evaluation, labels not one per
            file, a bad grouping or edges, or evaluations of different tasks.
        FileExistsError: the result exists and ``overwrite`` is False.
    """
    labels = evaluation_labels(evaluations, labels)
    if by not in EPISODE_GROUPINGS:
        raise ValueError(f"by must be one of {sorted(EPISODE_GROUPINGS)}, got {by!r}")
    if name is not None:
        new_result_path(f"breakdown_{name}", overwrite)
    _, unit, default_edges = EPISODE_GROUPINGS[by]
    edges = default_edges if edges is None else tuple(float(e) for e in edges)
    columns, tasks = [], set()
    for label, path in zip(labels, evaluations, strict=True):
        record, result = load_evaluation(path)
        tasks.add(result.get("task"))
        column = EPISODE_GROUPINGS[by][0]
        if by == "fixture_direction" and column not in result["episode_table"]:
            try:
                result["episode_table"][column] = stored_fixture_directions(record, result)
            except ValueError as error:
                raise ValueError(f"evaluations: {str(path)!r}: {error}") from error
        columns.append(
            {
                "label": label,
                "file": str(path),
                "command": record.get("command"),
                "seed": record.get("seed"),
                "episodes": result.get("episodes"),
                "success_rate": result.get("success_rate"),
                "groups": success_by_group(result, by, edges),
            }
        )
    if len(tasks) != 1:
        raise ValueError(f"evaluations: all must be of one task, got {sorted(map(str, tasks))}")
    data = {"task": tasks.pop(), "by": by, "unit": unit, "edges": list(edges), "columns": columns}
    if name is not None:
        write_result(f"breakdown_{name}", data, seed=None)
        (results_dir() / f"breakdown_{name}.md").write_text(breakdown_markdown(data))
    return data


def _cell(group: dict | None) -> str:
    if group is None:
        return "-"
    failures = group["failures"]
    shown = [str(failures.get(kind, 0)) for kind in _SHOWN_FAILURES]
    other = sum(v for k, v in failures.items() if k not in _SHOWN_FAILURES)
    return f"{100 * group['success_rate']:.1f} % ({' / '.join(shown)}" + (
        f", other {other})" if other else ")"
    )


def breakdown_markdown(data: dict) -> str:
    """Groups as rows, evaluations as columns: success % (force limit / on entrance /
    jammed failures) in each cell, n per group."""
    what = data["by"].replace("_", " ")
    edges = data["edges"]
    header = [f"unseen {what} error, {data['unit']}", "n"] + [c["label"] for c in data["columns"]]
    lines = [
        f"# {data['task']}: success by the unseen {what} error",
        "",
        f"{utc_now()[:10]}. Each cell: success % (failures at the force limit / left on "
        "the entrance / jammed; other kinds named). Regrouped from the stored evaluations "
        "below; nothing was run.",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
    ]
    for low, high in zip(edges, edges[1:], strict=False):
        cells, counts = [], set()
        for column in data["columns"]:
            group = next((g for g in column["groups"] if g["from"] == low), None)
            cells.append(_cell(group))
            if group is not None:
                counts.add(group["n"])
        if not counts:
            continue
        n = str(counts.pop()) if len(counts) == 1 else "differs"
        sides = data["by"] == "fixture_direction" and tuple(edges) == _SIDE_EDGES
        side = f" ({FIXTURE_SIDES[low]})" if sides else ""
        lines.append(f"| {low:g} to {high:g}{side} | {n} | " + " | ".join(cells) + " |")
    lines.append(
        "| all | - | "
        + " | ".join(f"{100 * c['success_rate']:.1f} % of {c['episodes']}" for c in data["columns"])
        + " |"
    )
    lines += ["", "Evaluations (each file holds its command, seed and date):", ""]
    lines += [f"- {c['label']}: `{c['file']}`: `{c['command']}`" for c in data["columns"]]
    return "\n".join(lines) + "\n"
