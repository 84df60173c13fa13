"""What bounds the explorer's memory across changes (issue 24, the RSS ratchet): the evaluation cache is bounded in
bytes as well as entries, and every update schedules the hand-back of freed memory (the server's trimmer).  The
resident memory itself over 20 SCOP changes is measured by benchmarks/explorer_browser.py (``rss``)."""

from __future__ import annotations

import numpy as np
import pytest

viser = pytest.importorskip("viser")

from explorer.app.model import _LRU, EVAL_CACHE_BYTES, ExplorerModel, run_nbytes  # noqa: E402
from tests.test_app import make_app, toy_registry  # noqa: E402


def test_lru_drops_the_least_recent_entries_beyond_its_byte_budget():
    cache = _LRU(100, max_bytes=10_000, weigh=lambda a: a.nbytes)
    for k in range(5):
        cache.get_or(k, lambda: np.zeros(400))  # 3,200 bytes each: three fit in 10,000
    assert len(cache) == 3 and cache.nbytes == 9_600
    assert cache.peek(0) is None and cache.peek(1) is None and cache.peek(4) is not None
    cache.peek(2)  # now the most recent
    cache.get_or(5, lambda: np.zeros(400))
    assert cache.peek(3) is None and cache.peek(2) is not None
    big = cache.get_or(6, lambda: np.zeros(5_000))  # larger than the budget alone: kept (the newest always stays)
    assert len(cache) == 1 and cache.peek(6) is big
    plain = _LRU(2)  # without a budget: entries only
    for k in range(4):
        plain.get_or(k, lambda: np.zeros(10_000))
    assert len(plain) == 2 and plain.nbytes == 0


def test_the_models_evaluations_are_weighed_by_their_arrays():
    model = ExplorerModel()
    assert model._evals.max_bytes == EVAL_CACHE_BYTES
    with toy_registry():
        from explorer.app.model import Settings

        s = Settings(preset="WSU", scp_count=2000, methods=("toy_poly",))
        run = model.evaluate("toy_poly", s)
    ev = run.evaluation
    want = ev.residual_row.nbytes + ev.residual_col.nbytes + ev.evaluated_index.nbytes + run.status.nbytes
    assert run_nbytes(run) == want > 2000 * 8
    assert model._evals.nbytes == want


class _Counter:
    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, _client=None) -> None:
        self.calls += 1


def test_every_update_schedules_the_trim():
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        with toy_registry():
            app = make_app(srv)
            app.trimmer = _Counter()
            app.handles["density"].value = "30"
            assert app.trimmer.calls == 1
            app.handles["density"].value = "50"
            assert app.trimmer.calls == 2
            app.close()
    finally:
        srv.stop()
