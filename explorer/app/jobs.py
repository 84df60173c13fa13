"""Background training for the explorer: :class:`FitPool` (threads only; no viser, no plotly)."""

from __future__ import annotations

import threading
import time
import traceback
from collections.abc import Callable, Hashable
from typing import Any


class FitPool:
    """Background threads that train methods, so a slow fit (an MLP trained by
    Levenberg-Marquardt takes seconds to minutes) never freezes the explorer.

    Jobs are keyed by :meth:`ExplorerModel.fit_key`.  The next job is the one of highest
    priority (lowest number), then lowest expected cost (the caller's estimate), then
    oldest; with two threads a long fit never holds up the quick ones, and low-priority
    jobs (priority > 0) only ever run on the first thread.  :meth:`keep`
    drops queued jobs the current settings no longer need (a running fit finishes and
    stays cached).  ``on_done(key, priority)`` is called after each job while holding
    ``cond``, so waiters see "job done" and its consequence at once.  A job submitted with
    ``hold=True`` waits (queued, pending) until :meth:`release` -- the explorer holds the long
    trainings until its first maps are on screen: on a shared CPU they would otherwise slow them.
    """

    def __init__(self, cond: threading.Condition, on_done: Callable[[Hashable, int], None],
                 threads: int = 2) -> None:
        self._cond = cond
        self._on_done = on_done
        self._jobs: dict[Hashable, tuple[int, float, int, Callable[[], Any]]] = {}
        self.held: set[Hashable] = set()
        """Queued jobs that wait for :meth:`release`."""
        self._counter = 0
        self.running: dict[Hashable, float] = {}
        self._closing = False
        self._threads = [threading.Thread(target=self._loop, args=(i,), name=f"explorer-fits-{i}",
                                          daemon=True) for i in range(threads)]
        for t in self._threads:
            t.start()

    def submit(self, key: Hashable, job: Callable[[], Any], priority: int = 0, cost: float = 1.0,
               hold: bool = False) -> None:
        """Queue ``job`` under ``key`` (nothing if that key is queued or running); ``hold``: it waits for
        :meth:`release`."""
        with self._cond:
            if key in self._jobs or key in self.running:
                return
            self._counter += 1
            self._jobs[key] = (priority, cost, self._counter, job)
            if hold:
                self.held.add(key)
            self._cond.notify_all()

    def release(self) -> None:
        """Let the held jobs run."""
        with self._cond:
            if self.held:
                self.held.clear()
                self._cond.notify_all()

    def keep(self, keys: set) -> None:
        with self._cond:
            for k in [k for k in self._jobs if k not in keys]:
                del self._jobs[k]
                self.held.discard(k)

    def is_pending(self, key: Hashable) -> bool:
        with self._cond:
            return key in self._jobs or key in self.running

    def queued(self, priority: int | None = None) -> int:
        """Jobs waiting (of one priority, or all)."""
        return sum(1 for j in self._jobs.values() if priority is None or j[0] == priority)

    @property
    def busy(self) -> bool:
        return bool(self._jobs) or bool(self.running)

    def wait_for(self, keys: list, deadline: float, abort: Callable[[], bool] | None = None) -> None:
        """Block until none of ``keys`` is pending, ``time.monotonic()`` passes ``deadline`` or
        ``abort()`` (checked whenever ``cond`` is notified) is true."""
        with self._cond:
            while any(self.is_pending(k) for k in keys) and not (abort is not None and abort()):
                left = deadline - time.monotonic()
                if left <= 0:
                    return
                self._cond.wait(left)

    def close(self) -> None:
        with self._cond:
            self._closing = True
            self._jobs.clear()
            self.held.clear()
            self._cond.notify_all()
        for t in self._threads:
            t.join(timeout=60)

    def _loop(self, index: int) -> None:
        # thread 0 takes any job; the others only priority-0 ones, so background work (the
        # accuracy sweep) never occupies more than one thread
        def ready() -> list:
            return [k for k, j in self._jobs.items() if (index == 0 or j[0] == 0) and k not in self.held]

        while True:
            with self._cond:
                while not ready() and not self._closing:
                    self._cond.wait()
                if self._closing:
                    return
                key = min(ready(), key=lambda k: self._jobs[k][:3])
                priority, _, _, job = self._jobs.pop(key)
                self.running[key] = time.monotonic()
            try:
                job()
            except Exception:  # the model records method errors; anything else is a bug to show
                traceback.print_exc()
            finally:
                with self._cond:
                    del self.running[key]
                    self._on_done(key, priority)
                    self._cond.notify_all()


__all__ = ["FitPool"]
