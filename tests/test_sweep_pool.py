"""explorer.app.sweep_pool: the export's accuracy-vs-SCOPs sweep shared with a second (spawned) process gives the
same files, byte for byte, as the serial sweep (the independent truth: ``workers=1``, the path used before), and
a worker that cannot start or dies leaves its jobs to the caller."""

from __future__ import annotations

import json

import numpy as np
import pytest

from explorer.app import export as export_module
from explorer.app.model import ExplorerModel, Settings
from explorer.app.sweep_pool import SweepPool
from explorer.presets import build_scene

RUN_DEPENDENT = ("timing.json", "timing.js")
SETTINGS = Settings(preset="WSU", scop_density=50, scp_count=3000, methods=("lrm", "prm", "ann", "ogp", "nr"),
                    color_method="lrm", sweep=True)


@pytest.fixture(scope="module")
def scene():
    return build_scene("WSU", relief_m=300.0, relief_seed=1)


def test_parallel_sweep_export_equals_the_serial_one_bit_for_bit(scene, monkeypatch):
    delivered: list[int] = []
    collect = SweepPool.collect

    def spy(self):
        out = collect(self)
        delivered.append(len(out))
        return out

    monkeypatch.setattr(SweepPool, "collect", spy)
    serial = export_module.export_files(scene, SETTINGS, source={"label": "WSU"}, seed=3, workers=1)
    assert delivered == []  # serial: no pool
    parallel = export_module.export_files(scene, SETTINGS, source={"label": "WSU"}, seed=3, workers=2)
    assert len(delivered) == 1 and delivered[0] >= 1  # the worker computed some of the sweep
    for name in serial:
        if name not in RUN_DEPENDENT:
            assert parallel[name] == serial[name], name
    sweep = json.loads(serial["summary.json"])["accuracy_vs_scops"]
    assert [p["n_scops"] for p in sweep["ogp"]] == [10, 20, 30, 50, 100, 300, 500, 1000]
    assert len(sweep["nr"]) == 1  # a fit-free method: one point


def _sweeps_equal(a: dict, b: dict) -> None:
    assert list(a) == list(b)
    for name in a:
        assert [e.n_scops for e in a[name]] == [e.n_scops for e in b[name]]
        for x, y in zip(a[name], b[name], strict=True):
            assert np.array_equal(x.residual_row, y.residual_row, equal_nan=True)
            assert np.array_equal(x.residual_col, y.residual_col, equal_nan=True)


def _serial(scene, s):
    model = ExplorerModel(preview_after_s=None, seed=3, scenes={s.preset: scene})
    return {name: model.sweep(name, s) for name in s.methods}


def test_a_worker_that_dies_leaves_its_jobs_to_the_caller(scene):
    s = Settings(preset="WSU", scop_density=50, scp_count=3000, methods=("lrm", "ann"), sweep=True)
    model = ExplorerModel(preview_after_s=None, seed=3, scenes={s.preset: scene})
    pool = SweepPool(scene, s, 3, model.sweep_points, export_module._pool_jobs(model, s))
    assert pool._process is not None
    pool._process.kill()  # before it delivered anything
    pool._process.join(30)
    sweeps, failed = export_module._sweep_with_pool(model, pool, s)
    assert pool.error and "ended" in pool.error
    _sweeps_equal(sweeps, _serial(scene, s))


def test_a_sensor_that_does_not_pickle_is_swept_by_the_caller_alone(scene):
    s = Settings(preset="WSU", scop_density=50, scp_count=3000, methods=("lrm",), sweep=True)
    model = ExplorerModel(preview_after_s=None, seed=3, scenes={s.preset: scene})
    unpicklable = lambda: None  # noqa: E731
    pool = SweepPool(unpicklable, s, 3, model.sweep_points, export_module._pool_jobs(model, s))
    assert pool._process is None and "does not pickle" in str(pool.error)
    assert [pool.claim() for _ in range(len(pool.jobs) + 2)] == [*range(len(pool.jobs)), None, None]
    pool2 = SweepPool(unpicklable, s, 3, model.sweep_points, export_module._pool_jobs(model, s))
    sweeps, _ = export_module._sweep_with_pool(model, pool2, s)
    _sweeps_equal(sweeps, _serial(scene, s))


def test_the_worker_runs_on_while_the_caller_is_busy(scene):
    """A result (5,000 check points' residuals) is larger than a pipe's buffer: the caller reads the worker's
    results as they come (a reader thread), so the worker goes on to its next job while the caller is still busy
    with the maps -- before, it blocked on its first result until the caller collected."""
    import time

    s = Settings(preset="WSU", scop_density=50, scp_count=10_000, methods=("lrm", "prm"), sweep=True)
    model = ExplorerModel(preview_after_s=None, seed=3, scenes={s.preset: scene})
    pool = SweepPool(scene, s, 3, model.sweep_points, export_module._pool_jobs(model, s))
    try:
        deadline = time.monotonic() + 120.0
        while pool._counter.value <= len(pool.jobs) and time.monotonic() < deadline:  # the caller claims nothing
            time.sleep(0.1)
        assert pool._counter.value > len(pool.jobs), "the worker stopped before taking every job"
        results = pool.collect()
    finally:
        pool.close()
    assert sorted(results) == list(range(len(pool.jobs)))
    assert all(kind == "ok" and value.n_evaluated == 5000 for kind, value in results.values())


def test_no_worker_when_memory_is_short(scene, monkeypatch):
    """Below WORKER_MEMORY available (PUSHBROOM_MEMORY_LIMIT, the memory guard's figure) the caller sweeps alone."""
    monkeypatch.setenv("PUSHBROOM_MEMORY_LIMIT", "1G")
    s = Settings(preset="WSU", scop_density=50, scp_count=3000, methods=("lrm",), sweep=True)
    model = ExplorerModel(preview_after_s=None, seed=3, scenes={s.preset: scene})
    pool = SweepPool(scene, s, 3, model.sweep_points, export_module._pool_jobs(model, s))
    assert pool._process is None and "of memory available" in str(pool.error)
    sweeps, _ = export_module._sweep_with_pool(model, pool, s)
    _sweeps_equal(sweeps, _serial(scene, s))


def test_a_script_without_a_main_guard_is_not_run_again_by_the_worker(tmp_path):
    """A spawned child imports the parent's main script first; a user's script calling ``run_export`` without an
    ``if __name__ == "__main__":`` guard was run again, whole, in the worker (the export computed twice, the
    script's top-level line printed by two processes). The script here prints its process id at top level and
    counts the sweep jobs the worker delivered: one process runs the script, and the worker still works."""
    import subprocess
    import sys

    script = tmp_path / "no_guard.py"
    script.write_text(
        "import os\n"
        "import explorer.app.sweep_pool as sp\n"
        "from explorer.app.export import run_export\n"
        "from explorer.sources import load_source\n"
        "collect = sp.SweepPool.collect\n"
        "def spy(self):\n"
        "    out = collect(self)\n"
        "    print('DELIVERED', len(out), self.error, flush=True)\n"
        "    return out\n"
        "sp.SweepPool.collect = spy\n"
        "print('TOP LEVEL', os.getpid(), flush=True)\n"
        f"run_export(load_source('preset', 'WSU'), {str(tmp_path / 'out')!r}, methods=['lrm', 'ann'], scps=2000,\n"
        "           workers=2, log=lambda line: None)\n")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.splitlines()
    assert len([ln for ln in lines if ln.startswith("TOP LEVEL")]) == 1, out.stdout
    delivered = [ln.split() for ln in lines if ln.startswith("DELIVERED")]
    assert len(delivered) == 1 and int(delivered[0][1]) >= 1 and delivered[0][2] == "None", out.stdout
    assert (tmp_path / "out" / "summary.json").exists()
