"""The executed tutorials in docs/tutorials/ hold the same code as their sources in notebooks/."""

from __future__ import annotations

import pytest

from tests.conftest import docs_script


def _builder():
    return docs_script("build_tutorials")


@pytest.mark.parametrize("source", _builder().notebook_sources(), ids=lambda p: p.stem)
def test_executed_tutorial_matches_its_source(source):
    jupytext = pytest.importorskip("jupytext")
    nbformat = pytest.importorskip("nbformat")
    build = _builder()
    executed = build.TARGET / f"{source.stem}.ipynb"
    assert executed.is_file(), f"{executed} is missing: run python docs/build_tutorials.py {source.stem}"
    nb = nbformat.read(executed, as_version=4)
    assert build.code_cells(nb) == build.code_cells(jupytext.read(source)), (
        f"{executed} is stale: run python docs/build_tutorials.py {source.stem}")
    images = sum("image/png" in out.get("data", {}) for cell in nb.cells if cell.cell_type == "code"
                 for out in cell.get("outputs", []))
    assert images >= 1, f"{executed} holds no figure"
