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


#: lines of a script that print ``DELIVERED <results> <error>`` when the sweep pool collects its worker's results
_SPY_COLLECT = ("collect = sp.SweepPool.collect\n"
                "def spy(self):\n"
                "    out = collect(self)\n"
                "    print('DELIVERED', len(out), self.error, flush=True)\n"
                "    return out\n"
                "sp.SweepPool.collect = spy\n")


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
        + _SPY_COLLECT +
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


def test_an_early_worker_gives_the_serial_export_bit_for_bit(scene, monkeypatch):
    """``explore --export`` starts the worker before the source is loaded (SweepPool.early: it imports meanwhile)
    and gives it the jobs once the sensor is there: the files are the serial export's (the independent truth,
    ``workers=1``), the pool reports no error, and it is closed by the export."""
    errors: list[str | None] = []
    collect = SweepPool.collect

    def spy(self):
        out = collect(self)
        errors.append(self.error)
        return out

    monkeypatch.setattr(SweepPool, "collect", spy)
    serial = export_module.export_files(scene, SETTINGS, source={"label": "WSU"}, seed=3, workers=1)
    early = SweepPool.early(list(SETTINGS.methods))
    assert early._process is not None and early._process.is_alive()  # running before it has any work
    parallel = export_module.export_files(scene, SETTINGS, source={"label": "WSU"}, seed=3, workers=2,
                                          early_pool=early)
    assert errors == [None] and early._process is None
    for name in serial:
        if name not in RUN_DEPENDENT:
            assert parallel[name] == serial[name], name


def test_an_early_worker_computes_the_serial_sweep(scene):
    """The early worker (torch imported first for ann, a network) takes every job when the caller claims none;
    its results equal the serial sweep's bit for bit."""
    import time

    s = Settings(preset="WSU", scop_density=50, scp_count=3000, methods=("lrm", "ann"), sweep=True)
    model = ExplorerModel(preview_after_s=None, seed=3, scenes={s.preset: scene})
    pool = SweepPool.early(list(s.methods))
    try:
        pool.submit(scene, s, 3, model.sweep_points, export_module._pool_jobs(model, s))
        deadline = time.monotonic() + 300.0
        while pool._counter.value <= len(pool.jobs) and time.monotonic() < deadline:  # the caller claims nothing
            time.sleep(0.1)
        assert pool._counter.value > len(pool.jobs), "the worker stopped before taking every job"
        sweeps, _ = export_module._sweep_with_pool(model, pool, s)
    finally:
        pool.close()
    assert pool.error is None and sorted(pool.results) == list(range(len(pool.jobs)))
    _sweeps_equal(sweeps, _serial(scene, s))


def test_an_early_worker_without_work_is_stopped(scene):
    """An early worker given no job (no sweep, one CPU, a sensor that does not pickle) is stopped and the caller
    does every job itself; an export that does not reach the sweep (a refused source) closes it too."""
    s = Settings(preset="WSU", scop_density=50, scp_count=3000, methods=("lrm",), sweep=True)
    model = ExplorerModel(preview_after_s=None, seed=3, scenes={s.preset: scene})
    early = SweepPool.early(["lrm"])
    process = early._process
    early.submit(lambda: None, s, 3, model.sweep_points, export_module._pool_jobs(model, s))  # does not pickle
    assert early._process is None and not process.is_alive() and "does not pickle" in str(early.error)
    sweeps, _ = export_module._sweep_with_pool(model, early, s)
    _sweeps_equal(sweeps, _serial(scene, s))

    early = SweepPool.early(["lrm"])
    process = early._process
    early.submit(scene, s, 3, model.sweep_points, [])  # no job
    assert early._process is None and not process.is_alive() and early.claim() is None

    early = SweepPool.early(["lrm"])
    process = early._process
    export_module.export_files(scene, Settings(preset="WSU", scop_density=50, scp_count=500, methods=("lrm",),
                                               sweep=False), source={"label": "WSU"}, seed=3, workers=2,
                               early_pool=early)  # no sweep: nothing for the worker
    assert early._process is None and not process.is_alive()


def test_explore_export_of_a_refused_source_leaves_no_worker(tmp_path, monkeypatch):
    """The early worker of ``explore --export`` is stopped when the source is refused (the error as before)."""
    from explorer.app import export as export_mod
    from explorer.cli import main

    started: list = []
    early = export_mod.early_sweep_pool

    def spy(methods, sweep):
        pool = early(methods, sweep)
        started.append((pool, pool._process if pool is not None else None))
        return pool

    monkeypatch.setattr(export_mod, "early_sweep_pool", spy)
    rc = main(["explore", "--scene", str(tmp_path / "missing.json"), "--export", str(tmp_path / "out")])
    assert rc == 2
    assert len(started) == 1
    pool, process = started[0]
    if process is not None:  # a machine with two CPUs: it was started, and is stopped
        assert pool._process is None and not process.is_alive()
    assert not (tmp_path / "out").exists()


def test_an_export_with_every_network_imports_torch_in_neither_process(tmp_path):
    """The command and its sweep worker train and evaluate mlp, ann, bpnn and nn-rfm without torch (issue 24: torch's
    import and teardown cost each process ~1.6 s of the export's 5 s).  A stand-in ``torch`` package first on
    the path of both processes (PYTHONPATH is inherited by the spawned worker) records every process that
    imports it; the export must succeed with every method finite and no record, and the worker must have
    delivered sweep jobs (so its process was checked too)."""
    import json
    import os
    import subprocess
    import sys

    fake = tmp_path / "fake"
    (fake / "torch").mkdir(parents=True)
    marks = tmp_path / "marks"
    marks.mkdir()
    (fake / "torch" / "__init__.py").write_text(
        "import os\n"
        f"open(os.path.join({str(marks)!r}, str(os.getpid())), 'w').close()\n"
        "raise ImportError('torch imported by an export that should not need it')\n")
    script = tmp_path / "export.py"
    script.write_text(
        "import explorer.app.sweep_pool as sp\n"
        + _SPY_COLLECT +
        "if __name__ == '__main__':\n"
        "    from explorer.cli import main\n"  # the command's path: its worker starts early, before the source loads
        "    raise SystemExit(main(['explore', '--preset', 'WSU', '--methods', 'lrm,mlp,ann,bpnn,nn-rfm',\n"
        f"                           '--scps', '2000', '--export', {str(tmp_path / 'out')!r}]))\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(fake), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600, cwd=tmp_path,
                         env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    assert sorted(p.name for p in marks.iterdir()) == [], "processes that imported torch"
    delivered = [ln.split() for ln in out.stdout.splitlines() if ln.startswith("DELIVERED")]
    assert len(delivered) == 1 and int(delivered[0][1]) >= 1 and delivered[0][2] == "None", out.stdout
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    for name in ("lrm", "mlp", "ann", "bpnn", "nn-rfm"):
        assert summary["methods"][name]["error"] is None, (name, summary["methods"][name])
        assert summary["methods"][name]["rmse_row_px"] is not None, name


def test_an_early_worker_does_its_first_kernel_loads_work_and_scipy_linalg_while_it_waits():
    """The worker waits for the sensor while the caller loads it: ``_import_for`` does there what its first job
    would do first (scipy.linalg for the polynomial fits; numba's first cached-kernel load, which refreshes the CPU
    target and imports numba's lowering modules).  In a fresh interpreter (``sys.modules``, the interpreter's own
    record): those modules are absent after the worker's module imports, present after ``_import_for``, and a
    later refresh -- the one every cached-kernel load makes -- imports no further numba module."""
    import subprocess
    import sys

    watch = ("scipy.linalg", "numba.np.arraymath", "numba.np.npyimpl", "numba.cpython.unicode")
    code = ("import json, sys\n"
            "import explorer.app.sweep_pool as sp\n"
            "from explorer.app.model import SWEEP_PURPOSE, ExplorerModel\n"
            f"watch = {watch!r}\n"
            "before = [m in sys.modules for m in watch]\n"
            "sp._import_for(('lrm', 'mlp'))\n"
            "after = [m in sys.modules for m in watch]\n"
            "numba_modules = {m for m in sys.modules if m.startswith('numba')}\n"
            "from numba.core.registry import cpu_target\n"
            "cpu_target.target_context.refresh()\n"
            "new = sorted({m for m in sys.modules if m.startswith('numba')} - numba_modules)\n"
            "print(json.dumps([before, after, new]))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    before, after, new = json.loads(out.stdout.splitlines()[-1])
    assert before == [False] * len(watch)
    assert after == [True] * len(watch)
    assert new == []


def test_the_workers_early_kernel_start_up_is_skipped_on_a_numba_without_its_internal(monkeypatch):
    """explorer._numba.prepare_kernel_loads uses numba's internal ``cpu_target``; a numba without it must not stop
    the worker (it is an optimisation: the first kernel load does the same work)."""
    pytest.importorskip("numba")
    import numba.core.registry as registry_module

    from explorer._numba import prepare_kernel_loads

    monkeypatch.delattr(registry_module, "cpu_target")
    prepare_kernel_loads()  # no error
