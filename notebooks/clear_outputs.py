"""Clears the outputs and execution counts of the notebooks, as they are committed.

.venv/bin/python notebooks/clear_outputs.py [NOTEBOOK ...]   (default: all here)
"""

from __future__ import annotations

import sys
from pathlib import Path

import nbformat


def clear_outputs(path: Path) -> bool:
    """Clears ``path`` in place; returns whether anything changed."""
    notebook = nbformat.read(path, as_version=nbformat.NO_CONVERT)
    changed = False
    for cell in notebook.cells:
        if cell.cell_type != "code":
            continue
        if cell.outputs or cell.execution_count is not None:
            cell.outputs, cell.execution_count = [], None
            changed = True
        # Jupyter's per-cell run state (collapsed/scrolled/execution times) is noise.
        for key in ("execution", "collapsed", "scrolled"):
            changed |= cell.metadata.pop(key, None) is not None
    if changed:
        nbformat.write(notebook, path)
    return changed


if __name__ == "__main__":
    paths = [Path(p) for p in sys.argv[1:]] or sorted(Path(__file__).parent.glob("*.ipynb"))
    for path in paths:
        print(f"{'cleared' if clear_outputs(path) else 'clean  '} {path}")
