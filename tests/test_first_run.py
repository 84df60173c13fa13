"""A user's first run after set-up compiles nothing (issues 23 and 25, class 9).

``./run.sh setup`` ends with ``pushbroom warmup``.  Here the warm-up runs once into an empty numba cache of its
own (``NUMBA_CACHE_DIR``: other tests running at the same time cannot fill it for us), then every command is run
the way a user first runs it, each in a fresh process watching numba's ``numba:compile`` event (fired when numba
really compiles, never when it loads a kernel from its cache; :mod:`tests.compile_watch`).  The truth is numba's
own account of what it compiled, not a wall time.  ``warmup --check`` must then agree: nothing missing.
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.compile_watch import ROOT, run_counting_compiles

pytestmark = pytest.mark.slow

ISD = "tests/data/usgscsm/ctxLineScan.json"
RPC = "tests/data/rpc/rpc_PLEIADES.xml"
DIMAP = "assets/rpc/PHRDIMAP_P1BP--2018122638935449CP.XML"
DIMAP_DEM = "assets/dem/MNT_P1BP--2018122638935449CP.tif"
LEFT = "assets/rpc/RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML"
RIGHT = "assets/rpc/RPC_PHR1B_P_201709281038393_SEN_PRG_FC_178609-001.XML"

#: Each command as a user first runs it (default sizes where they decide which kernel variant runs).
COMMANDS = {
    "explore --preset": ["explore", "--preset", "WSU", "--export", "{out}/e"],
    "explore --isd": ["explore", "--isd", ISD, "--export", "{out}/e"],
    "explore --rpc": ["explore", "--rpc", RPC, "--methods", "lrm,prm,rfm", "--export", "{out}/e"],
    "explore --dimap --dem": ["explore", "--dimap", DIMAP, "--dem", DIMAP_DEM, "--export", "{out}/e"],
    "bench --isd": ["bench", "--isd", ISD, "--methods", "exact,csm-secant,nr", "--scps", "3000", "--no-progress"],
    "bench --preset relief": ["bench", "--preset", "agile", "--relief", "500", "--methods", "exact,csm-secant,nr,lrm",
                              "--scps", "3000", "--no-progress"],
    "ortho --preset": ["ortho", "--preset", "WSU", "--synthetic", "--gsd", "20", "--out", "{out}/o.tif"],
    "ortho --rpc --dem": ["ortho", "--rpc", DIMAP, "--rpc-shape", "2000x2000", "--synthetic", "--gsd", "10", "--dem",
                          DIMAP_DEM, "--out", "{out}/o.tif"],
    "stereo triangulate": ["stereo", "triangulate", LEFT, RIGHT, "--matches", "{matches}", "--out", "{out}/p.csv"],
    "refine": ["refine", DIMAP, "--gcps", "{gcps}", "--model", "affine", "--no-panels", "--out", "{out}/r"],
    "scene from-isd": ["scene", "from-isd", ISD, "--out", "{out}/s.json"],
}


@pytest.fixture(scope="module")
def warmed(tmp_path_factory) -> dict[str, str]:
    """The environment of a set-up that has run ``pushbroom warmup`` into its own, initially empty, numba cache."""
    cache = tmp_path_factory.mktemp("numba_cache")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    env.pop("EXPLORER_DISABLE_NUMBA", None)
    run = subprocess.run([sys.executable, "-m", "explorer", "warmup", "--quiet"], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=3600)
    assert run.returncode == 0, run.stderr[-3000:]
    assert any(cache.rglob("*.nbi")), "the warm-up wrote nothing into NUMBA_CACHE_DIR"
    return {"NUMBA_CACHE_DIR": str(cache)}


def _matches(path: Path) -> Path:
    """2,000 matches of the packaged Pleiades pair (its own RPC projections of random ground points)."""
    from explorer import read_rpc

    left, right = read_rpc(ROOT / LEFT), read_rpc(ROOT / RIGHT)
    rng = np.random.default_rng(7)
    n = 2000
    lon, lat, h = rng.uniform(7.1, 7.25, n), rng.uniform(43.64, 43.71, n), rng.uniform(100, 1000, n)
    lr, lc = left.projection(lon, lat, h)
    rr, rc = right.projection(lon, lat, h)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "left_row", "left_col", "right_row", "right_col"])
        for i in range(n):
            w.writerow([i, *(repr(float(v[i])) for v in (lr, lc, rr, rc))])
    return path


def _gcps(path: Path) -> Path:
    """20 control points of the DIMAP's RPC (its own projections, an affine bias added: tests/refine/cases.py)."""
    from explorer import read_rpc
    from tests.refine.cases import simulate_points, write_points_csv

    return write_points_csv(path, simulate_points(read_rpc(ROOT / DIMAP), 20, seed=1))


@pytest.mark.parametrize("name", list(COMMANDS))
def test_first_run_after_warmup_compiles_nothing(name, warmed, tmp_path):
    argv = [a.format(out=tmp_path, matches=tmp_path / "m.csv", gcps=tmp_path / "g.csv") for a in COMMANDS[name]]
    if "{matches}" in COMMANDS[name]:
        _matches(tmp_path / "m.csv")
    if "{gcps}" in COMMANDS[name]:
        _gcps(tmp_path / "g.csv")
    run = run_counting_compiles(argv, env=warmed)
    assert run.rc == 0, run.stderr[-3000:]
    assert run.compiled == [], f"{name} compiled after the warm-up: {run.compiled}"
    assert "compiling kernels for first use" not in run.stderr


def test_check_after_warmup_finds_nothing_missing(warmed):
    """``pushbroom warmup --check`` after the warm-up: every kernel of the manifest cached, no package kernel
    outside the manifest left uncompiled (it would compile at first use)."""
    check = subprocess.run([sys.executable, "-m", "explorer", "warmup", "--check"], cwd=ROOT,
                           env=dict(os.environ, **warmed), capture_output=True, text=True, timeout=600)
    assert check.returncode == 0, check.stderr
    assert "are in numba's cache" in check.stdout and "nothing will compile" in check.stdout, check.stdout
