"""User-facing warnings as one-line log messages on the package logger ``explorer``.

A training that did not converge, a method that cannot generalise from too few control points:
the user should read one clear line, not a Python warning record with the source file path and
line number.  The package logs such messages with :func:`warn` on the ``explorer`` logger (or a
child, ``explorer.<name>``).  Without any logging configuration Python prints them on stderr as
the bare message (the ``logging.lastResort`` handler); an application that configures logging
formats them its own way; ``logging.getLogger("explorer").setLevel(logging.ERROR)`` silences them.

Tests check them with pytest's ``caplog`` (``caplog.at_level(logging.WARNING, logger="explorer")``).
:func:`collect_warnings` records the messages of a block (the benchmark stores them with its
results) and :func:`quiet` silences them for the current thread (a grid search whose failing
candidates are expected).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["LOGGER_NAME", "collect_warnings", "context", "get_logger", "quiet", "warn"]

LOGGER_NAME = "explorer"

_state = threading.local()


def get_logger(name: str | None = None) -> logging.Logger:
    """The package logger ``explorer`` (``name``: a child ``explorer.<name>``)."""
    return logging.getLogger(LOGGER_NAME if not name else f"{LOGGER_NAME}.{name}")


def warn(message: str, *, name: str | None = None) -> None:
    """Log a user-facing warning: one line (newlines become ``"; "``), level WARNING.

    Parameters
    ----------
    message : str
        What happened and what it means for the results, naming the method or input.
    name : str, optional
        Child logger ``explorer.<name>`` (e.g. the method name).
    """
    text = "; ".join(part.strip() for part in str(message).splitlines() if part.strip())
    if getattr(_state, "quiet", 0):
        return
    prefix = getattr(_state, "context", ())
    if prefix:
        text = f"[{' / '.join(prefix)}] {text}"
    get_logger(name).warning(text)


class _Collector(logging.Handler):
    """Collects the messages logged by one thread."""

    def __init__(self, thread: int) -> None:
        super().__init__(logging.WARNING)
        self.thread = thread
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.thread == self.thread:
            self.messages.append(record.getMessage())


@contextmanager
def context(what: str) -> Iterator[None]:
    """Prefix the warnings this thread logs inside the block with ``[what]`` (nested blocks join
    theirs with " / "), so a line from background work names the work, e.g.
    ``[accuracy-vs-SCOPs sweep, 30 SCOPs] mlp: ...``."""
    old = getattr(_state, "context", ())
    _state.context = (*old, str(what))
    try:
        yield
    finally:
        _state.context = old


@contextmanager
def collect_warnings() -> Iterator[list[str]]:
    """Record the package's warning messages logged by this thread inside the block.

    Yields
    ------
    list of str
        Filled as messages are logged (they are still passed on to the usual handlers).
    """
    handler = _Collector(threading.get_ident())
    logger = get_logger()
    logger.addHandler(handler)
    try:
        yield handler.messages
    finally:
        logger.removeHandler(handler)


@contextmanager
def quiet() -> Iterator[None]:
    """Drop the package's :func:`warn` messages issued by this thread inside the block."""
    _state.quiet = getattr(_state, "quiet", 0) + 1
    try:
        yield
    finally:
        _state.quiet -= 1
