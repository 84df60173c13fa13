"""The explorer's Refinement folder: live re-adjustment when the model or the dropped points change."""

from __future__ import annotations

import pytest

pytest.importorskip("torch")
viser = pytest.importorskip("viser")

from explorer.app.refine_view import RefineView  # noqa: E402
from tests.refine.cases import pleiades, simulate_points  # noqa: E402


@pytest.fixture
def server():
    srv = viser.ViserServer(host="127.0.0.1", port=8181, verbose=False)
    yield srv
    srv.stop()


def test_refine_folder_readjusts_live(server):
    rpc = pleiades()
    control = simulate_points(rpc, 12, seed=1, prefix="g")
    view = RefineView(server.gui, rpc, control, simulate_points(rpc, 30, seed=2, prefix="c"), sigma_px=0.3)
    assert view.error is None and view.refinement.model == "affine"
    assert len(view.quiver.figure.data) > 0 and "affine" in view.summary.content
    view.model.value = "shift"
    view.update()
    assert view.refinement.model == "shift" and len(view.refinement.parameters) == 2
    view.drop.value = "g0, g5"
    view.update()
    assert view.refinement.result.outlier.size == 10
    ids = {r["id"] for r in view.refinement.points_rows() if r["role"] == "control"}
    assert "g0" not in ids and "g5" not in ids
    view.model.value = "poly2"
    view.drop.value = ",".join(f"g{i}" for i in range(7))  # 5 points left for 12 parameters
    view.update()
    assert view.error.startswith("too few control points") and "Not adjusted" in view.summary.content
    view.drop.value = "nope"
    view.update()
    assert view.error == "no control point nope"
    assert view.refinement.model == "poly2"  # the last good adjustment (poly2 on 10 points) stays shown


def test_explore_gcps_refuses_a_source_it_cannot_refine(tmp_path, capsys):
    from explorer.cli import main
    from tests.refine.cases import write_points_csv

    gcps = write_points_csv(tmp_path / "g.csv", simulate_points(pleiades(), 5, seed=1))
    assert main(["explore", "--preset", "WSU", "--gcps", str(gcps), "--port", "8182"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].endswith("--gcps refines --rpc or --scene sources, not --preset")
