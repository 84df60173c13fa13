"""Issue 25 class 9: a malformed websocket message from a client costs one stderr line, not a traceback."""

from __future__ import annotations

import io
import logging

import pytest

pytest.importorskip("viser")


def test_client_errors_are_one_line_and_rate_limited(monkeypatch):
    from explorer.app import server

    logger = logging.getLogger("websockets.server")
    stream = io.StringIO()
    handler = logging.StreamHandler(stream)
    logger.addHandler(handler)
    one_line = server.quiet_client_errors()
    assert server.quiet_client_errors() is one_line  # installed once
    clock = iter([100.0, 100.2, 101.5])
    monkeypatch.setattr(server.time, "monotonic", lambda: next(clock))
    try:
        for _ in range(3):
            try:
                raise ValueError("MessagePack data is malformed: invalid opcode '\\xc1'")
            except ValueError:
                logger.error("connection handler failed", exc_info=True)
    finally:
        logger.removeHandler(handler)
        logger.removeFilter(one_line)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2 and one_line.dropped == 1  # the second within a second of the first is dropped
    assert all(line.startswith("pushbroom explorer: closed a client connection") and "ValueError" in line
               for line in lines)
    assert "Traceback" not in stream.getvalue()
