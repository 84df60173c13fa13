"""Issue 25, the second round of hostile inputs: every class of failure ends as exit status 2 and one stderr line
naming the input, with no traceback, nothing written outside the output and the input untouched.

Each case is an instance of a class (docs/validation.md): physically impossible models (RPC, scene JSON, DEM),
unreadable text, sizes the machine cannot hold, special files, outputs over inputs or devices, numbers out of
range.  Truth: the rule the input breaks (a negative scale, a latitude of 95 degrees...) is stated by the case;
the check is that the command names it and leaves every file as it was.
"""

from __future__ import annotations

import json
import os
import re
import stat
from pathlib import Path

import numpy as np
import pytest

from explorer.cli import main
from explorer.presets import build_scene
from tests.commands._hostile import assert_one_line_refusal, snapshot

ROOT = Path(__file__).resolve().parents[2]
RPC_DIR = ROOT / "tests" / "data" / "rpc"
IKONOS = RPC_DIR / "rpc_IKONOS.txt"
GEOM = RPC_DIR / "PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.geom"
DIMAP = RPC_DIR / "PHRDIMAP_P1BP--2018122638935449CP.XML"


def _sub(text: str, pattern: str, repl: str) -> str:
    out, n = re.subn(pattern, repl, text)
    assert n, pattern
    return out


@pytest.fixture()
def hostile(tmp_path):
    """The hostile files of the table, written into tmp_path."""
    ikonos = IKONOS.read_text()
    files = {
        "rpc_neg_line_scale.txt": _sub(ikonos, r"LINE_SCALE: \+?", "LINE_SCALE: -"),
        "rpc_neg_height_scale.txt": _sub(ikonos, r"HEIGHT_SCALE: \+?", "HEIGHT_SCALE: -"),
        "rpc_tiny_lat_scale.txt": _sub(ikonos, r"LAT_SCALE: [^\n]*", "LAT_SCALE: 1e-12 degrees"),
        "rpc_zero_numerators.txt": _sub(ikonos, r"(LINE_NUM_COEFF_\d+): [^\n]*", r"\1: +0.0"),
        "rpc_21_coefficients.txt": ikonos + "SAMP_NUM_COEFF_21: +1.000000E-03\n",
        "rpc_key_twice.txt": ikonos + "LAT_OFF: +12.5 degrees\n",
        # cut inside the last coefficient's exponent: "+1.929684859424581E-0" is a number too
        "rpc_cut_in_a_number.txt": ikonos[: ikonos.index("SAMP_DEN_COEFF_20") + 40],
    }
    paths = {}
    for name, text in files.items():
        (tmp_path / name).write_text(text)
        paths[name.removesuffix(".txt")] = tmp_path / name
    geom = GEOM.read_bytes()
    for pct in (50, 90):
        p = tmp_path / f"cut{pct}_{GEOM.name}"
        p.write_bytes(geom[: len(geom) * pct // 100])
        paths[f"geom{pct}"] = p
    binary = tmp_path / "junk.txt"
    binary.write_bytes(bytes(range(256)) * 8)
    paths["junk"] = binary
    base = json.loads(build_scene("WSU").to_json())
    for name, edit in {
        "lat95": lambda d: d["frame"].update(lat0_deg=95.0),
        "pitch": lambda d: d["interior"].update(detector_pitch_m=1e-300),
        "below": lambda d: d["exterior"]["position_coeffs"][2].__setitem__(0, -5000.0),
        "focal0": lambda d: d["interior"].update(focal_length_m=0.0),
    }.items():
        d = json.loads(json.dumps(base))
        edit(d)
        paths[f"scene_{name}"] = tmp_path / f"scene_{name}.json"
        paths[f"scene_{name}"].write_text(json.dumps(d))
    good = tmp_path / "scene_ok.json"
    good.write_text(json.dumps(base))
    paths["scene_ok"] = good
    (tmp_path / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    paths["deep"] = tmp_path / "deep.json"
    (tmp_path / "long_number.json").write_text(json.dumps(base).replace('"n_rows": 3996', '"n_rows": ' + "9" * 5000))
    paths["long_number"] = tmp_path / "long_number.json"
    n = 1201
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    (100 + i + 2 * j).astype("<i2").tofile(tmp_path / "N43E007.hgt")  # little-endian: refused
    paths["hgt_le"] = tmp_path / "N43E007.hgt"
    (100 + i + 2 * j).astype(">i2").tofile(tmp_path / "tile.hgt")
    paths["hgt_badname"] = tmp_path / "tile.hgt"
    fifo = tmp_path / "pipe.txt"
    os.mkfifo(fifo)
    paths["fifo"] = fifo
    isd = tmp_path / "isd.json"
    isd.write_bytes((ROOT / "tests" / "data" / "usgscsm" / "orbitalLineScan.json").read_bytes())
    paths["isd"] = isd
    paths["dir"] = tmp_path
    return paths


# (case id, argv template, words the one line must contain)
CASES = [
    ("rpc-negative-line-scale", ["rpc", "info", "{rpc_neg_line_scale}"], ["LINE_SCALE", "positive"]),
    ("rpc-negative-height-scale", ["rpc", "project", "{rpc_neg_height_scale}", "--lon", "-56.17", "--lat",
                                   "-34.9"], ["HEIGHT_SCALE"]),
    ("rpc-tiny-lat-scale", ["rpc", "info", "{rpc_tiny_lat_scale}"], ["LAT_SCALE"]),
    ("rpc-zero-numerators", ["rpc", "info", "{rpc_zero_numerators}"], ["LINE_NUM_COEFF", "degenerate"]),
    ("rpc-21st-coefficient", ["rpc", "info", "{rpc_21_coefficients}"], ["21st"]),
    ("rpc-key-twice", ["rpc", "info", "{rpc_key_twice}"], ["LAT_OFF", "twice"]),
    ("rpc-cut-in-a-number", ["rpc", "info", "{rpc_cut_in_a_number}"], ["truncated"]),
    ("geom-cut-at-50", ["rpc", "info", "{geom50}"], ["cut50"]),
    ("geom-cut-at-90", ["rpc", "info", "{geom90}"], ["type"]),
    ("rpc-binary", ["rpc", "info", "{junk}"], ["binary"]),
    ("rpc-fifo", ["rpc", "info", "{fifo}"], ["FIFO"]),
    ("rpc-dev-null", ["rpc", "info", "/dev/null"], ["device"]),
    ("scene-latitude-95", ["simulate", "--scene", "{scene_lat95}"], ["lat0_deg", "95"]),
    ("scene-pitch-1e-300", ["simulate", "--scene", "{scene_pitch}"], ["detector_pitch_m"]),
    ("scene-below-ground", ["simulate", "--scene", "{scene_below}"], ["terrain"]),
    ("scene-below-ground-bench", ["bench", "--scene", "{scene_below}", "--methods", "nr", "--scps", "100"],
     ["terrain"]),
    ("scene-focal-0", ["simulate", "--scene", "{scene_focal0}"], ["focal_length_m"]),
    ("scene-deep-json", ["simulate", "--scene", "{deep}"], ["nested"]),
    ("scene-5000-digits", ["simulate", "--scene", "{long_number}"], ["number literal"]),
    ("scene-fifo", ["simulate", "--scene", "{fifo}"], ["FIFO"]),
    ("hgt-little-endian", ["rpc", "localize", str(IKONOS), "--row", "10", "--col", "10", "--dem", "{hgt_le}"],
     ["N43E007.hgt", "little-endian"]),
    ("hgt-not-named-like-a-tile", ["rpc", "localize", str(IKONOS), "--row", "10", "--col", "10", "--dem",
                                   "{hgt_badname}"], ["tile.hgt", "N43E007"]),
    ("simulate-n-1e9", ["simulate", "--n", "1000000000"], ["--n", "GiB"]),
    ("explore-scps-1e9", ["explore", "--scps", "1000000000", "--export", "{dir}/e"], ["--scps", "GiB"]),
    ("from-dimap-compare-1e8", ["scene", "from-dimap", str(DIMAP), "--compare-points", "1000000",
                                "--compare-layers", "100"], ["--compare-points", "GiB"]),
    ("rpc-project-h-1e308", ["rpc", "project", str(IKONOS), "--lon", "-56.17", "--lat", "-34.9", "--h", "1e308"],
     ["--h"]),
    ("explore-seed-negative", ["explore", "--seed", "-1", "--export", "{dir}/e"], ["--seed"]),
    ("explore-seed-2-64", ["explore", "--seed", str(2**64), "--export", "{dir}/e"], ["--seed"]),
    ("explore-methods-empty", ["explore", "--methods", "", "--export", "{dir}/e"], ["--methods"]),
    ("bench-seed-2-64", ["bench", "--seed", str(2**64), "--scps", "100"], ["--seed"]),
    ("bench-param-unknown-name", ["bench", "--preset", "WSU", "--methods", "nr", "--scps", "100", "--param",
                                  "nr.bogus=1", "--no-progress"], ["nr.bogus"]),
    ("bench-param-wrong-type", ["bench", "--preset", "WSU", "--methods", "nr", "--scps", "100", "--param",
                                "nr.max_iter=1.5", "--no-progress"], ["nr.max_iter", "integer"]),
    ("bench-param-refused-value", ["bench", "--preset", "WSU", "--methods", "nr", "--scps", "100", "--param",
                                   "nr.tol_px=-1", "--no-progress"], ["nr.tol_px"]),
    ("bench-param-not-benchmarked", ["bench", "--preset", "WSU", "--methods", "nr", "--scps", "100", "--param",
                                     "lrm.column=true", "--no-progress"], ["lrm"]),
    ("out-dev-null", ["simulate", "--n", "16", "--out", "/dev/null"], ["/dev/null", "device"]),
    ("out-fifo", ["simulate", "--n", "16", "--out", "{fifo}"], ["FIFO"]),
    ("out-is-the-input", ["simulate", "--scene", "{scene_ok}", "--n", "16", "--out", "{scene_ok}"], ["input"]),
    ("from-isd-out-is-the-input", ["scene", "from-isd", "{isd}", "--out", "{isd}"], ["--out", "input"]),
    ("from-isd-out-dev-null", ["scene", "from-isd", "{isd}", "--out", "/dev/null"], ["device"]),
    ("explore-export-dev-null", ["explore", "--export", "/dev/null"], ["/dev/null", "not a folder"]),
    ("explore-export-into-a-file", ["explore", "--export", "{isd}"], ["not a folder"]),
    ("out-equals-report", ["scene", "from-rpc", str(IKONOS), "--out", "{dir}/x.json", "--report",
                           "{dir}/x.json"], ["--out", "--report"]),
]


@pytest.mark.parametrize(("argv", "words"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_hostile_input_exits_2_with_one_line_and_touches_nothing(argv, words, hostile, capsys):
    subst = {k: str(v) for k, v in hostile.items()}
    args = [a.format(**subst) for a in argv]
    before = snapshot(hostile["dir"])
    null_before = os.stat("/dev/null")
    status = main(args)
    assert_one_line_refusal(status, capsys.readouterr().err, words)
    assert snapshot(hostile["dir"]) == before, "a file was written, changed or removed"
    now = os.stat("/dev/null")
    assert stat.S_ISCHR(now.st_mode) and now.st_rdev == null_before.st_rdev


def test_encodings_of_a_valid_scene_are_read(tmp_path, capsys):
    """UTF-16 (with and without a byte-order mark), UTF-8 with a BOM and Latin-1 scene JSON: the same scene."""
    scene = build_scene("WSU")
    text = scene.to_json().replace('"name": "WSU"', '"name": "WSU café"')
    for encoding in ("utf-16", "utf-16-le", "utf-16-be", "utf-8-sig", "latin-1"):
        path = tmp_path / f"{encoding}.json"
        path.write_bytes(text.encode(encoding))
        assert main(["simulate", "--scene", str(path), "--n", "16"]) == 0, capsys.readouterr().err
        assert "WSU café" in capsys.readouterr().out


def test_encodings_of_a_valid_csv_are_read(tmp_path, capsys):
    """A UTF-8 BOM, UTF-16 and Latin-1 CSV of points give the same rows and columns as the UTF-8 one."""
    text = "lon, lat ,h\n-56.17,-34.90,28\n-56.16,-34.91,30\n"
    outputs = []
    for encoding in ("utf-8", "utf-8-sig", "utf-16", "latin-1"):
        path = tmp_path / f"{encoding}.csv"
        path.write_bytes(text.encode(encoding))
        assert main(["rpc", "project", str(IKONOS), "--points", str(path)]) == 0
        outputs.append(capsys.readouterr().out)
    assert all(o == outputs[0] for o in outputs) and outputs[0].count("True") == 2


def test_rigorous_scene_with_a_reflection_or_late_tables_is_refused(tmp_path, capsys):
    """A rigorous line-scan scene (the Pleiades DIMAP's) reads; with its sensor-to-body matrix turned into a
    reflection, or its ephemeris cut to start after the image, it is refused by name."""
    from explorer.real.dimap import rigorous_scene_from_dimap

    model, _ = rigorous_scene_from_dimap(RPC_DIR / "PHRDIMAP_P1BP--2017030824934340CP.XML")
    good = tmp_path / "rigorous.json"
    model.save(good)
    assert main(["simulate", "--scene", str(good), "--n", "16"]) == 0
    d = json.loads(good.read_text())
    m = d["exterior"]["sensor_to_body"]
    reflected = json.loads(json.dumps(d))
    reflected["exterior"]["sensor_to_body"] = [[-v for v in m[0]], m[1], m[2]]
    late = json.loads(json.dumps(d))
    eph = late["exterior"]["ephemeris"]
    n = len(eph["time_s"])
    for key, value in eph.items():
        if isinstance(value, list) and len(value) == n:
            eph[key] = value[n // 2 + 1:]
    capsys.readouterr()
    for name, doc, words in (("reflected", reflected, ["reflection"]), ("late", late, ["ephemeris", "extrapolated"])):
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps(doc))
        assert main(["simulate", "--scene", str(path), "--n", "16"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and path.name in err[0] and all(w in err[0] for w in words), err
