"""Execute the tutorial notebooks (``notebooks/*.py``, jupytext percent format) and write them with
their outputs and figures to ``docs/tutorials/<name>.ipynb``, so they can be read without running.

    python docs/build_tutorials.py [--full] [NAME ...]

By default the notebooks run in their fast mode (``FUSIONGS_NOTEBOOK_FAST=1``: tiny sizes and
iterations, a few minutes in all on 2 cores); ``--full`` runs them as a user would. Each notebook
runs in a temporary working folder; the written file's code cells are the source's, unchanged
(``tests/test_tutorials_doc.py`` checks that they stay in step).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ROOT / "notebooks"
TARGET = ROOT / "docs" / "tutorials"


def notebook_sources() -> list[Path]:
    """The tutorial sources, ``notebooks/NN_*.py``, in order."""
    return sorted(SOURCES.glob("[0-9]*.py"))


def code_cells(nb) -> list[str]:
    """The source text of every code cell of a notebook (nbformat node)."""
    return [cell.source for cell in nb.cells if cell.cell_type == "code"]


def build(source: Path, fast: bool) -> Path:
    """Execute one notebook in a temporary folder and write it with its outputs; returns the path."""
    import jupytext
    import nbclient
    import nbformat

    nb = jupytext.read(source)
    env = {"FUSIONGS_NOTEBOOK_FAST": "1"} if fast else {}
    old = {k: os.environ.get(k) for k in [*env, "PYTHONPATH"]}
    os.environ.update(env)
    os.environ["PYTHONPATH"] = str(ROOT) + (os.pathsep + old["PYTHONPATH"] if old["PYTHONPATH"] else "")
    try:
        with tempfile.TemporaryDirectory() as work:
            client = nbclient.NotebookClient(nb, timeout=3600, kernel_name="python3",
                                             resources={"metadata": {"path": work}})
            start = time.perf_counter()
            client.execute()
            print(f"{source.name}: executed in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    nb.metadata.pop("jupytext", None)
    TARGET.mkdir(parents=True, exist_ok=True)
    out = TARGET / f"{source.stem}.ipynb"
    tmp = out.with_suffix(".ipynb.tmp")
    nbformat.write(nb, tmp)
    tmp.replace(out)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="notebook stems to build (default: all)")
    ap.add_argument("--full", action="store_true", help="run at full size instead of the fast mode")
    args = ap.parse_args(argv)
    for source in notebook_sources():
        if not args.names or source.stem in args.names:
            print(build(source, fast=not args.full))
    return 0


if __name__ == "__main__":
    sys.exit(main())
