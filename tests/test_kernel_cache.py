"""Which kernels numba's on-disk cache lacks, and the progress line / GUI line while they compile
(explorer/kernel_cache.py, explorer/commands/_progress.py, ExplorerApp's compiling line).

Truth: numba itself -- an empty cache directory holds nothing; a kernel numba loaded from disk shows in its
``stats.cache_hits``; numba's ``numba:compile`` event fires exactly when it compiles.
"""

from __future__ import annotations

import importlib.util
import io
import json
import os
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import numpy as np
import pytest

from explorer._numba import NUMBA_AVAILABLE
from explorer.kernel_cache import (
    CompileProgress,
    Kernel,
    TerminalLine,
    _dispatcher,
    _signature,
    is_cached,
    manifest,
    needed_units,
    reporting_compiles,
    uncached,
)

pytestmark = pytest.mark.skipif(not NUMBA_AVAILABLE, reason="numba missing")

REPO = Path(__file__).resolve().parents[1]
TOY_SOURCE = textwrap.dedent('''
    from explorer._numba import njit


    @njit(cache=True)
    def toy_affine(x):
        out = x.copy()
        for i in range(x.shape[0]):
            out[i] = 2.0 * x[i] + 1.0
        return out
''')


def load_toy(path: Path):
    """A fresh module object (and so a fresh numba dispatcher) from ``path``, named inside the package so the
    progress counts it as one of the package's kernels."""
    name = f"explorer._test_toy_{uuid.uuid4().hex}"
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def toy_file(tmp_path):
    path = tmp_path / "toy_kernels.py"
    path.write_text(TOY_SOURCE)
    return path


def toy_kernel(module) -> Kernel:
    from numba.core import types

    return Kernel(module.__name__, "toy_affine", repr((types.float64[::1],)))


# ------------------------------------------------------------------------------------- detection
def test_is_cached_agrees_with_numba_before_and_after_compiling(toy_file):
    first = load_toy(toy_file)
    kernel = toy_kernel(first)
    assert not is_cached(kernel) and uncached([kernel]) == [kernel]
    x = np.linspace(-1.0, 1.0, 7)
    np.testing.assert_array_equal(first.toy_affine(x), 2.0 * x + 1.0)  # compiles, writes the cache
    assert is_cached(kernel)  # in memory now
    second = load_toy(toy_file)  # a new dispatcher: only the disk cache can hold it
    kernel2 = toy_kernel(second)
    assert is_cached(kernel2)
    second.toy_affine(x)
    assert sum(second.toy_affine.stats.cache_hits.values()) == 1  # numba loaded it from disk
    assert not second.toy_affine.stats.cache_misses


def test_a_stale_source_is_not_cached(toy_file):
    first = load_toy(toy_file)
    first.toy_affine(np.zeros(3))
    toy_file.write_text(TOY_SOURCE.replace("2.0 * x[i]", "3.0 * x[i]"))  # another source: numba recompiles
    edited = load_toy(toy_file)
    assert not is_cached(toy_kernel(edited))
    np.testing.assert_array_equal(edited.toy_affine(np.ones(2)), [4.0, 4.0])
    assert not edited.toy_affine.stats.cache_hits


def test_manifest_names_existing_kernels_with_their_arity():
    table = manifest()
    assert {"scene", "scene:relief", "rpc", "ortho", "method:nr", "method:exact"} <= set(table)
    assert table["method:nr"] and table["rpc"] and table["ortho"]
    import inspect

    for unit, entries in table.items():
        for k in entries:
            disp = _dispatcher(k)
            again = "re-record the manifest: python -m explorer.warmup --record"
            assert disp is not None, f"{unit}: {k.module}.{k.name} is not a kernel any more; {again}"
            sig = _signature(k)
            assert sig is not None, f"{unit}: {k.signature} does not parse; {again}"
            assert len(sig) == len(inspect.signature(disp.py_func).parameters), f"{unit}: {k.label}; {again}"


def test_needed_units_of_the_commands():
    assert needed_units("explore", methods=["lrm", "nr"]) == ["scene", "method:lrm", "method:nr", "csv"]
    assert needed_units("bench", source="rpc", methods=["exact"], dem=True) == [
        "scene:relief", "rpc", "method:exact", "method:exact:relief"]
    assert needed_units("ortho", source="rpc", dem=True) == ["ortho", "rpc"]
    assert needed_units("ortho", methods=["exact"]) == ["ortho", "scene", "method:exact"]
    assert needed_units("explore", source="isd", methods=["nr"]) == ["scene", "isd", "method:nr", "csv"]


def test_command_units_from_parsed_arguments():
    import argparse

    from explorer.commands import bench, ortho
    from explorer.commands._progress import command_units

    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    bench.register(sub)
    ortho.register(sub)
    args = parser.parse_args(["bench", "--preset", "WSU", "--methods", "exact,nr", "--relief", "300"])
    assert command_units("bench", args) == ["scene:relief", "method:exact", "method:exact:relief", "method:nr",
                                            "method:nr:relief"]
    assert command_units("bench", parser.parse_args(["bench", "--methods", "no-such-method"])) == []


# -------------------------------------------------------------------------------------- progress
def test_terminal_line_while_compiling_and_silence_when_cached(toy_file):
    first = load_toy(toy_file)
    out = io.StringIO()
    with reporting_compiles([], stream=out) as progress:
        progress.expected = {f"{first.__name__.removeprefix('explorer.')}.toy_affine"}
        assert uncached([toy_kernel(first)]) == [toy_kernel(first)]
        first.toy_affine(np.zeros(4))
    lines = out.getvalue().splitlines()
    label = f"{first.__name__.removeprefix('explorer.')}.toy_affine"
    assert lines[0] == f"compiling kernels for first use: 1/1 ({label}) ..."
    assert lines[-1].startswith("compiling kernels for first use: done, 1 kernel in ")
    assert lines[-1].endswith("run `pushbroom warmup` once to skip this")
    again = load_toy(toy_file)
    out = io.StringIO()
    with reporting_compiles([], stream=out):
        again.toy_affine(np.zeros(4))
    assert out.getvalue() == ""
    assert sum(again.toy_affine.stats.cache_hits.values()) == 1


def test_terminal_line_is_rewritten_in_place_on_a_tty():
    out = io.StringIO()
    line = TerminalLine(out, tty=True)
    progress = CompileProgress({"a.k1", "a.k2"}, [line])
    for name in ("a.k1", "a.k2"):
        progress.kernel_started(name)
        progress.kernel_started("a.callee")  # compiled inside k1/k2: part of it
        progress.kernel_finished("a.callee")
        progress.kernel_finished(name)
    progress.finish()
    text = out.getvalue()
    assert text.count("\n") == 1 and text.endswith("\n")
    parts = text.split("\r\x1b[K")[1:]
    assert parts[:2] == ["compiling kernels for first use: 1/2 (a.k1) ...",
                         "compiling kernels for first use: 2/2 (a.k2) ..."]
    assert parts[2].startswith("compiling kernels for first use: done, 2 kernels in ")
    assert not progress.started and not progress.expected  # counting afresh


# ---------------------------------------------------------------------------------------- the GUI
def test_gui_shows_a_compiling_line_while_a_method_compiles_then_removes_it(toy_file):
    viser = pytest.importorskip("viser")
    from explorer.app import ExplorerApp
    from explorer.methods import base as methods_base
    from explorer.methods.base import BestScanlineMethod

    def method_on(module):
        class ToyCompiled(BestScanlineMethod):
            """Test-only method: the middle row through a compiled kernel."""

            name = "toy_compiled"
            label = "toy compiled"
            reference = "test only"
            family = "search"
            needs_fit = False

            def _locate(self, ground, *, trace):
                n = len(ground)
                row = module.toy_affine(np.full(n, (self.scene.n_rows - 1) / 4.0 - 0.5))
                return self._result(ground, row, np.ones(n, bool), np.ones(n, int))
        return ToyCompiled

    def run_app(module):
        server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
        created = []
        add_markdown, add_bar = server.gui.add_markdown, server.gui.add_progress_bar

        def markdown(content, **kw):
            handle = add_markdown(content, **kw)
            if content.startswith("**Compiling"):
                created.append(handle)
            return handle

        progress = CompileProgress().install()

        def bar(value, **kw):
            handle = add_bar(value, **kw)
            if progress.compiling:  # not the status line's bar
                created.append(handle)
            return handle

        server.gui.add_markdown, server.gui.add_progress_bar = markdown, bar
        methods_base.registry()
        try:
            with pytest.MonkeyPatch.context() as mp:
                mp.setitem(methods_base._REGISTRY, "toy_compiled", method_on(module))
                app = ExplorerApp(server, preset="WSU", methods=["toy_compiled"], scp_count=1000, sweep=False,
                                  background=False, compile_progress=progress)
                app.close()
        finally:
            progress.uninstall()
            server.stop()
        return app, created

    first = load_toy(toy_file)
    app, created = run_app(first)
    label = f"{first.__name__.removeprefix('explorer.')}.toy_affine"
    # (a package kernel made stale by an edited source may compile too, in its own line)
    assert any(t.startswith("**Compiling kernels for first use** 1/") and f"`{label}`" in t for t in app.compile_log)
    assert app.compile_log[-1] == ""  # removed
    assert len(created) >= 2 and all(h._impl.removed for h in created)  # the line and its bar, removed
    assert any(label in getattr(h, "content", "") for h in created)
    assert "compile_note" not in app.handles and "compile_bar" not in app.handles
    run = app.runs["toy_compiled"]
    scps = app.model.scps(app.settings())
    assert run.ok and run.evaluation.n_evaluated == len(scps)  # the maps show after, with the kernel's rows
    middle = (app.scene.n_rows - 1) / 2.0  # 2 * ((n - 1) / 4 - 0.5) + 1
    np.testing.assert_allclose(run.evaluation.residual_row + scps.row[run.evaluation.evaluated_index], middle,
                               rtol=0, atol=1e-9 * middle)

    second = load_toy(toy_file)
    app, created = run_app(second)
    assert app.compile_log == [] and created == []
    assert app.runs["toy_compiled"].ok
    assert sum(second.toy_affine.stats.cache_hits.values()) == 1  # numba loaded it: nothing compiled


# ----------------------------------------------------------- a real command in an empty numba cache
def _python(code: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True,
                          timeout=900, check=True)


DETECT = ("import json; from explorer.kernel_cache import needed_units, uncached; "
          "print(json.dumps([k.label for k in uncached(needed_units('explore', methods=['nr']))]))")


def test_explore_in_an_empty_numba_cache_says_it_compiles_then_says_nothing(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), PYTHONDONTWRITEBYTECODE="1")
    env.pop("EXPLORER_DISABLE_NUMBA", None)
    missing = json.loads(_python(DETECT, env).stdout)
    assert "geometry.newton_kernel._newton_raphson_nb" in missing
    assert not (tmp_path / "numba").exists() or not any((tmp_path / "numba").rglob("*.nbi"))  # truth: empty
    check = subprocess.run([sys.executable, "-m", "explorer", "warmup", "--check"], cwd=REPO, env=env,
                           capture_output=True, text=True, timeout=300, check=True)
    assert "not in numba's cache" in check.stdout and "newton_kernel._newton_raphson_nb" in check.stdout
    explore = [sys.executable, "-m", "explorer", "explore", "--preset", "WSU", "--methods", "nr", "--scops", "10",
               "--scps", "2000"]
    cold = subprocess.run(explore + ["--export", str(tmp_path / "cold")], cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=900)
    assert cold.returncode == 0, cold.stderr
    lines = [ln for ln in cold.stderr.splitlines() if ln.startswith("compiling kernels for first use")]
    assert lines and lines[0].startswith("compiling kernels for first use: 1/")
    assert lines[-1].startswith("compiling kernels for first use: done, ") and "pushbroom warmup" in lines[-1]
    # warm what the detection covers (nr on every preset), counting numba's compilations of the re-run
    warm = ("from explorer.warmup import kernel_units; u = kernel_units(); u['scene'](); u['method:nr']()")
    _python(warm, env)
    recount = ("from numba.core import event; from explorer.warmup import kernel_units\n"
               "n = []\n"
               "class L(event.Listener):\n"
               "    def on_start(self, e): n.append(1)\n"
               "    def on_end(self, e): pass\n"
               "event.register('numba:compile', L()); u = kernel_units(); u['scene'](); u['method:nr'](); "
               "print(len(n))")
    assert json.loads(_python(DETECT, env).stdout) == []
    assert _python(recount, env).stdout.strip() == "0"  # numba agrees: nothing left to compile
    warm_run = subprocess.run(explore + ["--export", str(tmp_path / "warm")], cwd=REPO, env=env,
                              capture_output=True, text=True, timeout=900)
    assert warm_run.returncode == 0, warm_run.stderr
    assert "compiling kernels" not in warm_run.stderr


def test_check_names_package_kernels_the_manifest_does_not_know_until_they_are_compiled(monkeypatch):
    """Issue 25 class 9: ``warmup --check`` said "nothing will compile" while kernels missing from the manifest
    compiled for seconds; a kernel outside the manifest is now listed until it is really compiled."""
    import types

    numba = pytest.importorskip("numba")
    from explorer import kernel_cache

    module = types.ModuleType("explorer._fake_kernels")

    def twice(x):
        return 2.0 * x

    twice.__module__, twice.__qualname__ = module.__name__, "twice"
    module.twice = numba.njit(cache=False)(twice)
    monkeypatch.setitem(sys.modules, module.__name__, module)
    monkeypatch.setattr(kernel_cache, "package_kernels", lambda: [(module.__name__, "twice")])
    assert kernel_cache.unrecorded_uncached() == ["_fake_kernels.twice"]
    assert module.twice(1.5) == 3.0  # compiles now
    assert kernel_cache.unrecorded_uncached() == []


def test_package_kernels_finds_the_compiled_kernels_of_the_package():
    pytest.importorskip("numba")
    from explorer.kernel_cache import manifest, package_kernels

    found = set(package_kernels())
    recorded = {(k.module, k.name) for unit in manifest().values() for k in unit}
    assert recorded <= found  # every kernel the manifest names is one of the package's
    assert ("explorer.real.csm_kernels", "ground_to_image_nb") in found
