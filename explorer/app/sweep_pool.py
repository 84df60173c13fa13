"""The export's accuracy-vs-SCOPs sweep on a second process (no viser, no plotly).

The sweep refits every learned method at every SCOP density (:data:`explorer.app.model.SCOP_DENSITIES`) and
evaluates each fit on the same seeded check points: independent jobs, most of a file's default export (issue 24:
the DIMAP export 26-50 s, the sweep 15-39 s of it).  Their trainings are Python loops of small torch / numpy
operations, bound by the interpreter lock, so threads do not run them side by side (measured: no gain); a
second process does.

:class:`SweepPool` starts **one spawned** worker process (a fork is not safe: the parent has already run numba's
and torch's OpenMP regions, and a forked child that starts one is terminated by numba -- "fork() called from a
process already using GNU OpenMP").  The worker receives the sensor pickled (the same object, bit for bit: no
file is read again), the settings, the seed and the job list; it builds its own
:class:`~explorer.app.model.ExplorerModel` and claims jobs one at a time from a shared counter, as the parent
does once its maps are done, so whichever process is free takes the next job (the longest first).  Each job
is :meth:`ExplorerModel.sweep_point`, the same function in both processes on the same inputs: the results are
the same whichever process computed them, and they are combined in the order of the serial sweep -- the export is
byte-identical to the serial one (tests/test_sweep_pool.py compares them bit for bit).

If the worker cannot start (a sensor that does not pickle, no second CPU), dies, or is silent for
:data:`SILENT_S`, the parent computes the jobs it did not deliver: the pool only changes when a result is
ready, never what it is.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from typing import Any

from explorer import _log

SILENT_S = 300.0
"""Seconds without any result from the worker after which the parent stops waiting and computes its jobs."""


WORKER_MEMORY = 2 * 2**30
"""Memory (bytes, :func:`explorer.memory.available_memory`) below which no worker is started: the worker of the
DIMAP export with its DEM held 0.4 GB beside the command's 0.9 GB."""


def _worker(counter: Any, conn: Any, parent_pid: int, methods: tuple[str, ...] = ()) -> None:
    """The worker process: import what the jobs of ``methods`` need (while the caller may still be loading the
    sensor), receive the work (the pickled sensor, settings and jobs) on ``conn``, claim jobs from ``counter`` and
    send ``(index, result)`` for each, then ``None``."""
    from explorer.app.model import SWEEP_PURPOSE, ExplorerModel

    try:
        _import_for(methods)
        scene, s, seed, sweep_points, jobs = pickle.loads(conn.recv_bytes())
        model = ExplorerModel(preview_after_s=None, seed=seed, sweep_points=sweep_points, scenes={s.preset: scene})
        while os.getppid() == parent_pid:
            with counter.get_lock():
                k = int(counter.value)
                counter.value = k + 1
            if k >= len(jobs):
                break
            name, density = jobs[k]

            def get_fit(d: int, name: str = name) -> Any:
                return model.fit(name, s, d, purpose=SWEEP_PURPOSE)

            result = model.sweep_point(name, s, density, get_fit)
            conn.send((k, result))
        conn.send(None)
    except (BrokenPipeError, EOFError, KeyboardInterrupt):  # the parent is gone or stopping: nothing to say
        pass
    finally:
        conn.close()
    _leave()


def _leave() -> None:
    """End the worker process now that its results are sent: standard output and error flushed, then
    ``os._exit``.  The parent waits for the worker's end (:meth:`SweepPool.close`), and Python's teardown of the
    worker (every array, compiled kernel and module freed; torch's finalizers) took 0.4-0.8 s of that wait for
    nothing: the worker writes no file and holds no resource another process needs."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(0)


def _import_for(methods: Sequence[str]) -> None:
    """Import the modules of ``methods`` (and the registry's) so that a worker started early has done it before
    its first job.  torch is not among them: the networks of the export's learned methods train and answer
    without it (:mod:`explorer.methods._lm_compiled`, :class:`explorer.methods._torch_uniform.TorchUniform`); a
    method that still needs it (several hidden layers, no numba) imports it on its first fit.  The worker waits
    for the sensor while the caller loads it (~0.7 s on the DIMAP export): scipy.linalg and numba's first-load
    work (:func:`explorer._numba.prepare_kernel_loads`) are done in that wait, not in the first job."""
    if not methods:
        return
    import scipy.linalg  # noqa: F401  -- every fit's polynomial least squares (methods._polynomial), 0.1 s

    from explorer._numba import prepare_kernel_loads
    from explorer.methods import registry

    registry()
    prepare_kernel_loads()


@contextlib.contextmanager
def _main_not_replayed() -> Iterator[None]:
    """Start a spawned process without it running the caller's ``__main__`` again.

    A spawned child first imports the parent's main script (as ``__mp_main__``) so that functions defined there
    can be unpickled; :func:`_worker` lives in this module and needs none of it.  A user's script that calls
    :func:`explorer.app.export.run_export` without an ``if __name__ == "__main__":`` guard was run again, whole,
    in the worker -- the export computed twice, by the child before it took any job (seen: a script's top-level
    line printed by two processes).  The main module's file and spec are hidden while the process starts
    (``multiprocessing.spawn.get_preparation_data`` reads them then, and only then), so the child imports only
    this package."""
    main = sys.modules.get("__main__")
    if main is None:
        yield
        return
    missing = object()
    file, spec = main.__dict__.get("__file__", missing), main.__dict__.get("__spec__", missing)
    with contextlib.suppress(AttributeError, TypeError):
        main.__dict__.pop("__file__", None)
        main.__spec__ = None
    try:
        yield
    finally:
        if file is not missing:
            main.__file__ = file
        if spec is not missing:
            main.__spec__ = spec


class SweepPool:
    """A second process computing sweep jobs ``(method, density)`` beside the caller (see the module docstring).

    Parameters
    ----------
    scene : Sensor
        Pickled to the worker.
    settings : Settings
    seed, sweep_points : int
        As the caller's :class:`~explorer.app.model.ExplorerModel`.
    jobs : sequence of (str, int)
        Method and SCOP density of each job, the longest first (both processes take them in this order).
    """

    jobs: list[tuple[str, int]]
    results: dict[int, tuple[str, Any]]
    error: str | None
    """Why the worker did not start or did not finish (None: it delivered every job it took)."""
    _process: Any
    _conn: Any
    _counter: Any
    _next: int  # the caller's own count when there is no worker
    _reader: threading.Thread | None
    _payload: bytes | None

    def __init__(self, scene: Any, settings: Any, seed: int, sweep_points: int,
                 jobs: Sequence[tuple[str, int]]) -> None:
        self._reset()
        self.jobs = list(jobs)
        if not self.jobs or not self._memory_ok():
            return
        payload = self._pickled(scene, settings, seed, sweep_points)
        if payload is not None:
            self._spawn(())
            self._send(payload)

    @classmethod
    def early(cls, methods: Sequence[str] = ()) -> SweepPool:
        """A pool whose worker process starts now, before the sensor is loaded: it imports the package and the
        modules of ``methods`` while the caller loads, then waits for :meth:`submit` (issue 24: the DIMAP export's
        worker spent its first 2 s importing after the sensor was loaded)."""
        pool = cls.__new__(cls)
        pool._reset()
        if pool._memory_ok():
            pool._spawn(tuple(methods))
        return pool

    def submit(self, scene: Any, settings: Any, seed: int, sweep_points: int,
               jobs: Sequence[tuple[str, int]]) -> None:
        """Give the worker of :meth:`early` its work (as the constructor's arguments); with no job, or a sensor that
        does not pickle, the worker is stopped and the caller does every job."""
        self.jobs = list(jobs)
        if self._process is None:
            return
        payload = self._pickled(scene, settings, seed, sweep_points) if self.jobs else None
        if payload is None:  # the worker is stopped (it has only imported)
            self.close()
            self._counter = None
            return
        self._send(payload)

    def _reset(self) -> None:
        self.jobs = []
        self.results = {}
        self._process = None
        self._conn = None
        self._counter = None
        self._next = 0  # the caller's own count when there is no worker
        self._reader = None
        self._lock = threading.Lock()
        self._last = 0.0
        self._finished = False
        self._payload = None
        self.error = None

    def _memory_ok(self) -> bool:
        from explorer.memory import available_memory, format_bytes

        if available_memory() < WORKER_MEMORY:  # the same results serially rather than a machine swapping
            self.error = (f"{format_bytes(available_memory())} of memory available, below the "
                          f"{format_bytes(WORKER_MEMORY)} a worker process is given")
            return False
        return True

    def _pickled(self, scene: Any, settings: Any, seed: int, sweep_points: int) -> bytes | None:
        try:
            return pickle.dumps((scene, settings, int(seed), int(sweep_points), self.jobs),
                                protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:  # a sensor that does not pickle: the caller does every job
            self.error = f"the sensor does not pickle ({type(exc).__name__}: {exc})"
            return None

    def _spawn(self, methods: tuple[str, ...]) -> None:
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        self._counter = ctx.Value("q", 0)
        # duplex: the work goes to the worker and its results come back on one connection.  The work (the sensor,
        # megabytes) is sent by the reader thread, not as the process's arguments: those are written before
        # start() returns, and a pipe holds 64 KiB, so the caller waited for the new interpreter to start and
        # read them (0.6 s on the DIMAP export)
        self._conn, child = ctx.Pipe(duplex=True)
        self._process = ctx.Process(target=_worker, args=(self._counter, child, os.getpid(), methods),
                                    name="pushbroom-sweep", daemon=True)
        try:
            with _main_not_replayed():
                self._process.start()
        except Exception as exc:  # pragma: no cover - no process could be started (e.g. a script without a main guard)
            self.error = f"no worker process ({type(exc).__name__}: {exc})"
            self._process = None
            self._counter = None
        finally:
            child.close()

    def _send(self, payload: bytes) -> None:
        """Start the reader thread, which sends ``payload`` to the worker, then reads its results."""
        if self._process is None:
            return
        self._payload = payload
        self._last = time.monotonic()
        self._reader = threading.Thread(target=self._read, name="pushbroom-sweep-reader", daemon=True)
        self._reader.start()

    def claim(self) -> int | None:
        """The next job for the caller (its index in :attr:`jobs`), or None when every job is taken."""
        if self._counter is None:
            k, self._next = self._next, self._next + 1
            return k if k < len(self.jobs) else None
        with self._counter.get_lock():
            k = int(self._counter.value)
            if k >= len(self.jobs):
                return None
            self._counter.value = k + 1
        return k

    def _read(self) -> None:
        """The reader thread: send the worker its work, then receive its results as they come (a result is larger
        than a pipe's buffer: unread, the worker would block on its first send until the caller collects)."""
        conn = self._conn
        try:
            payload, self._payload = self._payload, None
            assert payload is not None
            conn.send_bytes(payload)
            while True:
                msg = conn.recv()
                if msg is None:
                    self._finished = True
                    return
                with self._lock:
                    self.results[int(msg[0])] = msg[1]
                    self._last = time.monotonic()
        except (EOFError, OSError):
            self.error = "the worker process ended before sending every result"
        except Exception as exc:  # pragma: no cover - a result that does not unpickle
            self.error = f"the worker's result could not be read ({type(exc).__name__}: {exc})"

    def collect(self) -> dict[int, tuple[str, Any]]:
        """Wait for the worker's results (until it says it is done, dies, or is silent for :data:`SILENT_S`) and
        return them by job index.  Jobs it took but did not deliver are absent: the caller computes them."""
        reader = self._reader
        if reader is None:
            return self.results
        try:
            while reader.is_alive():
                reader.join(1.0)
                with self._lock:
                    silent = time.monotonic() - self._last
                if reader.is_alive() and silent > SILENT_S:
                    self.error = f"the worker process was silent for {SILENT_S:g} s"
                    break
        finally:
            self.close()
        if self.error:
            _log.warn(f"accuracy-vs-SCOPs sweep: {self.error}; its remaining jobs were computed here")
        with self._lock:
            return dict(self.results)

    def close(self) -> None:
        """Stop the worker (if it still runs) and release the pipe."""
        if self._process is not None:
            if self._process.is_alive():
                self._process.join(timeout=5.0 if self._finished else 0.0)
            if self._process.is_alive():
                self._process.terminate()
                self._process.join(timeout=5.0)
            self._process = None
        if self._reader is not None:
            self._reader.join(timeout=5.0)  # the pipe's end closed by the worker's exit: the reader returns
        if self._conn is not None:
            self._conn.close()
            self._conn = None


__all__ = ["SILENT_S", "WORKER_MEMORY", "SweepPool"]
