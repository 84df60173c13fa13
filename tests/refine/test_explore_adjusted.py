"""``explore --adjusted SIDECAR`` (issue 28): the explorer opens the adjusted sensor ``pushbroom refine`` wrote
(``adjusted_model.json``) -- its maps are measured against the adjusted model, checked point by point against
:func:`explorer.refine.line_adjust.load_adjusted` --, refuses a base file whose SHA-256 is not the sidecar's in
one line, and opens an adjusted RPC (``adjusted_rpc.txt``, a plain RPC) as ``--rpc``; the RPC's adjustment is
checked against the closed form (the original RPC plus the known shift)."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

from explorer.cli import main  # noqa: E402
from explorer.errors import InputError, SceneFileError  # noqa: E402
from explorer.refine.line_adjust import correction_for, load_adjusted, sidecar_dict, write_sidecar  # noqa: E402
from explorer.sources import load_source  # noqa: E402
from tests.refine.cases import PLEIADES, pleiades, random_ground, simulate_points, write_points_csv  # noqa: E402

DIMAP = Path(__file__).resolve().parents[1] / "data" / "rpc" / "PHRDIMAP_P1BP--2017030824934340CP.XML"
#: along / cross / radial metres, roll / pitch / yaw radians: several pixels on a Pleiades image
PARAMS = np.array([40.0, -25.0, 10.0, 8e-6, -5e-6, 6e-6])


@pytest.fixture(scope="module")
def adjusted_files(tmp_path_factory):
    """A copy of the 2017 Pleiades DIMAP and a sidecar adjusting it by :data:`PARAMS` (position-attitude), beside
    it, as ``pushbroom refine --dimap ... --out DIR`` writes one."""
    folder = tmp_path_factory.mktemp("adjusted")
    base = folder / DIMAP.name
    shutil.copy(DIMAP, base)
    sensor = load_source("dimap", str(base)).scene
    side = write_sidecar(folder / "adjusted_model.json",
                         sidecar_dict(correction_for(sensor, "position-attitude"), PARAMS, None, base_file=base,
                                      source_kind="dimap"))
    return base, side


def _check_ground(sensor, n: int = 200, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.05, 0.95, n) * sensor.n_rows
    c = rng.uniform(0.05, 0.95, n) * sensor.n_columns
    return sensor.image_to_ground(r, c, height=float(sensor.terrain.mean_height) + rng.uniform(-300, 300, n))


@pytest.mark.parametrize("alone", [True, False])
def test_the_explorer_source_is_the_adjusted_sensor(adjusted_files, alone):
    """``--adjusted S`` alone (the base file found beside the sidecar by its recorded name) or with ``--dimap X``:
    the source projects every point as ``load_adjusted`` does (bit for bit), several pixels from the base file's
    sensor, and says it is adjusted."""
    from argparse import Namespace

    from explorer.sources import source_from_args

    base, side = adjusted_files
    args = Namespace(adjusted=str(side), dimap=None if alone else str(base))
    src = source_from_args(args)
    truth = load_adjusted(side)
    g = _check_ground(truth)
    got, want = src.scene.ground_to_image(g), truth.ground_to_image(g)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    unadjusted = load_source("dimap", str(base)).scene.ground_to_image(g)
    moved = np.hypot(got[0] - unadjusted[0], got[1] - unadjusted[1])
    assert moved.min() > 1.0  # the adjustment matters: several pixels on every point
    assert src.kind == "dimap" and src.label.endswith(", adjusted)")
    assert src.info["adjusted"]["correction"] == "position-attitude"
    assert src.info["adjusted"]["parameters"]["roll_rad"] == PARAMS[3]
    assert "adjusted by adjusted_model.json" in src.info["truth"]


def test_explore_export_measures_against_the_adjusted_model(adjusted_files, tmp_path):
    """``pushbroom explore --adjusted S --export DIR``: every check point's exact image position in
    ``residuals.csv`` is the adjusted model's (``load_adjusted`` at the written ECEF point; to the file's
    print precision), the summary names the sidecar."""
    base, side = adjusted_files
    out = tmp_path / "out"
    assert main(["explore", "--adjusted", str(side), "--export", str(out), "--scps", "1000", "--scops", "30",
                 "--methods", "lrm", "--no-sweep"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["source"]["adjusted"]["sidecar"] == str(side)
    with open(out / "residuals.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["method"] == "lrm"]
    assert len(rows) > 500
    ecef = np.array([[float(r["x_m"]), float(r["y_m"]), float(r["z_m"])] for r in rows])
    truth = load_adjusted(side)
    row, col = truth.ground_to_image(truth.frame.ecef_to_enu(ecef))
    written = np.array([[float(r["row_px"]), float(r["col_px"])] for r in rows])
    np.testing.assert_allclose(written[:, 0], row, atol=2e-6)
    np.testing.assert_allclose(written[:, 1], col, atol=2e-6)
    base_row, base_col = load_source("dimap", str(base)).scene.ground_to_image(truth.frame.ecef_to_enu(ecef))
    assert np.hypot(written[:, 0] - base_row, written[:, 1] - base_col).min() > 1.0


def test_a_base_file_that_is_not_the_adjusted_one_is_one_line(adjusted_files, tmp_path, capsys):
    base, side = adjusted_files
    other = tmp_path / base.name
    other.write_bytes(base.read_bytes() + b" ")  # one byte more: another file for the hash
    shutil.copy(side, tmp_path / side.name)
    for argv in (["--adjusted", str(tmp_path / side.name)], ["--dimap", str(other), "--adjusted", str(side)]):
        assert main(["explore", *argv, "--export", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("pushbroom explore: error: ")
        assert err[0].endswith(f"{other} is not the file this adjustment was made on (SHA-256 differs)"), err
    assert not (tmp_path / "out").exists()
    with pytest.raises(SceneFileError, match="SHA-256"):
        load_source("dimap", str(other), adjusted=str(side))


@pytest.mark.parametrize("kind, message", [
    ("rpc", "--adjusted goes with --dimap, --dg or --isd"),
    ("isd", "adjusts a --dimap file, not a --isd one"),
])
def test_adjusted_with_another_source_kind_is_refused(adjusted_files, kind, message):
    _, side = adjusted_files
    path = {"rpc": PLEIADES, "isd": Path(__file__).resolve().parents[1] / "data" / "usgscsm" / "orbitalLineScan.json"}
    with pytest.raises(InputError, match=message):
        load_source(kind, str(path[kind]), adjusted=str(side))


def test_an_adjusted_rpc_opens_in_explore(tmp_path):
    """``refine --rpc`` writes ``adjusted_rpc.txt``, a plain RPC: ``explore --rpc`` opens it (the source and an
    export), and it projects as the original RPC plus the known shift (closed form; a shift folds exactly)."""
    rpc = pleiades()
    shift = np.array([4.2, -3.1])
    gcps = write_points_csv(tmp_path / "g.csv", simulate_points(rpc, 12, model="shift", params=shift, noise_px=0.0,
                                                                seed=4))
    out = tmp_path / "adj"
    assert main(["refine", str(PLEIADES), "--gcps", str(gcps), "--model", "shift", "--out", str(out),
                 "--no-panels"]) == 0
    adjusted = out / "adjusted_rpc.txt"
    src = load_source("rpc", str(adjusted))
    lon, lat, h = random_ground(rpc, 50, np.random.default_rng(9)).T
    row, col = src.scene.ground_to_image(src.scene.frame.geodetic_to_enu(lon, lat, h))
    want_row, want_col = rpc.projection(lon, lat, h)
    np.testing.assert_allclose(row, want_row + shift[0], atol=1e-6)
    np.testing.assert_allclose(col, want_col + shift[1], atol=1e-6)
    assert main(["explore", "--rpc", str(adjusted), "--export", str(tmp_path / "x"), "--scps", "1000",
                 "--scops", "30", "--methods", "lrm", "--no-sweep"]) == 0
    assert json.loads((tmp_path / "x" / "summary.json").read_text())["source"]["kind"] == "rpc"


def test_bad_sidecars_are_one_line(adjusted_files, tmp_path, capsys):
    """Not a sidecar, a sidecar alone whose base file is not beside it, a sidecar with --pair: one line each."""
    _, side = adjusted_files
    isd = Path(__file__).resolve().parents[1] / "data" / "usgscsm" / "orbitalLineScan.json"
    moved = tmp_path / "moved.json"
    shutil.copy(side, moved)  # without its base file
    cases = [(["--adjusted", str(isd)], "not an adjusted line-scanner sidecar"),
             (["--adjusted", str(moved)], "is not there (give its path)"),
             (["--pair", str(PLEIADES), str(PLEIADES), "--adjusted", str(side)], "not a --pair")]
    for argv, message in cases:
        assert main(["explore", *argv, "--export", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], (argv, err)
    assert not (tmp_path / "out").exists()
