"""The warm-up covers every preset and the RPC/DEM/ortho kernels, and its steps run."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from explorer.presets import preset_ids
from explorer.warmup import _rpc_for_warmup, _warm_ortho, _warm_rpc, steps


def test_steps_cover_every_preset_and_the_rpc():
    names = [name for name, _ in steps()]
    for pid in preset_ids():
        assert any(name.startswith(f"{pid}:") for name in names), pid
    assert any("rational function model" in name for name in names)
    assert any("relief" in name for name in names)


def test_warmup_model_is_consistent_and_rpc_steps_run():
    rpc = _rpc_for_warmup()
    lon, lat, ok = rpc.localization(np.array([10.0, 900.0]), np.array([20.0, 800.0]), np.array([400.0, 600.0]))
    assert ok.all()
    row, col = rpc.projection(lon, lat, np.array([400.0, 600.0]))
    np.testing.assert_allclose(row, [10.0, 900.0], atol=1e-8)
    np.testing.assert_allclose(col, [20.0, 800.0], atol=1e-8)
    _warm_rpc()
    _warm_ortho()


def test_warmup_command_parses():
    from explorer.commands.warmup import register

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args(["warmup", "--quiet"])
    assert args.quiet and callable(args.func)


def test_stereo_kernels_compile_both_variants_from_one():
    """Which variant of a stereo kernel runs depends on the number of matches: after a small generic-pair
    triangulation (serial variants), compile_parallel_twins gives every parallel twin the serial one's argument
    types -- numba's own list of compiled signatures is the truth."""
    pytest.importorskip("numba")
    from explorer.stereo import _kernels
    from explorer.stereo.triangulation import compile_parallel_twins
    from explorer.warmup import _warm_generic_pair

    _warm_generic_pair()
    parallel, serial = _kernels._closest_approach_parallel, _kernels._closest_approach_serial
    assert serial.signatures
    compile_parallel_twins()
    for par, ser in _kernels.TWINS:
        assert set(ser.signatures) <= set(par.signatures) and set(par.signatures) <= set(ser.signatures)
    assert set(serial.signatures) <= set(parallel.signatures)


def test_warmup_writes_the_bytecode_python_will_read():
    """The first warm-up step writes every module's ``.pyc`` stamped with its source's mtime and size (what Python
    checks before reading it instead of compiling the source), whatever PYTHONDONTWRITEBYTECODE says."""
    import importlib.util
    import os
    import struct
    from pathlib import Path

    import explorer
    from explorer.warmup import _warm_bytecode, compile_bytecode

    assert steps()[0][1] is _warm_bytecode
    assert compile_bytecode()
    sources = sorted(Path(explorer.__file__).parent.rglob("*.py"))
    assert len(sources) > 100
    for src in sources:
        pyc = Path(importlib.util.cache_from_source(str(src)))
        head = pyc.read_bytes()[:16]
        assert head[:4] == importlib.util.MAGIC_NUMBER, src
        flags, mtime, size = struct.unpack("<III", head[4:16])
        st = os.stat(src)
        assert flags == 0 and mtime == int(st.st_mtime) & 0xFFFFFFFF and size == st.st_size & 0xFFFFFFFF, src
