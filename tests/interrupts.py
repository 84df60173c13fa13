"""Helpers for tests that interrupt a command in a child process."""

from __future__ import annotations

import signal
import subprocess
import time
from collections.abc import Callable

import pytest


def as_foreground_job() -> None:
    """``preexec_fn``: give the child the default Ctrl-C handling of a job started from a terminal.

    A shell starts background jobs (``cmd &``, as some CI runners do) with SIGINT ignored, and a child inherits
    that: its Python then never raises KeyboardInterrupt, and a Ctrl-C test could only time out.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def interrupt_when(proc: subprocess.Popen, started: Callable[[], bool], sig: int, *, timeout: float = 120.0) -> str:
    """Wait until ``started()`` (the run reached the phase under test), send ``sig``, wait for the end.

    Fails the test if the run ended before it could be interrupted or did not stop after the signal (both
    waits are hang guards, not speed assertions); asserts the interrupted exit status (130 or 143) and no
    traceback, and returns the run's stderr.
    """
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None and not started():
        time.sleep(0.05)
    assert proc.poll() is None, f"the run ended before it could be interrupted: {proc.communicate()}"
    time.sleep(0.5)
    proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("the interrupted run did not stop")
    assert proc.returncode in (130, 143), err
    assert "Traceback" not in err
    return err
