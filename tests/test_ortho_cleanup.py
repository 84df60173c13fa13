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
