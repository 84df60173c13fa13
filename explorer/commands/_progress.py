"""A progress line on stderr while a command compiles kernels (:mod:`explorer.kernel_cache`).

``p.set_defaults(func=with_compile_progress("bench", cmd_bench))`` runs the handler inside
:func:`explorer.kernel_cache.reporting_compiles` with the units its arguments need.  Only the standard
library is imported here (``pushbroom --help`` stays fast).
"""

from __future__ import annotations

import argparse
import functools
from collections.abc import Callable

FILE_SOURCES = ("rpc", "scene", "dimap", "dg", "isd")


def command_units(command: str, args: argparse.Namespace) -> list[str]:
    """The warm-up units (:func:`explorer.kernel_cache.needed_units`) a ``bench`` / ``ortho`` / ``explore``
    invocation runs, from its parsed arguments; [] if they do not say (only the count shown depends on it)."""
    from explorer.kernel_cache import needed_units

    kind = next((k for k in FILE_SOURCES if getattr(args, k, None)), "preset")
    dem = bool(getattr(args, "dem", None))
    relief = float(getattr(args, "relief", 0.0) or 0.0) > 0
    if command == "ortho":
        method = getattr(args, "method", None)
        return needed_units("ortho", source=kind, methods=[method] if method else [], relief=relief, dem=dem)
    spec = getattr(args, "methods", None)
    try:
        from explorer.bench import resolve_methods

        methods = resolve_methods(spec) if spec else []
    except Exception:  # a bad --methods is the command's own error to report
        return []
    return needed_units(command, source=kind, methods=methods, relief=relief, dem=dem)


def with_compile_progress(command: str, handler: Callable[[argparse.Namespace], int]
                          ) -> Callable[[argparse.Namespace], int]:
    """``handler`` with a progress line on stderr while it compiles kernels (nothing when nothing compiles)."""

    @functools.wraps(handler)
    def run(args: argparse.Namespace) -> int:
        from explorer.kernel_cache import reporting_compiles

        try:
            units = command_units(command, args)
        except Exception:  # the count is a nicety: never stop a command for it
            units = []
        with reporting_compiles(units):
            return handler(args)

    return run


__all__ = ["command_units", "with_compile_progress"]
