"""Every expected failure of the command line: exit status 2, one line on stderr naming the problem and the
input, no traceback, and no file left under the output name (issue 18's probe, as a table)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from explorer.cli import main

ROOT = Path(__file__).resolve().parents[2]
RPC_DIR = ROOT / "tests" / "data" / "rpc"
RPC = RPC_DIR / "rpc_IKONOS.txt"
DIMAP = RPC_DIR / "PHRDIMAP_P1BP--2018122638935449CP.XML"


@pytest.fixture()
def files(tmp_path):
    """Bad inputs written for the test: a text file posing as a DEM, a CSV with a bad number, a tiny image."""
    not_raster = tmp_path / "not_a_dem.tif"
    not_raster.write_text("this is not a GeoTIFF\n")
    bad_csv = tmp_path / "bad.csv"
    bad_csv.write_text("lon,lat,h\n-56.17,-34.90,28\n-56.17,abc,28\n")
    missing_col = tmp_path / "missing.csv"
    missing_col.write_text("lon,h\n-56.17,28\n")
    tiny = tmp_path / "tiny.npy"
    np.save(tiny, np.zeros((48, 48), np.uint8))
    rpc_text = RPC.read_text()
    nan_off = tmp_path / "rpc_nan_line_off.txt"
    nan_off.write_text(rpc_text.replace("LINE_OFF: +005124.00 pixels", "LINE_OFF: NaN pixels"))
    zero_scale = tmp_path / "rpc_zero_samp_scale.txt"
    zero_scale.write_text(rpc_text.replace("SAMP_SCALE: +006334.00 pixels", "SAMP_SCALE: +000000.00 pixels"))
    bad_lat_off = tmp_path / "rpc_lat_off.txt"
    bad_lat_off.write_text(rpc_text.replace("LAT_OFF: -34.90300000 degrees", "LAT_OFF: -134.90300000 degrees"))
    return {"dir": tmp_path, "not_raster": not_raster, "bad_csv": bad_csv, "missing_col": missing_col,
            "tiny": tiny, "nan_off": nan_off, "zero_scale": zero_scale, "bad_lat_off": bad_lat_off}


# (case id, argv template, output that must not exist afterwards, words the message must contain)
CASES = [
    ("rpc-info-nan-line-off", ["rpc", "info", "{nan_off}"], None, ["LINE_OFF"]),
    ("rpc-info-zero-samp-scale", ["rpc", "info", "{zero_scale}"], None, ["SAMP_SCALE"]),
    ("rpc-info-lat-off-out-of-range", ["rpc", "info", "{bad_lat_off}"], None, ["LAT_OFF"]),
    ("rpc-info-missing", ["rpc", "info", "{dir}/nope.txt"], None, ["no such file"]),
    ("rpc-info-directory", ["rpc", "info", "{dir}"], None, ["directory"]),
    ("rpc-project-lat-200", ["rpc", "project", str(RPC), "--lon", "-56.17", "--lat", "200"], None, ["latitude"]),
    ("rpc-project-lon-inf", ["rpc", "project", str(RPC), "--lon", "inf", "--lat", "-34.9"], None, ["finite"]),
    ("rpc-project-lon-nan", ["rpc", "project", str(RPC), "--lon", "nan", "--lat", "-34.9"], None, ["finite"]),
    ("rpc-project-no-point", ["rpc", "project", str(RPC)], None, ["--lon"]),
    ("rpc-project-csv-bad-number", ["rpc", "project", str(RPC), "--points", "{bad_csv}", "--out", "{dir}/o.csv"],
     "{dir}/o.csv", ["line 3", "abc"]),
    ("rpc-project-csv-missing-column", ["rpc", "project", str(RPC), "--points", "{missing_col}"], None, ["lat"]),
    ("rpc-project-out-is-dir", ["rpc", "project", str(RPC), "--points", "{bad_csv}", "--out", "{dir}"], None,
     ["directory"]),
    ("rpc-localize-no-height", ["rpc", "localize", str(RPC), "--row", "1", "--col", "2"], None, ["--h"]),
    ("rpc-localize-dem-not-raster", ["rpc", "localize", str(RPC), "--row", "1", "--col", "2", "--dem",
                                     "{not_raster}"], None, ["raster"]),
    ("scene-from-rpc-dem-not-raster", ["scene", "from-rpc", str(RPC), "--dem", "{not_raster}", "--out",
                                       "{dir}/s.json"], "{dir}/s.json", ["raster"]),
    ("scene-from-rpc-gcps-0", ["scene", "from-rpc", str(RPC), "--gcps", "0", "--out", "{dir}/s.json"],
     "{dir}/s.json", ["--gcps"]),
    ("scene-from-rpc-gcps-negative", ["scene", "from-rpc", str(RPC), "--gcps", "-5"], None, ["--gcps"]),
    ("scene-from-rpc-gcps-huge", ["scene", "from-rpc", str(RPC), "--gcps", "1e12"], None, ["integer"]),
    ("scene-from-rpc-layers-0", ["scene", "from-rpc", str(RPC), "--layers", "0"], None, ["--layers"]),
    ("scene-from-rpc-missing", ["scene", "from-rpc", "{dir}/nope.xml"], None, ["no such file"]),
    ("scene-from-dimap-out-dir", ["scene", "from-dimap", str(DIMAP), "--out", "{dir}"], None, ["directory"]),
    ("ortho-gsd-0", ["ortho", "--preset", "WSU", "--synthetic", "--gsd", "0", "--out", "{dir}/o.tif"],
     "{dir}/o.tif", ["--gsd"]),
    ("ortho-gsd-negative", ["ortho", "--preset", "WSU", "--synthetic", "--gsd", "-1", "--out", "{dir}/o.tif"],
     "{dir}/o.tif", ["--gsd"]),
    ("ortho-gsd-huge", ["ortho", "--preset", "WSU", "--synthetic", "--gsd", "1e9", "--out", "{dir}/o.tif"],
     "{dir}/o.tif", ["--gsd"]),
    ("ortho-scheduler-bogus", ["ortho", "--preset", "WSU", "--synthetic", "--gsd", "5", "--scheduler", "bogus",
                               "--out", "{dir}/o.tif"], "{dir}/o.tif", ["scheduler"]),
    ("ortho-chunk-negative", ["ortho", "--preset", "WSU", "--synthetic", "--gsd", "5", "--chunk", "-5",
                              "--out", "{dir}/o.tif"], "{dir}/o.tif", ["--chunk"]),
    ("ortho-chunk-0", ["ortho", "--preset", "WSU", "--synthetic", "--gsd", "5", "--chunk", "0",
                       "--out", "{dir}/o.tif"], "{dir}/o.tif", ["--chunk"]),
    ("ortho-height-nan", ["ortho", "--preset", "WSU", "--synthetic", "--gsd", "5", "--height", "nan",
                          "--out", "{dir}/o.tif"], "{dir}/o.tif", ["finite"]),
    ("ortho-rpc-shape-abc", ["ortho", "--rpc", str(RPC), "--synthetic", "--rpc-shape", "abc", "--gsd", "5",
                             "--out", "{dir}/o.tif"], "{dir}/o.tif", ["ROWSxCOLS"]),
    ("ortho-rpc-dem-not-raster", ["ortho", "--rpc", str(RPC), "--dem", "{not_raster}", "--synthetic",
                                  "--rpc-shape", "100x100", "--gsd", "5", "--out", "{dir}/o.tif"], "{dir}/o.tif",
     ["raster"]),
    ("ortho-image-wrong-size", ["ortho", "--preset", "WSU", "--image", "{tiny}", "--gsd", "5", "--out",
                                "{dir}/o.tif"], "{dir}/o.tif", ["48 x 48"]),
    ("ortho-image-missing", ["ortho", "--preset", "WSU", "--image", "{dir}/none.tif", "--gsd", "5", "--out",
                             "{dir}/o.tif"], "{dir}/o.tif", ["no such file"]),
    ("ortho-out-dir", ["ortho", "--preset", "WSU", "--synthetic", "--gsd", "5", "--out", "{dir}"], None,
     ["directory"]),
    ("ortho-out-missing-folder", ["ortho", "--preset", "WSU", "--synthetic", "--gsd", "5", "--out",
                                  "{dir}/no/such/o.tif"], "{dir}/no/such/o.tif", ["does not exist"]),
    ("bench-json-dir", ["bench", "--preset", "WSU", "--methods", "nr", "--scps", "100", "--json", "{dir}"], None,
     ["directory"]),
    ("bench-unknown-method", ["bench", "--preset", "WSU", "--methods", "nrr", "--scps", "100", "--no-progress"],
     None, ["nrr"]),
    ("bench-unknown-preset", ["bench", "--preset", "wsux", "--methods", "nr", "--scps", "100", "--no-progress"],
     None, ["wsux"]),
    ("bench-param-malformed", ["bench", "--preset", "WSU", "--methods", "nr", "--scps", "100", "--param", "nr"],
     None, ["--param"]),
    ("bench-scps-0", ["bench", "--preset", "WSU", "--scps", "0"], None, ["--scps"]),
    ("simulate-jitter-inf", ["simulate", "--jitter-scale", "inf", "--out", "{dir}/p.npz"], "{dir}/p.npz",
     ["finite"]),
    ("simulate-n-0", ["simulate", "--n", "0"], None, ["--n"]),
    ("simulate-n-3", ["simulate", "--n", "3", "--out", "{dir}/p.npz"], "{dir}/p.npz", ["4"]),
    ("simulate-unknown-preset", ["simulate", "--preset", "wsux"], None, ["did you mean"]),
    ("simulate-scene-missing", ["simulate", "--scene", "{dir}/nope.json"], None, ["no such file"]),
    ("explore-unknown-preset", ["explore", "--preset", "bogus", "--port", "0"], None, ["unknown preset"]),
    ("explore-port-out-of-range", ["explore", "--port", "70000"], None, ["70000"]),
    ("unknown-command", ["nosuch"], None, ["nosuch"]),
]


@pytest.mark.parametrize(("argv", "output", "words"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_exits_2_with_one_line_and_no_file(argv, output, words, files, capsys):
    subst = {k: str(v) for k, v in files.items()}
    args = [a.format(**subst) for a in argv]
    status = main(args)
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert status == 2, f"exit {status}; stderr: {err}"
    assert len(lines) == 1, f"expected one line on stderr, got:\n{err}"
    assert "Traceback" not in err
    assert lines[0].startswith("pushbroom"), lines[0]
    for word in words:
        assert word.lower() in lines[0].lower(), f"{word!r} not in {lines[0]!r}"
    if output is not None:
        target = Path(output.format(**subst))
        assert not target.exists(), f"{target} was left behind"
        assert not list(target.parent.glob(f".{target.name}.partial-*")) if target.parent.exists() else True


def test_simulate_out_is_written_under_exactly_the_given_name(tmp_path, capsys):
    out = tmp_path / "pts"
    assert main(["simulate", "--preset", "WSU", "--n", "16", "--out", str(out)]) == 0
    assert out.is_file() and not (tmp_path / "pts.npz").exists()
    assert f"wrote {out}" in capsys.readouterr().out
    with np.load(out) as z:
        assert z["ground"].shape == (16, 3)


def test_real_process_exit_status_and_no_traceback(tmp_path):
    """The installed entry point, in a separate process: status 2 and one stderr line."""
    proc = subprocess.run([sys.executable, "-m", "explorer", "ortho", "--preset", "WSU", "--synthetic",
                           "--gsd", "-1", "--out", str(tmp_path / "o.tif")], capture_output=True, text=True)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr
    assert not (tmp_path / "o.tif").exists()


def test_help_of_every_command_exits_0(capsys):
    for argv in (["--help"], ["ortho", "--help"], ["rpc", "project", "--help"], ["scene", "from-rpc", "--help"]):
        assert main(argv) == 0
