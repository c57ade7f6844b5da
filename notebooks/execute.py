"""Execute every notebook here in place, so that the committed notebooks show their outputs.

    python notebooks/execute.py            # all of them
    python notebooks/execute.py 03_bevo_quickstart.ipynb

The test suite executes them too (in a temporary folder, without writing), and checks that every
committed notebook was executed.
"""

from __future__ import annotations

import sys
from pathlib import Path

import nbformat
from nbclient import NotebookClient

HERE = Path(__file__).resolve().parent


def execute(path: Path) -> None:
    book = nbformat.read(path, as_version=4)
    NotebookClient(book, timeout=1200, kernel_name="python3", resources={"metadata": {"path": str(HERE)}}).execute()
    nbformat.validate(book)
    nbformat.write(book, path)
    print(f"executed {path.name}")


def main(names: list[str]) -> int:
    paths = [HERE / n for n in names] if names else sorted(HERE.glob("*.ipynb"))
    for path in paths:
        execute(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
