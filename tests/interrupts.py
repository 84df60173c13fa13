"""Helpers for tests that interrupt a command in a child process."""

from __future__ import annotations

import signal


def as_foreground_job() -> None:
    """``preexec_fn``: give the child the default Ctrl-C handling of a job started from a terminal.

    A shell starts background jobs (``cmd &``, as some CI runners do) with SIGINT ignored, and a child inherits
    that: its Python then never raises KeyboardInterrupt, and a Ctrl-C test could only time out.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)
