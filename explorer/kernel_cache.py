"""Which compiled kernels are not in numba's on-disk cache yet, and a progress line while numba compiles them.

Every numba kernel of the package is compiled with ``cache=True`` (:mod:`explorer.warmup`): numba keeps one
index file per kernel (``<module>.<function>-<line>.py311.nbi`` in ``__pycache__`` next to the module, or under
``$NUMBA_CACHE_DIR``) mapping ``(argument types, CPU name and features, hash of the function's bytecode)`` to
the machine code, stamped with numba's version and the source file's hash.  :func:`is_cached` asks exactly the
question numba asks before it compiles -- is that key in a valid index? -- without loading or compiling
anything (a pickle read per kernel, a few milliseconds for all of them).

What a command needs is a union of *units* (:func:`explorer.warmup.kernel_units`: the scene and point
simulation on every preset, each method, relief, the RPC model, orthorectification); the manifest
``explorer/kernel_manifest.json`` lists, per unit, the kernels called from Python and their argument types,
recorded by running the unit (``python -m explorer.warmup --record``).  :func:`needed_units` maps a
command's options to units and :func:`uncached` lists what of them is missing: a new installation, another
numba version, another CPU, an edited source file, or a cache directory numba cannot write to.

:class:`CompileProgress` follows numba's ``numba:compile`` events (fired only when numba really compiles, never
for a cache hit) and tells its observers -- the terminal line of :class:`TerminalLine`, the explorer's GUI --
which kernel is compiling and how many of the expected ones are done, so nothing is shown when nothing
compiles and something is shown whenever something does, whatever the manifest predicted.
"""

from __future__ import annotations

import contextlib
import importlib
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, TextIO

__all__ = ["PROGRESS_PREFIX", "CompileProgress", "Kernel", "TerminalLine", "compile_kernels", "expected_compiles",
           "is_cached", "kernels", "manifest", "needed_units", "package_kernels", "reporting_compiles", "uncached",
           "unrecorded_uncached"]

WARMUP_HINT = "run `pushbroom warmup` once to skip this"
PROGRESS_PREFIX = "compiling kernels for first use: "
"""How each line of :class:`TerminalLine` starts (a command's stderr has them before its own output when numba
compiles kernels its cache lacks)."""


@dataclass(frozen=True)
class Kernel:
    """One compiled kernel called from Python with one signature.

    Attributes
    ----------
    module : str
        Module that defines it, e.g. ``"explorer.rpc.inverse"``.
    name : str
        Its name in that module (a numba dispatcher).
    signature : str
        ``repr`` of the tuple of numba argument types, e.g. ``"(Array(float64, 1, 'C', False, aligned=True),)"``.
    """

    module: str
    name: str
    signature: str

    @property
    def label(self) -> str:
        """Short name for progress lines, e.g. ``"rpc.inverse._dem_blocks"``."""
        return f"{self.module.removeprefix('explorer.')}.{self.name}"


#: The generated data file beside this module (package data of the wheel).
MANIFEST_NAME = "kernel_manifest.json"


def manifest() -> dict[str, tuple[Kernel, ...]]:
    """The recorded kernels per unit (``explorer/kernel_manifest.json``); empty if it is missing."""
    import json
    from importlib.resources import files

    try:
        doc = json.loads(files("explorer").joinpath(MANIFEST_NAME).read_text(encoding="utf-8"))
    except (OSError, ValueError):  # pragma: no cover - a build without the manifest: nothing is predicted
        return {}
    table = [Kernel(*entry) for entry in doc["kernels"]]
    return {unit: tuple(table[i] for i in indices) for unit, indices in doc["units"].items()}


def kernels(units: Iterable[str]) -> list[Kernel]:
    """The kernels of ``units`` (unknown units contribute nothing), each once, in manifest order."""
    table = manifest()
    seen: dict[Kernel, None] = {}
    for unit in units:
        for k in table.get(unit, ()):
            seen.setdefault(k, None)
    return list(seen)


def needed_units(command: str, *, source: str = "preset", methods: Sequence[str] = (), relief: bool = False,
                 dem: bool = False) -> list[str]:
    """Units a command runs.

    Parameters
    ----------
    command : {"explore", "bench", "ortho"}
    source : str
        Source kind (:data:`explorer.sources.SOURCE_KINDS`, or ``"rpc"`` / ``"preset"`` for ortho).
    methods : sequence of str
        Best-scanline methods it evaluates (explore, bench; ortho's ``--method``).
    relief : bool
        Terrain with relief (a preset's relief, or any DEM).
    dem : bool
        A DEM is given (``--dem``).
    """
    relief = relief or dem
    units: list[str] = []
    if command == "ortho":
        units.append("ortho")
        if source == "rpc":
            units.append("rpc")
        else:
            units.append("scene:relief" if relief else "scene")
            units += [f"method:{m}" for m in methods]
        return units
    units.append("scene:relief" if relief else "scene")
    if source in ("rpc", "isd"):
        units.append(source)
    if source in ("dimap", "dg", "scene"):  # a rigorous line-scan model (a scene file may hold one)
        units.append("linescan")
    for m in methods:
        units.append(f"method:{m}")
        if relief:
            units.append(f"method:{m}:relief")
    if command == "explore":
        units.append("csv")  # the export's residuals.csv (--export, the GUI's Export button)
    return units


# ------------------------------------------------------------------------------------------- the cache
def _types_namespace() -> dict[str, Any]:
    from numba.core import types

    ns = dict(vars(types))
    ns["bool"] = types.boolean  # repr(types.boolean) is "bool"
    return ns


def _signature(kernel: Kernel) -> tuple | None:
    """The argument types of ``kernel`` (None if the recorded text no longer parses)."""
    try:
        sig = eval(kernel.signature, {"__builtins__": {}}, _types_namespace())  # noqa: S307 - numba type reprs only
    except Exception:
        return None
    return tuple(sig) if isinstance(sig, tuple) else None


def _dispatcher(kernel: Kernel) -> Any:
    """The numba dispatcher of ``kernel``, or None (numba off, the kernel renamed or removed)."""
    from explorer._numba import NUMBA_AVAILABLE

    if not NUMBA_AVAILABLE:
        return None
    try:
        module = importlib.import_module(kernel.module)
    except Exception:
        return None
    disp = getattr(module, kernel.name, None)
    return disp if hasattr(disp, "overloads") and hasattr(disp, "py_func") else None


def _index(disp: Any) -> dict | None:
    """The valid entries of ``disp``'s cache index (numba's own reader: empty if the index is missing, of
    another numba version or of another source file); None if the kernel cannot be cached at all."""
    cache = getattr(disp, "_cache", None)
    cache_file = getattr(cache, "_cache_file", None)
    if cache_file is None:  # numba's NullCache: no writable cache location, it compiles in every process
        return None
    return cache_file._load_index()


def is_cached(kernel: Kernel) -> bool:
    """True if calling ``kernel`` with its signature compiles nothing: it is in memory already, or numba's
    on-disk cache holds it for this CPU, this numba and the current source (also True when numba is off or the
    kernel no longer exists: nothing to compile).  Loads and compiles nothing."""
    disp = _dispatcher(kernel)
    if disp is None:
        return True
    sig = _signature(kernel)
    if sig is not None and sig in disp.overloads:
        return True
    try:
        index = _index(disp)
        if not index:
            return False
        codegen = disp.targetctx.codegen()
        if sig is not None:
            return disp._cache._index_key(sig, codegen) in index
        # a signature that no longer parses: cached if any entry is for this CPU and this bytecode
        _, magic, hashes = disp._cache._index_key((), codegen)
        return any(key[1] == magic and key[2] == hashes for key in index)
    except Exception:  # numba's private cache API changed: say it may compile (only a count is affected)
        return False


def _has_cache_entry(disp: Any) -> bool:
    """True if ``disp`` is compiled in memory, or numba's index holds any entry for this CPU and this bytecode."""
    if getattr(disp, "overloads", None):
        return True
    try:
        index = _index(disp)
        if index is None:
            return False
        if not index:
            return False
        _, magic, hashes = disp._cache._index_key((), disp.targetctx.codegen())
        return any(key[1] == magic and key[2] == hashes for key in index)
    except Exception:  # numba's private cache API changed: say it may compile
        return False


def package_kernels() -> list[tuple[str, str]]:
    """``(module, name)`` of every numba kernel of the package (modules whose source uses numba -- ``jit``,
    ``explorer._numba.kernel`` -- are imported to find their dispatchers; the explorer's GUI modules are not)."""
    from importlib.resources import files

    from explorer._numba import NUMBA_AVAILABLE

    if not NUMBA_AVAILABLE:
        return []
    found = []
    root = files("explorer")
    stack = [(root, "explorer")]
    while stack:
        folder, dotted = stack.pop()
        for entry in sorted(folder.iterdir(), key=lambda e: e.name):
            if entry.is_dir() and entry.name not in ("app", "__pycache__") and not entry.name.startswith("."):
                stack.append((entry, f"{dotted}.{entry.name}"))
            elif entry.name.endswith(".py"):
                text = entry.read_text(encoding="utf-8")
                if "jit" not in text and "@kernel" not in text and "numba" not in text:
                    continue
                module_name = dotted if entry.name == "__init__.py" else f"{dotted}.{entry.name[:-3]}"
                try:
                    module = importlib.import_module(module_name)
                except Exception:  # an optional dependency missing: not this machine's kernels
                    continue
                for name, obj in sorted(vars(module).items()):
                    if hasattr(obj, "overloads") and _is_package_kernel(obj) and obj.py_func.__module__ == module_name:
                        found.append((module_name, name))
    return found


def unrecorded_uncached() -> list[str]:
    """Labels of the package's kernels that the manifest does not list and numba's cache does not hold for
    this CPU and source: they compile at first use, and ``pushbroom warmup`` (which compiles the manifest)
    cannot compile them ahead.  Kernels called only from other kernels compile and are cached with their
    caller, so after one use they no longer appear."""
    import inspect
    import re

    recorded = {(k.module, k.name) for k in kernels(list(manifest()))}
    found = [(m, n, getattr(importlib.import_module(m), n)) for m, n in package_kernels()]
    sources = {}
    for m, n, disp in found:
        try:
            sources[(m, n)] = inspect.getsource(disp.py_func)
        except (OSError, TypeError):
            sources[(m, n)] = ""
    out = set()
    for m, n, disp in found:
        if (m, n) in recorded or disp.targetoptions.get("inline") == "always":
            continue
        # a call, not a definition: a serial twin (``_numba.serial_twin``) has its parallel variant's source
        called = re.compile(rf"(?<!def )\b(?:{re.escape(disp.py_func.__name__)}|{re.escape(n)})\s*\(")
        if any(called.search(src) for key, src in sources.items() if key != (m, n)):
            continue  # called from another kernel: compiled (and cached) with it, never on its own
        if not _has_cache_entry(disp):
            out.add(_label(disp))
    return sorted(out)


def uncached(units_or_kernels: Iterable[str] | Iterable[Kernel]) -> list[Kernel]:
    """The kernels of the given units (or the given kernels) that would be compiled, in manifest order."""
    items: list[Any] = list(units_or_kernels)
    ks: list[Kernel] = kernels(items) if items and isinstance(items[0], str) else items
    return [k for k in ks if not is_cached(k)]


def expected_compiles(units: Iterable[str]) -> set[str]:
    """The kernels numba would compile for ``units``, named as :class:`CompileProgress` names them: the
    functions with a signature missing from the cache (a function compiles once per run: one scene gives
    one argument type per kernel)."""
    out = set()
    for k in uncached(list(units)):
        disp = _dispatcher(k)
        out.add(_label(disp) if disp is not None else k.label)
    return out


def compile_kernels(ks: Iterable[Kernel]) -> list[str]:
    """Compile (or load from the cache) each kernel for its recorded argument types, without running it.

    Returns the failures as ``"label: error"`` (a kernel whose recorded types no longer fit it)."""
    failures = []
    for k in ks:
        disp, sig = _dispatcher(k), _signature(k)
        if disp is None:
            continue
        if sig is None:
            failures.append(f"{k.label}: argument types {k.signature} do not parse")
            continue
        try:
            disp.compile(sig)
        except Exception as exc:  # reported; the kernel then compiles on first use
            failures.append(f"{k.label}: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}")
    return failures


# ---------------------------------------------------------------------------------------- progress
def _is_package_kernel(disp: Any) -> bool:
    fn = getattr(disp, "py_func", None)
    return bool(fn is not None and str(getattr(fn, "__module__", "")).startswith("explorer."))


def _label(disp: Any) -> str:
    fn = disp.py_func
    return f"{fn.__module__.removeprefix('explorer.')}.{fn.__qualname__}"


class CompileProgress:
    """Follows numba's compilations of the package's kernels and tells observers.

    ``expected`` names the kernels predicted to compile (:func:`expected_compiles`); ``compiled`` those
    compiled from Python so far (a kernel compiled inside another one is part of that one), ``current`` the
    one compiling; the total shown is both together, so a kernel nobody predicted still counts.  An
    observer ``f(progress, finished)`` is called when a kernel starts and ends (``finished`` False), and once
    with ``finished`` True from :meth:`finish` if anything compiled -- which happens by itself once every
    predicted kernel is compiled.

    Parameters
    ----------
    expected : iterable of str
        Kernels predicted to compile, as ``"module.function"`` without the leading ``explorer.``.
    observers : sequence of callable(CompileProgress, bool)
    """

    def __init__(self, expected: Iterable[str] = (),
                 observers: Sequence[Callable[[CompileProgress, bool], None]] = ()) -> None:
        self.expected: set[str] = set(expected)
        self.compiled: set[str] = set()
        self.current: str | None = None
        self.t_first: float | None = None
        self.seconds = 0.0
        self.observers = list(observers)
        self._lock = threading.RLock()
        self._depth = threading.local()
        self._listener: Any = None

    @property
    def done(self) -> int:
        return len(self.compiled)

    @property
    def total(self) -> int:
        """The predicted kernels and any other that compiled or is compiling."""
        return len(self.expected | self.compiled | ({self.current} if self.current else set()))

    @property
    def position(self) -> int:
        """The number of the kernel compiling now (1-based), else of the last compiled."""
        return self.done + (self.current is not None and self.current not in self.compiled)

    @property
    def started(self) -> bool:
        """Something compiled (or is compiling) since the last :meth:`finish`."""
        return bool(self.compiled) or self.current is not None

    @property
    def compiling(self) -> bool:
        return self.current is not None

    def _notify(self, finished: bool) -> None:
        for f in list(self.observers):
            with contextlib.suppress(Exception):  # a failing observer must not break a compilation
                f(self, finished)

    def kernel_started(self, label: str) -> None:
        depth = getattr(self._depth, "n", 0)
        self._depth.n = depth + 1
        if depth:
            return
        with self._lock:
            if self.t_first is None:
                self.t_first = time.perf_counter()
            self.current = label
            self._notify(False)

    def kernel_finished(self, label: str) -> None:
        self._depth.n = max(getattr(self._depth, "n", 1) - 1, 0)
        if self._depth.n:
            return
        with self._lock:
            self.compiled.add(label)
            self.current = None
            if self.t_first is not None:
                self.seconds = time.perf_counter() - self.t_first
            self._notify(False)
            if self.expected and self.expected <= self.compiled:
                self.finish()  # all that was predicted; anything after starts a new count

    def finish(self) -> None:
        """Report the end (if anything compiled) and start counting afresh (nothing expected)."""
        with self._lock:
            if self.compiled and not self.compiling:
                self._notify(True)
                self.compiled = set()
                self.expected = set()
                self.t_first = None
                self.seconds = 0.0

    # numba's event API
    def install(self) -> CompileProgress:
        """Listen to numba's ``numba:compile`` events (every thread) until :meth:`uninstall`."""
        from explorer._numba import NUMBA_AVAILABLE

        if not NUMBA_AVAILABLE or self._listener is not None:
            return self
        from numba.core import event

        progress = self

        class _Listener(event.Listener):
            def on_start(self, ev: Any) -> None:
                disp = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
                if disp is not None and _is_package_kernel(disp):
                    progress.kernel_started(_label(disp))

            def on_end(self, ev: Any) -> None:
                disp = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
                if disp is not None and _is_package_kernel(disp):
                    progress.kernel_finished(_label(disp))

        self._listener = _Listener()
        event.register("numba:compile", self._listener)
        return self

    def uninstall(self) -> None:
        if self._listener is None:
            return
        from numba.core import event

        with contextlib.suppress(Exception):
            event.unregister("numba:compile", self._listener)
        self._listener = None


class TerminalLine:
    """The terminal's progress line (an observer of :class:`CompileProgress`).

    On a terminal one line is rewritten in place; otherwise one plain line per kernel, e.g.
    ``compiling kernels for first use: 3/11 (rpc.inverse._dem_blocks) ...`` and at the end
    ``compiling kernels for first use: done, 11 kernels in 41 s; run `pushbroom warmup` once to skip this``.
    """

    def __init__(self, stream: TextIO | None = None, tty: bool | None = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)()) if tty is None else tty
        self._open = False

    def __call__(self, progress: CompileProgress, finished: bool) -> None:
        if finished:
            text = (f"{PROGRESS_PREFIX}done, {progress.done} kernel{'s' * (progress.done != 1)} in "
                    f"{progress.seconds:.0f} s; {WARMUP_HINT}")
            self._write(text, end=True)
            return
        if progress.current is None:  # a kernel ended: the next start rewrites the line
            return
        self._write(f"{PROGRESS_PREFIX}{progress.position}/{progress.total} ({progress.current}) ...",
                    end=False)

    def _write(self, text: str, end: bool) -> None:
        if self.tty:
            self.stream.write("\r\x1b[K" + text + ("\n" if end else ""))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()


@contextlib.contextmanager
def reporting_compiles(units: Sequence[str], stream: TextIO | None = None) -> Iterator[CompileProgress]:
    """Show a progress line on ``stream`` (stderr) while the block compiles any of the package's kernels.

    The total is what :func:`uncached` predicts for ``units``; nothing is printed if nothing compiles.
    """
    progress = CompileProgress(expected_compiles(units) if units else (), [TerminalLine(stream)]).install()
    try:
        yield progress
    finally:
        progress.uninstall()
        progress.finish()
