"""The ``pushbroom`` command line: thin wrappers over the library.

Each sub-command module in ``explorer.commands`` exposes ``register(subparsers)`` and imports only the
standard library at module level; the library is imported by the handler of the command that runs, so
``pushbroom --help`` and ``pushbroom <command> --help`` stay fast.

One error path: every deliberate error of the package (:class:`explorer.errors.ExplorerError`: a bad file,
a bad number, a bad path, an unknown name) and every file-system error ends the command with one line on
stderr naming the problem and exit status 2, as argparse does for bad arguments. Ctrl-C and SIGTERM stop the
command (writers remove their partial files) with exit status 130 / 143.  Anything else (a bug) still ends
as one line and exit status 2 (``PUSHBROOM_TRACEBACK=1`` shows the traceback); input validation
(``docs/validation.md``) exists so that this line is never the answer to a bad input.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import signal
import sys
import warnings
from typing import NoReturn

COMMAND_MODULES = (
    "explorer.commands.simulate",
    "explorer.commands.bench",
    "explorer.commands.explore",
    "explorer.commands.rpc",
    "explorer.commands.scene",
    "explorer.commands.ortho",
    "explorer.commands.warmup",
    "explorer.commands.refine",
    "explorer.commands.stereo",
)


class OneLineErrorParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (the problem and where to read the usage), exit 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    """The ``pushbroom`` parser with every sub-command (imports only the light command modules)."""
    parser = OneLineErrorParser(
        prog="pushbroom", description="Best scanline search for linear pushbroom images."
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def _command_name(args: argparse.Namespace) -> str:
    parts = [str(args.command)]
    for key in ("scene_command", "rpc_command", "stereo_command"):
        if getattr(args, key, None):
            parts.append(str(getattr(args, key)))
    return " ".join(parts)


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that writers clean up."""


def _on_sigterm(signum: int, frame: object) -> None:
    raise _Terminated()


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001
    print(f"pushbroom: warning: {_one_line(Warning(message))}", file=sys.stderr)


def _options_of(args: argparse.Namespace, value: str) -> list[str]:
    """The ``--options`` (or positional names) of ``args`` that hold ``value``."""
    return [key if key == "file" else "--" + key.replace("_", "-")
            for key, held in vars(args).items() if held == value and key not in ("func", "command")]


def _option_of(args: argparse.Namespace, value: str) -> str:
    return next(iter(_options_of(args, value)), repr(value))


def _same_file(a: str, b: str) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.abspath(a) == os.path.abspath(b)


def check_paths(args: argparse.Namespace, inputs: list[str], outputs: list[str]) -> str | None:
    """The problem with the command's paths, if any: an output that is an input or another output."""
    for i, out in enumerate(outputs):
        for other in outputs[i + 1:]:
            if _same_file(out, other):
                names = list(dict.fromkeys(_options_of(args, out) + _options_of(args, other))) or ["two outputs"]
                return (f"{' and '.join(names)} name the same file {out!r}; give each output its own name")
        for src in inputs:
            if _same_file(out, src):
                out_option = next((o for o in _options_of(args, out) if o != "file"), "an output")
                src_option = next((o for o in _options_of(args, src) if o != out_option), "")
                return (f"{out_option} {out!r} is the input {src_option or repr(src)}; "
                        "refusing to overwrite an input")
    return None


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit status."""
    from explorer.commands import parsed_paths

    parser = build_parser()
    parsed_paths.clear()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or a bad argument (2, message already printed)
        return exc.code if isinstance(exc.code, int) else 2
    name = _command_name(args)
    problem = check_paths(args, list(parsed_paths.INPUTS), list(parsed_paths.OUTPUTS))
    if problem is not None:
        print(f"pushbroom {name}: error: {problem}", file=sys.stderr)
        return 2
    previous = signal.signal(signal.SIGTERM, _on_sigterm)
    # one line per warning, no file paths -- while the command runs: restored after it, as the SIGTERM handler is
    # (left in place, a caller of main() -- a test, a notebook -- had every later warning of its process, from any
    # thread, printed on its stderr instead of going where it sent warnings)
    previous_showwarning = warnings.showwarning
    warnings.showwarning = _show_warning
    from explorer.errors import ExplorerError
    from explorer.io_atomic import note_input, protect_inputs

    try:
        with protect_inputs():
            for path in parsed_paths.INPUTS:
                note_input(path)
            return int(args.func(args) or 0)
    except ExplorerError as exc:
        print(f"pushbroom {name}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader of stdout went away (e.g. `| head`): stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except OSError as exc:  # file-system errors (rasterio's I/O errors derive from OSError too)
        where = f" {exc.filename!r}" if getattr(exc, "filename", None) else ""
        reason = exc.strerror or _one_line(exc)
        print(f"pushbroom {name}: error:{where} {reason}", file=sys.stderr)
        return 2
    except _Terminated:
        print(f"pushbroom {name}: terminated", file=sys.stderr)
        return 143
    except KeyboardInterrupt:
        print(f"pushbroom {name}: interrupted", file=sys.stderr)
        return 130
    except MemoryError:
        print(f"pushbroom {name}: error: out of memory; lower the sizes asked for (points, layers, --scps)",
              file=sys.stderr)
        return 2
    except Exception as exc:  # a bug: still one line (PUSHBROOM_TRACEBACK=1 shows the traceback)
        if os.environ.get("PUSHBROOM_TRACEBACK"):
            raise
        print(f"pushbroom {name}: error: unexpected {type(exc).__name__}: {_one_line(exc)} (a bug: please "
              "report it; PUSHBROOM_TRACEBACK=1 shows the traceback)", file=sys.stderr)
        return 2
    finally:
        signal.signal(signal.SIGTERM, previous)
        warnings.showwarning = previous_showwarning


def run() -> None:
    """The ``pushbroom`` / ``python -m explorer`` entry point: :func:`main`, then exit with its status.

    After Ctrl-C or SIGTERM the writers have removed their partial files by the time :func:`main` returns, but
    worker threads (a Dask pool, a kernel numba is still compiling) may still run; a normal exit would wait
    for them, so an interrupted command leaves at once instead.

    A command that finished leaves by :func:`exit_after_command`: its files are written and closed, and
    Python's own teardown of the process (freeing every array and compiled kernel, modules' finalizers) gave the
    user nothing but a wait -- 0.4 s after a DIMAP export, 0.8 s once torch was loaded (issue 24's 5 s bar).
    """
    code = main()
    if code in (130, 143):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    exit_after_command(code)


def exit_after_command(code: int) -> None:
    """End the process with status ``code`` once the command is done, without Python's teardown.

    The exit handlers still run first (``atexit``: logging's flush, multiprocessing's children, temporary
    directories), then standard output and error are flushed and the process ends (``os._exit``).  A normal exit
    is taken instead while a thread that is not a daemon still runs (the normal exit waits for it), and under a
    profiler or tracer (``python -m cProfile -m explorer ...`` writes its statistics after the command returns).
    """
    import atexit
    import threading

    if (any(t.is_alive() and not t.daemon for t in threading.enumerate() if t is not threading.main_thread())
            or sys.getprofile() is not None or sys.gettrace() is not None):
        sys.exit(code)
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(code)


if __name__ == "__main__":
    run()
