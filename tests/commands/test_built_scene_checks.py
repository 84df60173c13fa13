"""Scenes built in memory pass the physical checks of a scene file (issue 25, class 5; docs/validation.md).

``bench``, ``explore``, ``simulate`` and ``scene from-*`` build their scene from an RPC (``--as-mpc``), a DIMAP or a
DigitalGlobe file without any JSON in between; an impossible model must be refused there as it is when read
from JSON: exit status 2, one stderr line naming the file and the rule, nothing written, the input untouched.

Truth: the rule each mutation breaks -- an RPC whose heights sit 50 km up (no terrain is there), an ephemeris
scaled by 0.9 about the Earth's centre (7 km below the ellipsoid at its lowest: PROJ-free closed form of the
geodetic height), attitude quaternions of norm 2 -- and the unmutated files, which still build.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from explorer.cli import main
from explorer.geometry.frames import ecef_to_geodetic
from tests.commands._hostile import assert_one_line_refusal, snapshot

ROOT = Path(__file__).resolve().parents[2]
RPC_DIR = ROOT / "tests" / "data" / "rpc"
IKONOS = RPC_DIR / "rpc_IKONOS.txt"
DIMAP = RPC_DIR / "PHRDIMAP_P1BP--2018122638935449CP.XML"
WV1 = RPC_DIR / "rpc_WV1.xml"


def _scaled_positions(text: str, pattern: str, factor: float, columns: slice) -> str:
    def scale(m: re.Match) -> str:
        values = m.group(2).split()
        values[columns] = [f"{float(v) * factor:.6f}" for v in values[columns]]
        return m.group(1) + " ".join(values) + m.group(3)

    out, n = re.subn(pattern, scale, text)
    assert n > 3
    return out


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("built")
    out = {}
    out["rpc_50km"] = folder / "rpc_50km.txt"
    out["rpc_50km"].write_text(re.sub(r"HEIGHT_OFF: [^\n]*", "HEIGHT_OFF: +50000.000 meters", IKONOS.read_text()))
    dimap = DIMAP.read_text()
    out["dimap_inside"] = folder / "PHRDIMAP_inside.XML"
    out["dimap_inside"].write_text(_scaled_positions(dimap, r'(<LOCATION_VALUES unit="m">)([^<]*)(<)', 0.9,
                                                     slice(0, 3)))
    out["dimap_quaternion"] = folder / "PHRDIMAP_quaternion.XML"
    out["dimap_quaternion"].write_text(_scaled_positions(dimap, r"(<Q_VALUES>)([^<]*)(<)", 2.0, slice(0, 4)))
    out["dg_inside"] = folder / "WV1_inside.xml"
    out["dg_inside"].write_text(_scaled_positions(WV1.read_text(), r"(<EPHEMLIST>)([^<]*)(<)", 0.9, slice(1, 4)))
    out["dir"] = folder
    return out


def test_the_mutations_are_what_they_claim():
    """The 0.9 ephemeris is below the ellipsoid (so below any terrain) while the original is 694 km up."""
    pos = np.array([[float(v) for v in m.split()] for m in
                    re.findall(r'<LOCATION_VALUES unit="m">([^<]*)<', DIMAP.read_text())])
    _, _, h = ecef_to_geodetic(pos)
    _, _, h_scaled = ecef_to_geodetic(0.9 * pos)
    assert h.min() > 600e3 and h_scaled.min() < -1000.0


CASES = [
    ("bench-rpc-50km", ["bench", "--rpc", "{rpc_50km}", "--as-mpc", "--methods", "nr", "--scps", "100",
                        "--no-progress"],
     ["rpc_50km.txt", "terrain", "50000"]),
    ("from-rpc-50km", ["scene", "from-rpc", "{rpc_50km}", "--out", "{dir}/x.json"], ["rpc_50km.txt", "terrain"]),
    ("explore-rpc-50km", ["explore", "--rpc", "{rpc_50km}", "--as-mpc", "--export", "{dir}/e"],
     ["rpc_50km.txt", "terrain"]),
    ("bench-dimap-inside", ["bench", "--dimap", "{dimap_inside}", "--methods", "nr", "--scps", "100",
                            "--no-progress"], ["PHRDIMAP_inside.XML", "inside the Earth"]),
    ("from-dimap-inside", ["scene", "from-dimap", "{dimap_inside}", "--out", "{dir}/x.json"],
     ["PHRDIMAP_inside.XML", "ephemeris point", "below the WGS84 ellipsoid"]),
    ("simulate-dimap-quaternion", ["simulate", "--dimap", "{dimap_quaternion}", "--n", "10"],
     ["PHRDIMAP_quaternion.XML", "quaternion", "norm 2"]),
    ("from-dg-inside", ["scene", "from-dg", "{dg_inside}", "--out", "{dir}/x.json"],
     ["WV1_inside.xml", "inside the Earth"]),
    ("explore-dg-inside", ["explore", "--dg", "{dg_inside}", "--export", "{dir}/e"], ["WV1_inside.xml", "Earth"]),
]


@pytest.mark.parametrize(("argv", "words"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_an_impossible_built_scene_is_one_line_and_writes_nothing(files, argv, words, capsys):
    args = [a.format(**{k: str(v) for k, v in files.items()}) for a in argv]
    before = snapshot(files["dir"])
    assert_one_line_refusal(main(args), capsys.readouterr().err, words)
    assert snapshot(files["dir"]) == before
