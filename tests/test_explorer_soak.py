"""The explorer frees what it holds for a browser when the browser leaves.

Soak: 10 rounds of 50 websocket clients (the viser protocol, as a browser speaks it) connect to a
running explorer, receive the start of the scene and leave.  After each round the server must
have forgotten every client, and at the end the process's resident memory must be back within
10 % of what it was idle after one warm-up client.  Truth: the operating system's resident set
(``/proc/self/statm``) and viser's own client table.
"""

from __future__ import annotations

import gc
import os
import threading
import time

import pytest

viser = pytest.importorskip("viser")
ws_client = pytest.importorskip("websockets.sync.client")

from explorer.app import serve  # noqa: E402
from tests.test_app import toy_registry  # noqa: E402

ROUNDS, CLIENTS = 10, 50


def rss_bytes() -> int:
    """Resident set size of this process (Linux)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _visit(url: str, messages: int = 1) -> None:
    """Connect as a browser would, read a few messages of the initial state, leave."""
    ws = url.replace("http://", "ws://")
    with ws_client.connect(ws, subprotocols=[f"viser-v{viser.__version__}"], open_timeout=30,
                           max_size=None) as conn:
        for _ in range(messages):
            conn.recv(timeout=30)


def _wait_clients(app, n: int, timeout: float = 60.0) -> int:
    end = time.monotonic() + timeout
    while len(app.server.get_clients()) != n and time.monotonic() < end:
        time.sleep(0.05)
    return len(app.server.get_clients())


def _wait_trim(app, n: int, timeout: float = 30.0) -> None:
    end = time.monotonic() + timeout
    while app.trimmer.trims < n and time.monotonic() < end:
        time.sleep(0.1)
    assert app.trimmer.trims >= n


@pytest.mark.slow
def test_clients_leaving_free_their_memory():
    if not os.path.exists("/proc/self/statm"):
        pytest.skip("needs Linux /proc")
    with toy_registry():
        box: dict = {}
        stop = threading.Event()
        th = threading.Thread(target=lambda: box.setdefault("rc", serve(
            "WSU", port=0, methods=["toy_poly"], stop_event=stop, ready=lambda a: box.setdefault("app", a),
            scp_count=3000, sweep=False)), daemon=True)
        th.start()
        t0 = time.monotonic()
        while "app" not in box and time.monotonic() - t0 < 120:
            time.sleep(0.05)
        app = box["app"]
        try:
            assert app.wait_idle(120)
            _visit(app.url)  # warm-up: first-use caches (plotly.js read, message encoders)
            assert _wait_clients(app, 0) == 0
            _wait_trim(app, 1)
            gc.collect()
            idle = rss_bytes()
            peaks = []
            for _ in range(ROUNDS):
                workers = [threading.Thread(target=_visit, args=(app.url,)) for _ in range(CLIENTS)]
                for w in workers:
                    w.start()
                for w in workers:
                    w.join(120)
                peaks.append(rss_bytes())
                assert _wait_clients(app, 0) == 0, "the server still holds clients that left"
            _wait_trim(app, app.trimmer.trims + 1)  # the explorer hands freed memory back after the last left
            gc.collect()
            end = rss_bytes()
            print(f"soak: idle {idle / 2**20:.1f} MiB, after {ROUNDS} x {CLIENTS} clients {end / 2**20:.1f} MiB, "
                  f"peaks {[round(p / 2**20) for p in peaks]} MiB")
            assert end <= 1.10 * idle, (
                f"resident memory {end / 2**20:.1f} MiB after {ROUNDS} x {CLIENTS} clients, idle "
                f"{idle / 2**20:.1f} MiB (peaks {[round(p / 2**20) for p in peaks]} MiB)")
            assert app.errors == []
        finally:
            stop.set()
            th.join(60)
        assert box["rc"] == 0
