"""The notebooks run top to bottom with their tiny default budget, write nothing into
``results/``, ``models/`` or ``notebooks/``, and are saved with their outputs cleared.

Each notebook runs in a fresh ``python3`` kernel (jupyter_client starts it with this
interpreter, so it sees the same installed packages); about 20-60 s each on 2 cores.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import nbformat
import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK_DIR = ROOT / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
EXPECTED = [
    "01_compose.ipynb",
    "02_demonstrate_and_fit.ipynb",
    "03_train.ipynb",
    "04_evaluate.ipynb",
]
#: Longest a single cell may take with the tiny budget, s (the slowest, evaluation of
#: two policies on 3 episodes each, takes about 15 s).
CELL_TIMEOUT_S = 300
#: Longest a whole notebook may take with the tiny budget, s.
NOTEBOOK_BUDGET_S = 120
KERNEL = "python3"


def _tree_snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    """Every file under ``folder`` with its size and modification time."""
    return {
        str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in folder.rglob("*")
        if p.is_file() and "__pycache__" not in p.parts
    }


def test_the_four_notebooks_are_there():
    assert [p.name for p in NOTEBOOKS] == EXPECTED


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_is_saved_without_outputs(path):
    notebook = nbformat.read(path, as_version=nbformat.NO_CONVERT)
    nbformat.validate(notebook)
    assert notebook.metadata["kernelspec"]["name"] == KERNEL
    code_cells = [cell for cell in notebook.cells if cell.cell_type == "code"]
    assert code_cells, f"{path.name} has no code"
    for index, cell in enumerate(notebook.cells):
        if cell.cell_type != "code":
            continue
        assert cell.outputs == [], f"{path.name} cell {index} has saved outputs"
        assert cell.execution_count is None, f"{path.name} cell {index} has an execution count"
    # The parameter cell near the top: tiny budget unless RLFD_NOTEBOOK_FULL=1.
    assert 'os.environ.get("RLFD_NOTEBOOK_FULL", "0") == "1"' in "".join(
        cell.source for cell in code_cells[:2]
    ), f"{path.name} lacks the FULL_RUN parameter cell near the top"


def _require_kernel() -> None:
    from jupyter_client.kernelspec import KernelSpecManager, NoSuchKernel

    try:
        KernelSpecManager().get_kernel_spec(KERNEL)
    except NoSuchKernel:
        pytest.fail(
            f"no Jupyter kernel {KERNEL!r}: install the dev extra (pip install -e '.[dev]', "
            "which brings ipykernel) so that notebooks can be executed",
            pytrace=False,
        )


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs_top_to_bottom(path, monkeypatch):
    from nbclient import NotebookClient

    _require_kernel()
    # The kernel inherits this environment: force the tiny budget.
    monkeypatch.setenv("RLFD_NOTEBOOK_FULL", "0")
    guarded = {name: _tree_snapshot(ROOT / name) for name in ("results", "models", "notebooks")}
    notebook = nbformat.read(path, as_version=4)
    client = NotebookClient(
        notebook,
        timeout=CELL_TIMEOUT_S,
        kernel_name=KERNEL,
        resources={"metadata": {"path": str(NOTEBOOK_DIR)}},
    )
    start = time.perf_counter()
    client.execute()  # raises CellExecutionError, naming the cell, on any error
    elapsed = time.perf_counter() - start

    errors = [
        output
        for cell in notebook.cells
        if cell.cell_type == "code"
        for output in cell.outputs
        if output.output_type == "error"
    ]
    assert not errors, json.dumps(errors, indent=1)[:2000]
    for name, before in guarded.items():
        after = _tree_snapshot(ROOT / name)
        changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
        assert not changed, f"{path.name} wrote into {name}/: {changed}"
    assert elapsed < NOTEBOOK_BUDGET_S, f"{path.name} took {elapsed:.0f} s with the tiny budget"


def test_clear_outputs_script_restores_the_committed_form(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "clear_outputs", NOTEBOOK_DIR / "clear_outputs.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    original = NOTEBOOKS[0].read_text()
    notebook = nbformat.reads(original, as_version=nbformat.NO_CONVERT)
    code = next(cell for cell in notebook.cells if cell.cell_type == "code")
    code.outputs = [nbformat.v4.new_output("stream", name="stdout", text="ran\n")]
    code.execution_count = 1
    code.metadata["execution"] = {"iopub.status.idle": "2026-11-22T00:00:00Z"}
    executed = tmp_path / NOTEBOOKS[0].name
    nbformat.write(notebook, executed)
    assert module.clear_outputs(executed)
    assert executed.read_text() == original
    assert not module.clear_outputs(executed)
