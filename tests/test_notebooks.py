"""Every notebook under notebooks/ executes (they keep their settings small), and the committed
copies are the executed ones (``python notebooks/execute.py`` refreshes them)."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = sorted((Path(__file__).parent.parent / "notebooks").glob("*.ipynb"))


def test_notebooks_are_numbered_and_committed_executed():
    assert NOTEBOOKS
    for number, path in enumerate(NOTEBOOKS, 1):
        assert path.name.startswith(f"{number:02d}_"), path.name
        book = nbformat.read(path, as_version=4)
        code = [c for c in book.cells if c.cell_type == "code"]
        assert code and all(c.execution_count is not None for c in code), f"{path.name} is not committed executed"
        assert any(o.get("output_type") in ("stream", "display_data", "execute_result") for c in code for o in c.outputs)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_executes(path, tmp_path):
    book = nbformat.read(path, as_version=4)
    NotebookClient(book, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
