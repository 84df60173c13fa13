"""``pushbroom bench`` on file sources (the same resolution as ``explore``: explorer.sources)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from explorer.cli import main

ROOT = Path(__file__).resolve().parents[2]
ISD = ROOT / "tests" / "data" / "usgscsm" / "orbitalLineScan.json"


def _runs(path: Path) -> dict[str, dict]:
    return {r["method"]: r for r in json.loads(path.read_text())["runs"]}


def test_bench_on_an_isd_and_on_the_scene_json_it_writes(tmp_path, capsys):
    out_isd, scene_json, out_scene = tmp_path / "isd.json", tmp_path / "scene.json", tmp_path / "scene_bench.json"
    assert main(["bench", "--isd", str(ISD), "--methods", "exact,nr", "--scops", "30", "--scps", "900",
                 "--no-progress", "--json", str(out_isd)]) == 0
    runs = _runs(out_isd)
    # the SCPs are simulated on the scene itself, so the exact method must reproduce their rows
    assert runs["exact"]["rmse_px"] < 1e-9 and runs["nr"]["rmse_px"] < 1e-6
    assert runs["exact"]["preset"].startswith("orbitalLineScan.json")

    assert main(["scene", "from-isd", str(ISD), "--out", str(scene_json)]) == 0
    assert main(["bench", "--scene", str(scene_json), "--methods", "exact", "--scops", "30", "--scps", "900",
                 "--no-progress", "--json", str(out_scene)]) == 0
    # the scene JSON is the same MPC scene: identical SCPs and identical exact rows
    assert _runs(out_scene)["exact"]["n_scps"] == runs["exact"]["n_scps"]
    assert abs(_runs(out_scene)["exact"]["rmse_px"] - runs["exact"]["rmse_px"]) < 1e-12


def test_bench_refuses_two_sources(tmp_path, capsys):
    assert main(["bench", "--preset", "WSU", "--isd", str(ISD), "--scps", "100"]) == 2
    assert "one source" in capsys.readouterr().err


def test_bench_on_an_isd_whose_second_line_rate_runs_past_the_tables(tmp_path, capsys):
    """Issue 25 class 1: an HRSC-like ISD (two line rates, 4 x 4 summing; the second segment runs past the position
    and pointing tables) benches on the covered lines and says so; the MPC stand-in's error there is reported as
    it is, checked against the camera's own ground to image (usgscsm's model) at the same check points."""
    from explorer.points import simulate_points
    from explorer.real.csm import camera_from_isd
    from explorer.real.csm_scene import scene_from_camera
    from explorer.real.csm_sensor import csm_scene
    from tests.real.test_csm_tables import hrsc_like

    isd = tmp_path / "hrsc_like.json"
    isd.write_text(json.dumps(hrsc_like()))
    out = tmp_path / "bench.json"
    assert main(["bench", "--isd", str(isd), "--methods", "exact,csm-secant,lrm", "--scops", "30", "--scps", "900",
                 "--no-progress", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "ephemeris tables cover 83.3 % of the lines (0-2347): the other lines are flagged" in printed
    doc = json.loads(out.read_text())
    assert doc["table_coverage"]["fraction"] == 2347 / 2816 and doc["table_coverage"]["lines"] == [[0.0, 2347.0]]
    runs = {r["method"]: r for r in doc["runs"]}
    for name in ("exact", "csm-secant"):  # the camera's own lines on every check point
        assert runs[name]["valid_frac"] == 1.0 and runs[name]["rmse_px"] < 1e-6, runs[name]
    assert runs["lrm"]["n_scps"] == runs["exact"]["n_scps"] > 0
    # the stand-in's error, recomputed from the camera itself at the bench's own check points
    camera = camera_from_isd(hrsc_like(), source=str(isd))
    scene = csm_scene(camera)
    check = simulate_points(scene, 900, kind="scp", seed=0)
    assert scene.rows_covered(check.row).all()  # check points only on covered lines
    truth = camera.ground_to_image(scene.to_body_fixed(check.ground))
    assert truth.valid.all()
    mpc = scene_from_camera(camera, degree=3, n_check=0)
    row, _ = mpc.ground_to_image(mpc.frame.ecef_to_enu(scene.to_body_fixed(check.ground)))
    err = row - (truth.line - 0.5)
    stand_in = doc["stand_in"]
    assert stand_in["n"] == len(check)
    assert abs(stand_in["max_row_px"] - np.max(np.abs(err))) < 1e-6 * max(1.0, np.max(np.abs(err)))
    assert abs(stand_in["rmse_row_px"] - np.sqrt(np.mean(err**2))) < 1e-6 * max(1.0, np.max(np.abs(err)))
    assert f"row RMSE {stand_in['rmse_row_px']:.4g} px, max {stand_in['max_row_px']:.4g} px" in printed
