"""Serving the explorer: the listening address checked before anything starts, then :func:`serve`.

:func:`check_listen_address` turns every address problem into one
:class:`~explorer.errors.InputError` naming it -- a port outside 0..65535, a busy port (viser
would silently move to the next one), a ``--host`` that is not an address of this machine or
does not resolve (viser would retry forever) -- before a server exists.  :func:`serve` prints
the URL as soon as the server listens and runs until Ctrl-C / SIGTERM; :func:`run_explore`
is ``pushbroom explore`` (source validation first, then ``--export`` or serving).
"""

from __future__ import annotations

import errno
import logging
import signal
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

from explorer.errors import InputError

RESOLVE_TIMEOUT_S = 3.0
"""How long a host name may take to resolve before it is an error (no network: no hang)."""
TRIM_DELAY_S = 2.0
"""After a browser leaves, freed memory is handed back to the system this much later (once for a
group of browsers leaving together)."""


def release_freed_memory() -> bool:
    """Hand memory the process has freed back to the operating system (glibc ``malloc_trim``).

    Each browser receives the whole scene (plotly.js alone is ~3.5 MB), encoded in buffers that are
    freed when it leaves; glibc keeps freed heap pages in its per-thread arenas, so without a trim
    the resident memory of a long-running explorer only grows with the browsers it has seen.
    Returns False where there is no glibc (nothing to do).
    """
    import ctypes
    import ctypes.util
    import gc

    gc.collect()
    name = ctypes.util.find_library("c")
    if not name:
        return False
    try:
        libc = ctypes.CDLL(name)
        return bool(libc.malloc_trim(0))
    except (OSError, AttributeError):
        return False


MALLOC_ARENAS = 2
"""glibc malloc arenas the serving process may use (``mallopt(M_ARENA_MAX)``)."""
MMAP_THRESHOLD = 1 << 20
"""Allocations from this size (bytes) get their own mapping, returned on free (``M_MMAP_THRESHOLD``)."""


def limit_malloc_arenas(n: int = MALLOC_ARENAS, mmap_threshold: int = MMAP_THRESHOLD) -> bool:
    """Tune glibc's allocator for a server whose browsers come and go.

    Each browser is sent the whole scene (plotly.js alone is 3.5 MB) in buffers freed when it
    leaves.  glibc (a) gives threads their own arenas (up to 8 per core) and (b) after freeing a
    large mapped block raises its mmap threshold, so later large buffers come from the heap and
    fragment it; freed memory is then neither reused nor returned.  Over 500 browser visits the
    resident memory grew by ~40 % (plateauing ~11 % above idle with the arenas capped alone).  Two
    arenas (``M_ARENA_MAX``) and a fixed 1 MiB mmap threshold (which also stops the dynamic
    raise), with :func:`release_freed_memory` after browsers leave, keep it within ~2 % of idle
    (``tests/test_explorer_soak.py``).  False where there is no glibc.
    """
    import ctypes
    import ctypes.util

    name = ctypes.util.find_library("c")
    if not name:
        return False
    try:
        libc = ctypes.CDLL(name)
        ok = libc.mallopt(-8, int(n))  # M_ARENA_MAX
        return bool(ok and libc.mallopt(-3, int(mmap_threshold)))  # M_MMAP_THRESHOLD
    except (OSError, AttributeError):
        return False


class _Trimmer:
    """Runs :func:`release_freed_memory` once, ``TRIM_DELAY_S`` after the last of a group of
    disconnects (a viser ``on_client_disconnect`` callback)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._timer: threading.Timer | None = None
        self.trims = 0

    def __call__(self, _client: Any = None) -> None:
        with self._lock:
            if self._timer is not None:
                self._timer.cancel()
            self._timer = threading.Timer(TRIM_DELAY_S, self._run)
            self._timer.daemon = True
            self._timer.start()

    def _run(self) -> None:
        release_freed_memory()
        self.trims += 1

    def cancel(self) -> None:
        with self._lock:
            if self._timer is not None:
                self._timer.cancel()


def _resolve(host: str, port: int) -> list[tuple]:
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["infos"] = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        except OSError as exc:
            box["error"] = exc

    th = threading.Thread(target=run, daemon=True)
    th.start()
    th.join(RESOLVE_TIMEOUT_S)
    if th.is_alive():
        raise InputError(f"--host {host!r} did not resolve within {RESOLVE_TIMEOUT_S:g} s")
    if "error" in box:
        raise InputError(f"--host {host!r} does not resolve to an address ({box['error']})")
    return box["infos"]


def check_listen_address(host: str, port: int) -> None:
    """Raise :class:`InputError` unless a server can listen on ``host``:``port`` now.

    Parameters
    ----------
    host : str
        Interface name or address (must be an address of this machine).
    port : int
        0..65535; 0 picks a free port (always fine).
    """
    if not isinstance(port, int) or isinstance(port, bool) or not 0 <= port <= 65535:
        raise InputError(f"--port {port!r} is not a port number (0..65535; 0 picks a free one)")
    infos = _resolve(host, port)
    last: OSError | None = None
    for family, kind, proto, _, addr in infos:
        with socket.socket(family, kind, proto) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server will
            try:
                s.bind(addr)
                return
            except OSError as exc:
                last = exc
                if exc.errno == errno.EADDRINUSE:
                    raise InputError(f"port {port} on {host} is busy (another program listens there); "
                                     "choose another --port, or --port 0 for a free one") from None
    if last is not None and last.errno == errno.EADDRNOTAVAIL:
        raise InputError(f"--host {host!r} is not an address of this machine (use 127.0.0.1, or 0.0.0.0 "
                         "for every interface)")
    raise InputError(f"cannot listen on {host}:{port}: {last}")


class _OneLineClientErrors(logging.Filter):
    """Turn the websocket server's per-connection tracebacks (a malformed frame or message from a client: not
    a bug of the explorer, and any client can send them) into one line each, at most one per second."""

    def __init__(self) -> None:
        super().__init__()
        self._last = 0.0
        self.dropped = 0

    def filter(self, record: logging.LogRecord) -> bool:
        if record.exc_info and record.exc_info[1] is not None:
            exc = record.exc_info[1]
            record.msg = (f"pushbroom explorer: closed a client connection after a malformed message "
                          f"({type(exc).__name__}: {' '.join(str(exc).split())[:120]})")
            record.args = None
            record.exc_info = None
            record.exc_text = None
        now = time.monotonic()
        if now - self._last < 1.0:
            self.dropped += 1
            return False
        self._last = now
        return True


def quiet_client_errors() -> _OneLineClientErrors:
    """Install :class:`_OneLineClientErrors` on the ``websockets`` server logger (idempotent); return it."""
    logger = logging.getLogger("websockets.server")
    for existing in logger.filters:
        if isinstance(existing, _OneLineClientErrors):
            return existing
    one_line = _OneLineClientErrors()
    logger.addFilter(one_line)
    return one_line


def serve(preset: str | None = None, host: str = "127.0.0.1", port: int = 8080, *,
          methods: list[str] | None = None, ready: Callable[[Any], None] | None = None,
          stop_event: threading.Event | None = None, sources: list | None = None, **app_kwargs: Any) -> int:
    """Run the explorer until Ctrl-C / SIGTERM (or ``stop_event``), then stop cleanly.

    Prints the URL as soon as the server listens; the scene fills in as it is computed.

    Parameters
    ----------
    preset : str, optional
        Scene shown first (a preset id or a source's label).
    host, port
        ``port=0`` picks a free port (the printed URL names it); a busy port or a host that
        is not local is an :class:`InputError` (:func:`check_listen_address`).
    methods : list of str, optional
        Methods checked at start (default :data:`explorer.app.model.DEFAULT_METHODS` that are
        registered).
    ready : callable, optional
        Called with the :class:`~explorer.app.gui.ExplorerApp` (its ``url`` set) once the server
        listens.
    stop_event : threading.Event, optional
        Stop when set (for running in a thread); Ctrl-C and SIGTERM stop the main thread.
    sources : list of explorer.sources.Source, optional
        Loaded scenes offered first in the scene dropdown.
    **app_kwargs
        Passed to :class:`~explorer.app.gui.ExplorerApp`.

    Returns
    -------
    int
        0 after a clean stop (worker joined, server stopped, port released).
    """
    check_listen_address(host, port)
    quiet_client_errors()  # a malformed websocket frame: one line, not a traceback per frame
    import viser

    from explorer.app.gui import ExplorerApp

    t0 = time.perf_counter()
    limit_malloc_arenas()
    server = viser.ViserServer(host=host, port=port, label="pushbroom explorer", verbose=False)
    if port and server.get_port() != port:  # taken between the check and the bind
        server.stop()
        raise InputError(f"port {port} on {host} is busy (another program listens there); "
                         "choose another --port, or --port 0 for a free one")
    trimmer = _Trimmer()
    # every websocket that closes (the connection layer; viser's public hook only sees browsers
    # that got as far as reporting a camera)
    infra = getattr(server, "_websock_server", None)
    (infra if infra is not None and hasattr(infra, "on_client_disconnect") else server).on_client_disconnect(trimmer)
    url = f"http://{host}:{server.get_port()}"
    print(f"pushbroom explorer: {url}  (Ctrl-C to stop)", flush=True)
    app = None
    stop = stop_event or threading.Event()
    old = None
    if threading.current_thread() is threading.main_thread():
        old = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        loading = server.gui.add_markdown("**Loading the methods...**")
        app = ExplorerApp(server, preset=preset, methods=methods, sources=sources or [], **app_kwargs)
        app.trimmer = trimmer
        loading.remove()
        app.url = url
        app.startup_s = time.perf_counter() - t0
        if ready is not None:
            ready(app)
        while not stop.wait(0.25):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        if app is not None:
            app.close()
        trimmer.cancel()
        server.stop()
        if old is not None:
            signal.signal(signal.SIGTERM, old)
        print("pushbroom explorer: stopped", flush=True)
    return 0


def run_explore(args: Any) -> int:
    """``pushbroom explore``: validate the source (and the address), then export or serve.

    ``args`` has the source options (``preset``, ``scene``, ``rpc``, ``dimap``, ``dg``, ``isd``,
    ``dem``), ``host``, ``port``, ``methods`` and optionally ``export``, ``scops``, ``scps``,
    ``seed``.  Every problem is raised as an :mod:`explorer.errors` error before a URL is
    printed.
    """
    from explorer.app.model import DEFAULT_METHODS
    from explorer.kernel_cache import CompileProgress, TerminalLine, expected_compiles, needed_units
    from explorer.sources import SOURCE_KINDS, source_from_args

    methods = [m for m in args.methods.split(",") if m] if getattr(args, "methods", None) else None
    export = getattr(args, "export", None)
    if export is None:
        check_listen_address(args.host, args.port)  # fail before the (slow) source is loaded
    # a progress line on stderr while numba compiles kernels (loading a real source may compile some too);
    # its total: what the source kind and the methods need and numba's cache lacks
    kind = next((k for k in SOURCE_KINDS if k != "preset" and getattr(args, k, None)), "preset")
    if kind == "preset" and getattr(args, "adjusted", None):  # a sidecar alone: the kind it records
        from explorer.sources import sidecar_source

        kind = sidecar_source(args.adjusted)[0]
    units = needed_units("explore", source=kind, methods=methods if methods is not None else DEFAULT_METHODS,
                         dem=bool(getattr(args, "dem", None)))
    progress = CompileProgress(expected_compiles(units), [TerminalLine()]).install()
    early_pool = None
    try:
        if export is not None:  # the sweep's worker imports while the source loads (closed below if unused)
            from explorer.app.export import early_sweep_pool

            early_pool = early_sweep_pool(methods, sweep=not getattr(args, "no_sweep", False))
        source = source_from_args(args)
        scops = getattr(args, "scops", None) or 100
        scps = getattr(args, "scps", None) or 50_000
        seed = getattr(args, "seed", None) or 0
        if export is not None:
            from explorer.app.export import run_export

            run_export(source, export, methods=methods, scops=scops, scps=scps, seed=seed,
                       sweep=not getattr(args, "no_sweep", False), early_pool=early_pool)
            return 0
        if methods is not None:
            from explorer.methods import available

            names = available()
            unknown = [m for m in methods if m not in names]
            if unknown:
                raise InputError(f"unknown method(s) {', '.join(unknown)}; available: {', '.join(names)}")
        from explorer.app.model import ExplorerModel

        ready = _refine_folder(args, source) if getattr(args, "gcps", None) else None
        # the GUI shows its own line (ExplorerApp; each update counts what it needs, _expect_compiles)
        return serve(source.label, host=args.host, port=args.port, methods=methods, ready=ready,
                     sources=[source] if source.scene is not None else [],
                     model=ExplorerModel(seed=seed), scp_count=scps, scop_density=scops, compile_progress=progress,
                     sweep=not getattr(args, "no_sweep", False))
    finally:
        if early_pool is not None:  # a source or a setting refused: the worker stops
            early_pool.close()
        progress.uninstall()
        progress.finish()

def _refine_folder(args: Any, source: Any) -> Callable[[Any], None]:
    """``--gcps``: read the points and the sensor now (errors before serving); the *Refinement* folder
    (:mod:`explorer.app.refine_view`) is added once the app is up, drawing the trajectories in its 3D scene."""
    from explorer.app.refine_view import RefineView, refine_target_of
    from explorer.refine.points_io import read_points_csv

    control = read_points_csv(args.gcps)
    check = read_points_csv(args.check) if getattr(args, "check", None) else None
    target = refine_target_of(source)

    def ready(app: Any) -> None:
        app.refine_view = RefineView(app.server.gui, target, control, check, sigma_px=getattr(args, "sigma_px", 0.5),
                                     scene_api=app.server.scene, display_frame=lambda: getattr(app, "frame", None),
                                     on_drawn=app._layout_labels)
        app.refine_label = source.label
        app.request_update(debounce=False)  # the view framed again, the trajectories inside it

    return ready


__all__ = ["check_listen_address", "limit_malloc_arenas", "quiet_client_errors", "release_freed_memory", "run_explore",
           "serve"]
