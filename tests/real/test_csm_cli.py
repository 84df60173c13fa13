"""``pushbroom scene from-isd`` through the real CLI entry point."""

import json
from pathlib import Path

import numpy as np

from explorer.cli import main
from explorer.real.csm import body_fixed_to_enu, read_isd
from explorer.scene import Scene

DATA = Path(__file__).resolve().parents[1] / "data" / "usgscsm"


def test_from_isd_writes_a_scene_that_matches_the_camera(tmp_path, capsys):
    out, rep = tmp_path / "orbital.json", tmp_path / "r.json"
    assert main(["scene", "from-isd", str(DATA / "orbitalLineScan.json"), "--out", str(out), "--report",
                 str(rep)]) == 0
    text = capsys.readouterr().out
    assert "CSM line scanner" in text and "MPC fit" in text
    scene = Scene.load(out)
    assert scene.shape == (16, 16)
    report = json.loads(rep.read_text())
    assert report["csm_fit"]["row_max_px"] < 0.05
    # the written scene maps the CSM camera's ground points to (line - 0.5, sample - 0.5)
    cam = read_isd(DATA / "orbitalLineScan.json")
    g = cam.image_to_ground([8.0], [8.0], 0.0).ground
    col = scene.column_at_row(body_fixed_to_enu(scene, g), np.array([7.5]))
    assert abs(col[0] - 7.5) < 0.05


def test_from_isd_errors_are_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    isd = json.loads((DATA / "orbitalLineScan.json").read_text())
    isd["optical_distortion"] = {"cahvor": {"coefficients": [1.0]}}
    bad.write_text(json.dumps(isd))
    assert main(["scene", "from-isd", str(bad), "--out", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err
    assert "cahvor" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.json").exists()
