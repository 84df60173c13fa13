"""New instances of the classes of issue 25, written for this round (not the cases the issue listed): other
encodings, other special paths (sockets, symlinks to devices, dangling links), other absurd numbers and sizes,
other option combinations.  Each must end as exit status 2 and one stderr line naming the input, with no
traceback and nothing written or changed in the folder; the valid ones (a UTF-32 scene or CSV) must work.

Truth: the rule each input breaks, stated by the case (a step giving 1.6e15 grid nodes, a NUL byte in a text file,
a socket where a file is expected...).
"""

from __future__ import annotations

import hashlib
import os
import socket
import stat
from pathlib import Path

import pytest

from explorer.cli import main
from explorer.presets import build_scene
from tests.commands._hostile import assert_one_line_refusal, snapshot

ROOT = Path(__file__).resolve().parents[2]
RPC_DIR = ROOT / "tests" / "data" / "rpc"
IKONOS = str(RPC_DIR / "rpc_IKONOS.txt")
GEOMS = [str(RPC_DIR / f"PHR1B_P_20170928103{n}_SEN_PRG_FC_17860{k}-001.geom") for n, k in (("8045", 8), ("8393", 9))]


@pytest.fixture()
def folder(tmp_path):
    text = build_scene("WSU").to_json()
    (tmp_path / "utf32.json").write_bytes(text.encode("utf-32"))
    (tmp_path / "nul.json").write_bytes(text.encode()[:500] + b"\x00" * 10 + text.encode()[500:])
    (tmp_path / "pts_utf32.csv").write_bytes("lon,lat,h\n-56.17,-34.90,28\n".encode("utf-32"))
    (tmp_path / "pts_1e400.csv").write_text("lon,lat,h\n-56.17,-34.90,1e400\n")
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(tmp_path / "sock"))
    os.symlink("/dev/null", tmp_path / "link_null")
    os.symlink("/dev/zero", tmp_path / "link_zero")
    os.symlink(tmp_path / "nowhere.json", tmp_path / "dangling")
    os.mkfifo(tmp_path / "fifo.csv")
    yield tmp_path
    sock.close()


CASES = [
    ("nul-byte-in-scene", ["simulate", "--scene", "{d}/nul.json", "--n", "4"], ["nul.json", "binary"]),
    ("stereo-step-1e-3", ["stereo", "grids", *GEOMS, "--height", "100", "--step", "0.001", "--out", "{d}/g"],
     ["step 0.001", "--step", "memory"]),
    ("csv-1e400", ["rpc", "project", IKONOS, "--points", "{d}/pts_1e400.csv"], ["pts_1e400.csv", "line 2", "finite"]),
    ("gsd-1e308", ["ortho", "--preset", "WSU", "--synthetic", "--gsd", "1e308", "--out", "{d}/o.tif"], ["--gsd"]),
    ("dem-datum-navd88", ["rpc", "localize", IKONOS, "--row", "1", "--col", "1", "--h", "0", "--dem-datum",
                          "navd88"], ["--dem-datum", "navd88"]),
    ("dem-datum-without-dem", ["explore", "--preset", "WSU", "--dem-datum", "egm96", "--export", "{d}/e"],
     ["--dem-datum", "--dem"]),
    ("socket-as-scene", ["simulate", "--scene", "{d}/sock"], ["sock", "socket"]),
    ("socket-as-out", ["simulate", "--n", "4", "--out", "{d}/sock"], ["sock", "socket"]),
    ("symlink-to-dev-null-as-out", ["simulate", "--n", "4", "--out", "{d}/link_null"], ["link_null", "device"]),
    ("symlink-to-dev-zero-as-rpc", ["rpc", "info", "{d}/link_zero"], ["link_zero", "device"]),
    ("dangling-symlink-as-scene", ["simulate", "--scene", "{d}/dangling"], ["dangling", "no such file"]),
    ("dev-zero-as-dem", ["rpc", "localize", IKONOS, "--row", "1", "--col", "1", "--dem", "/dev/zero"],
     ["/dev/zero", "device"]),
    ("fifo-as-points", ["rpc", "project", IKONOS, "--points", "{d}/fifo.csv"], ["fifo.csv", "FIFO"]),
    ("out-is-the-input-csv", ["rpc", "project", IKONOS, "--points", "{d}/pts_utf32.csv", "--out",
                              "{d}/pts_utf32.csv"], ["pts_utf32.csv", "input"]),
    ("report-is-the-input-rpc", ["scene", "from-rpc", IKONOS, "--report", IKONOS], ["--report", "input"]),
]


@pytest.mark.parametrize(("argv", "words"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_new_instance_exits_2_with_one_line_and_touches_nothing(folder, argv, words, capsys):
    args = [a.format(d=folder) for a in argv]
    before = snapshot(folder)
    ikonos_before = hashlib.sha256(Path(IKONOS).read_bytes()).hexdigest()
    try:
        status = main(args)
    except SystemExit as exc:  # argparse
        status = exc.code
    assert_one_line_refusal(status, capsys.readouterr().err, words)
    assert snapshot(folder) == before
    assert hashlib.sha256(Path(IKONOS).read_bytes()).hexdigest() == ikonos_before
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_utf32_scene_and_csv_are_read(folder, capsys):
    assert main(["simulate", "--scene", str(folder / "utf32.json"), "--n", "4"]) == 0
    assert main(["rpc", "project", IKONOS, "--points", str(folder / "pts_utf32.csv")]) == 0
    assert "True" in capsys.readouterr().out
