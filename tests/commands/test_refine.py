"""``pushbroom refine``: files written, summary printed, one-line errors for bad input."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("torch")

from explorer.cli import main  # noqa: E402
from tests.refine.cases import PLEIADES, pleiades, simulate_points, write_points_csv  # noqa: E402


@pytest.fixture(scope="module")
def gcps(tmp_path_factory):
    folder = tmp_path_factory.mktemp("refine_cli")
    rpc = pleiades()
    return (write_points_csv(folder / "gcps.csv", simulate_points(rpc, 20, seed=1)),
            write_points_csv(folder / "check.csv", simulate_points(rpc, 30, seed=2, prefix="c")))


def test_refine_writes_the_report(gcps, tmp_path, capsys):
    control, check = gcps
    out = tmp_path / "out"
    assert main(["refine", str(PLEIADES), "--gcps", str(control), "--check", str(check), "--model", "affine",
                 "--sigma-px", "0.3", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["model"] == "affine"
    assert report["check_rmse_px"] < 0.5 < report["check_rmse_px_before"]
    assert (out / "adjusted_rpc.txt").exists() and (out / "points.csv").exists()
    assert "row_per_row" in (out / "panels.html").read_text()
    assert "row_per_row" in capsys.readouterr().out


@pytest.mark.parametrize("extra, message", [
    (["--model", "poly2"], "too few control points: the poly2 model has 12 parameters"),
    (["--model", "attitude"], "unknown RPC correction model 'attitude'"),  # an RPC has image-space models
    (["--ties", "{gcps}"], "--ties needs two images"),
])
def test_refine_bad_input_is_one_line(gcps, tmp_path, capsys, extra, message):
    control, _ = gcps
    few = tmp_path / "few.csv"
    few.write_text("\n".join(control.read_text().splitlines()[:6]) + "\n")
    args = ["refine", str(PLEIADES), "--gcps", str(few), "--out", str(tmp_path / "o")]
    assert main(args + [a.format(gcps=control) for a in extra]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_refine_images_with_ties(tmp_path, capsys):
    import numpy as np

    from explorer.rpc import read_rpc
    from tests.refine.cases import PAIR, simulate_pair_points

    rpcs = [read_rpc(p) for p in PAIR]
    rng = np.random.default_rng(9)
    ties = simulate_pair_points(rpcs, 40, ground_known=False, prefix="t", rng=rng)
    gcps = simulate_pair_points(rpcs, 5, ground_known=True, prefix="g", rng=rng)
    (tmp_path / "ties.csv").write_text("id,image,row,col\n" + "".join(
        f"{i},{PAIR[int(k)].name},{r:.4f},{c:.4f}\n" for i, k, r, c in zip(ties.ids, ties.image, ties.row, ties.col,
                                                                          strict=True)))
    write_points_csv(tmp_path / "gcps.csv", gcps, image=gcps.image)
    out = tmp_path / "ba"
    assert main(["refine", "--images", *map(str, PAIR), "--ties", str(tmp_path / "ties.csv"), "--gcps",
                 str(tmp_path / "gcps.csv"), "--sigma-px", "0.3", "--no-panels", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert not (out / "panels.html").exists()
    assert len(report["parameters"]) == 12 and report["tie_rmse_px"] < 0.3
    assert (out / "adjusted_rpc_0.txt").exists() and (out / "adjusted_rpc_1.txt").exists()
    assert main(["refine", str(PAIR[0]), "--images", str(PAIR[1]), "--gcps", str(tmp_path / "gcps.csv"),
                 "--out", str(out)]) == 2
    assert "not both" in capsys.readouterr().err


def test_refine_scene_attitude(tmp_path):
    """An MPC scene file moved by known offsets: ``--model attitude`` writes the adjusted scene sidecar."""
    import numpy as np

    from explorer.presets import build_scene
    from explorer.real.linescan import load_scene
    from explorer.refine.points_io import PointTable
    from explorer.refine.torch_scene import adjusted_scene

    scene = build_scene("WSU")
    scene.save(tmp_path / "scene.json")
    true = np.array([3.0, -2.0, 1.0, 1e-5, -1e-5, 2e-5])
    rng = np.random.default_rng(3)
    n = 30
    ground = scene.image_to_ground(rng.uniform(0, scene.n_rows - 1, n), rng.uniform(0, scene.n_columns - 1, n),
                                   height=rng.uniform(-50, 50, n))
    row, col = adjusted_scene(scene, "attitude", true).ground_to_image(ground)
    lon, lat, h = scene.frame.enu_to_geodetic(ground)
    write_points_csv(tmp_path / "gcps.csv", PointTable([f"g{i}" for i in range(n)], row + rng.normal(0, 0.3, n),
                                                      col + rng.normal(0, 0.3, n), lon, lat, h))
    out = tmp_path / "out"
    assert main(["refine", str(tmp_path / "scene.json"), "--gcps", str(tmp_path / "gcps.csv"), "--model",
                 "attitude", "--sigma-px", "0.3", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert [p["name"] for p in report["parameters"]][:3] == ["position_e_m", "position_n_m", "position_u_m"]
    assert report["control_rmse_px"] < 0.4 < report["control_rmse_px_before"]
    adjusted = load_scene(out / "adjusted_scene.json")
    values = np.array([p["value"] for p in report["parameters"]])
    np.testing.assert_allclose(adjusted.exterior.position_coeffs[:, 0],
                               scene.exterior.position_coeffs[:, 0] + values[:3], rtol=0, atol=1e-9)


def test_list_options_before_the_source_leave_the_source_alone():
    """``--model`` / ``--kinds`` / ``--jitter-hz`` take one comma-separated token: written before SOURCE they do not
    swallow the file name (with nargs="+" ``refine --model affine X.xml`` lost its SOURCE)."""
    from explorer.cli import build_parser

    args = build_parser().parse_args(["refine", "--model", "affine", str(PLEIADES), "--gcps", str(PLEIADES),
                                      "--out", "o"])
    assert args.source == str(PLEIADES) and args.model == ["affine"]
    args = build_parser().parse_args(["refine", "--kinds", "dimap,rpc", "--model", "attitude,affine",
                                      "--jitter-hz", "0.5,1", "--images", str(PLEIADES), str(PLEIADES), "--out", "o"])
    assert args.kinds == ["dimap", "rpc"] and args.model == ["attitude", "affine"] and args.jitter_hz == [0.5, 1.0]
    for bad in (["--model", "affine,,shift"], ["--model", "afine"], ["--kinds", "dimap,raw"], ["--jitter-hz", "1,-2"]):
        with pytest.raises(SystemExit):
            build_parser().parse_args(["refine", str(PLEIADES), *bad])
