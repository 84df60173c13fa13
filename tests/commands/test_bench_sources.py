"""``pushbroom bench`` on file sources (the same resolution as ``explore``: explorer.sources)."""

from __future__ import annotations

import json
from pathlib import Path

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
