"""``pushbroom scene from-rpc / from-dg / from-dimap`` through the real CLI entry point."""

import json

from explorer.cli import main
from explorer.scene import Scene

from .conftest import PHR_2018, RPC_DIR, WV1


def test_from_rpc_writes_a_scene_and_a_report(tmp_path, capsys):
    out, rep = tmp_path / "s.json", tmp_path / "r.json"
    argv = ["scene", "from-rpc", str(RPC_DIR / "rpc_PLEIADES.xml"), "--gcps", "40", "--check", "60",
            "--degree", "3", "--out", str(out), "--report", str(rep)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "GCPs: RMSE" in text and "check points: RMSE" in text
    scene = Scene.load(out)
    assert scene.shape == (36176, 40000)
    report = json.loads(rep.read_text())
    assert report["rmse_px"] < 0.01 and len(report["gcp_row_residual_px"]) == report["n_gcps"]


def test_from_rpc_with_a_preset_fixes_the_focal_length(tmp_path, capsys):
    out = tmp_path / "s.json"
    assert main(["scene", "from-rpc", str(RPC_DIR / "rpc_WV1.xml"), "--preset", "WBU", "--gcps", "40",
                 "--check", "0", "--out", str(out)]) == 0
    assert "focal fixed" in capsys.readouterr().out
    from explorer.presets import preset_spec

    assert Scene.load(out).interior.focal_length_m == preset_spec("WBU")["focal_length_m"]


def test_from_dg_and_from_dimap(tmp_path, capsys):
    out = tmp_path / "wv1.json"
    assert main(["scene", "from-dg", str(WV1), "--compare-points", "60", "--compare-layers", "2",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "rigorous model vs RPC" in text and Scene.load(out).n_rows == 26828
    rig = tmp_path / "phr_rigorous.json"
    assert main(["scene", "from-dimap", str(PHR_2018), "--no-compare", "--rigorous-out", str(rig)]) == 0
    assert "calibrated on the RPC" in capsys.readouterr().out
    from explorer.real import load_scene

    assert load_scene(rig).n_columns == 40000


def test_missing_file_is_a_clear_error(capsys):
    assert main(["scene", "from-rpc", "no_such_file.xml"]) == 2
    assert "error" in capsys.readouterr().err
