"""An interrupted or terminated ortho run leaves no file under its final name and no partial file."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.interrupts import as_foreground_job


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_interrupted_ortho_leaves_nothing_under_the_final_name(tmp_path: Path, sig: int) -> None:
    out = tmp_path / "ortho.tif"
    proc = subprocess.Popen(
        [sys.executable, "-m", "explorer", "ortho", "--preset", "linear", "--synthetic", "--gsd", "0.1",
         "--chunk", "256", "--scheduler", "threads", "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path, preexec_fn=as_foreground_job,
    )
    # wait until the writer has started (its hidden partial file exists), then interrupt
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if list(tmp_path.glob(".ortho.tif.partial-*")):
            break
        time.sleep(0.05)
    assert proc.poll() is None, f"the run ended before it could be interrupted: {proc.communicate()}"
    time.sleep(0.5)
    proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=60)  # a hang guard, not a speed assertion
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("the interrupted ortho run did not stop")
    assert proc.returncode in (130, 143), err
    assert "Traceback" not in err
    assert not out.exists()
    assert not list(tmp_path.glob(".ortho.tif.partial-*"))
