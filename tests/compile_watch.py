"""Run a ``pushbroom`` command in a fresh Python process and record every numba compilation it makes.

The child registers a listener on numba's ``numba:compile`` event (fired only when numba really compiles a
function, never when it loads one from its on-disk cache), runs :func:`explorer.cli.main` with the given
arguments, and writes what compiled -- kernels called from Python, with their argument types and seconds --
to a JSON file.  Kernels compiled *inside* another compilation (callees) are counted with their caller.

Used by ``tests/test_first_run.py``; also a developer tool::

    python -m tests.compile_watch explore --isd tests/data/usgscsm/ctxLineScan.json --export /tmp/x
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_CHILD = r"""
import json, sys, threading, time
from numba.core import event

out_path, argv = sys.argv[1], sys.argv[2:]
compiled = []
depth = threading.local()
lock = threading.Lock()


class Listener(event.Listener):
    def on_start(self, ev):
        n = getattr(depth, "n", 0)
        depth.n = n + 1
        if n == 0:
            disp = ev.data["dispatcher"]
            fn = disp.py_func
            depth.t0 = time.perf_counter()
            depth.entry = [f"{fn.__module__}.{fn.__qualname__}", repr(tuple(ev.data["args"])), 0.0]

    def on_end(self, ev):
        depth.n -= 1
        if depth.n == 0:
            depth.entry[2] = time.perf_counter() - depth.t0
            with lock:
                compiled.append(depth.entry)


event.register("numba:compile", Listener())
from explorer.cli import main  # noqa: E402

try:
    rc = main(argv)
except SystemExit as exc:
    rc = exc.code if isinstance(exc.code, int) else 1
with open(out_path, "w") as f:
    json.dump({"rc": rc, "compiled": compiled}, f)
sys.exit(0)
"""


@dataclass
class Run:
    """What one command run did: its exit code, the kernels it compiled, its stderr."""

    rc: int
    compiled: list[tuple[str, str, float]]
    stderr: str

    @property
    def kernel_names(self) -> list[str]:
        return sorted({name for name, _, _ in self.compiled})


def run_counting_compiles(argv: list[str], cwd: Path = ROOT, timeout: float = 900.0,
                          env: dict[str, str] | None = None) -> Run:
    """Run ``pushbroom ARGV`` in a fresh interpreter (this one's ``sys.executable``) and return what compiled."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "compiled.json"
        proc = subprocess.run([sys.executable, "-c", _CHILD, str(out), *argv], cwd=cwd, capture_output=True,
                              text=True, timeout=timeout, env={**os.environ, **(env or {})})
        if not out.exists():
            raise RuntimeError(f"pushbroom {' '.join(argv)} died (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
        doc = json.loads(out.read_text())
    return Run(doc["rc"], [tuple(c) for c in doc["compiled"]], proc.stderr)


if __name__ == "__main__":  # pragma: no cover - developer tool
    run = run_counting_compiles(sys.argv[1:], cwd=Path.cwd())
    print(f"exit {run.rc}; {len(run.compiled)} compilation(s)")
    for name, sig, seconds in run.compiled:
        print(f"  {name} {seconds:.1f} s {sig}")
