"""Execute every teaching notebook (jupytext percent files) at its small CI size."""

import os
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).parent.parent / "notebooks").glob("[0-9][0-9]_*.py"))


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path, monkeypatch):
    jupytext = pytest.importorskip("jupytext")
    nbclient = pytest.importorskip("nbclient")
    monkeypatch.setenv("PUSHBROOM_NB_SMALL", "1")
    nb = jupytext.read(path)
    first = nb.cells[0].source if nb.cells else ""
    assert first.lstrip().startswith("# 0"), "a notebook opens with its title and what it teaches"
    assert any("Exercises" in c.source for c in nb.cells if c.cell_type == "markdown"), "ends with exercises"
    assert any("parameters" in c.metadata.get("tags", []) for c in nb.cells), "one parameter cell"
    client = nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                     resources={"metadata": {"path": str(path.parent)}})
    client.execute(env={**os.environ, "PUSHBROOM_NB_SMALL": "1"})
