"""Ortho's temporary folder (the synthetic source, 6.4 GB for a full Pleiades scene) does not outlive its run.

Removed when the run finishes, fails, is interrupted (Ctrl-C, SIGTERM) and, for a run that could not clean up
(SIGKILL, out of memory), by the next run.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from explorer.commands.ortho import WORK_PREFIX, work_folder
from explorer.errors import InputError
from tests.interrupts import as_foreground_job, interrupt_when

DATA = Path(__file__).parent / "data" / "rpc"
DEM = Path(__file__).parent.parent / "assets" / "dem" / "MNT_P1BP--2018122638935449CP.tif"
HOLD_FOLDER = """
import os, signal, sys
from explorer.commands.ortho import work_folder
with work_folder() as folder:
    (folder / "synthetic_source.npy").write_bytes(b"x" * 1000)
    print(folder, flush=True)
    if sys.argv[1] == "kill":
        os.kill(os.getpid(), signal.SIGKILL)
    sys.stdin.read()  # alive until its stdin closes
"""


def _env(tmp: Path) -> dict:
    return {**os.environ, "TMPDIR": str(tmp)}


def _start_holder(tmp: Path, mode: str) -> tuple[subprocess.Popen, Path]:
    proc = subprocess.Popen([sys.executable, "-c", HOLD_FOLDER, mode], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True, env=_env(tmp))
    assert proc.stdout is not None
    return proc, Path(proc.stdout.readline().strip())


@pytest.fixture
def tmp_root(tmp_path, monkeypatch):
    root = tmp_path / "tmp"
    root.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(root))
    return root


def test_a_killed_runs_folder_is_removed_by_the_next_run_and_a_live_one_is_kept(tmp_root):
    killed, killed_folder = _start_holder(tmp_root, "kill")
    killed.wait(timeout=60)
    assert killed.returncode == -signal.SIGKILL
    assert (killed_folder / "synthetic_source.npy").exists()  # nobody could clean up
    alive, alive_folder = _start_holder(tmp_root, "wait")
    try:
        with work_folder() as mine:
            assert mine.is_dir() and mine.name.startswith(WORK_PREFIX)
            assert not killed_folder.exists()
            assert (alive_folder / "synthetic_source.npy").exists()
        assert not mine.exists()
    finally:
        alive.communicate(timeout=60)  # closes its stdin: it ends normally
    assert alive.returncode == 0
    assert list(tmp_root.iterdir()) == []


def test_a_failed_run_removes_its_folder(tmp_root):
    with pytest.raises(InputError):
        with work_folder() as folder:
            (folder / "synthetic_source.npy").write_bytes(b"x")
            raise InputError("a failure half-way")
    assert list(tmp_root.iterdir()) == []


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_an_interrupted_ortho_run_removes_its_folder_and_partial_output(tmp_path, sig):
    root = tmp_path / "tmp"
    root.mkdir()
    out = tmp_path / "ortho.tif"
    proc = subprocess.Popen(
        [sys.executable, "-m", "explorer", "ortho", "--rpc", str(DATA / "PHRDIMAP_P1BP--2018122638935449CP.XML"),
         "--dem", str(DEM), "--synthetic", "--rpc-shape", "3000x3000", "--gsd", "0.5", "--chunk", "256",
         "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(root), preexec_fn=as_foreground_job,
    )
    interrupt_when(proc, lambda: bool(list(root.glob(WORK_PREFIX + "*/synthetic_source.npy"))), sig)  # rendering
    assert list(root.iterdir()) == []
    assert list(tmp_path.glob("*ortho.tif*")) == []


def _children(pid: int) -> list[int]:
    """Live (not zombie) processes whose parent is ``pid`` (from /proc)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            out.append(int(stat.parent.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")
def test_a_sigkilled_process_pool_run_leaves_no_worker_and_the_rerun_starts_clean(tmp_path):
    """Issue 25 class 7: the workers of a SIGKILLed ``--scheduler processes`` run leave with it (they used to
    wait forever beside the next run), and the next run removes the killed run's partial GeoTIFF and folder."""
    import time

    root = tmp_path / "tmp"
    root.mkdir()
    out = tmp_path / "o.tif"
    argv = [sys.executable, "-m", "explorer", "ortho", "--preset", "SCB", "--synthetic", "--chunk", "128",
            "--scheduler", "processes", "--out", str(out)]
    proc = subprocess.Popen(argv + ["--gsd", "4"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=_env(root))
    deadline = time.monotonic() + 300
    workers: list[int] = []
    while time.monotonic() < deadline and proc.poll() is None:
        workers = [p for p in _children(proc.pid) if b"spawn_main" in Path(f"/proc/{p}/cmdline").read_bytes()]
        if workers and list(tmp_path.glob(".o.tif.partial-*")):
            break
        time.sleep(0.1)
    assert proc.poll() is None and workers, "the run ended before its pool was at work"
    helpers = _children(proc.pid)
    proc.kill()
    proc.wait(timeout=60)
    deadline = time.monotonic() + 30  # a hang guard, not a speed assertion
    while time.monotonic() < deadline and any(_alive(p) for p in helpers):
        time.sleep(0.1)
    left = [p for p in helpers if _alive(p)]
    for p in left:  # do not leave them to the next test
        os.kill(p, signal.SIGKILL)
    assert left == [], "worker processes outlived the killed run"
    assert list(tmp_path.glob(".o.tif.partial-*")) and list(root.glob(WORK_PREFIX + "*"))  # nobody cleaned up
    rerun = subprocess.run(argv + ["--gsd", "60"], capture_output=True, text=True, env=_env(root), timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.tif", "tmp"]
    assert list(root.iterdir()) == []
