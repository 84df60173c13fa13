"""An interrupted or terminated ortho run leaves no file under its final name and no partial file."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.interrupts import as_foreground_job, interrupt_when


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_interrupted_ortho_leaves_nothing_under_the_final_name(tmp_path: Path, sig: int) -> None:
    out = tmp_path / "ortho.tif"
    proc = subprocess.Popen(
        [sys.executable, "-m", "explorer", "ortho", "--preset", "linear", "--synthetic", "--gsd", "0.1",
         "--chunk", "256", "--scheduler", "threads", "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path, preexec_fn=as_foreground_job,
    )
    # interrupted once the writer has started (its hidden partial file exists)
    interrupt_when(proc, lambda: bool(list(tmp_path.glob(".ortho.tif.partial-*"))), sig, timeout=60)
    assert not out.exists()
    assert not list(tmp_path.glob(".ortho.tif.partial-*"))
