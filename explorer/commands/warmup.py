"""``pushbroom warmup``: compile every numba kernel once (numba's on-disk cache), see :mod:`explorer.warmup`."""

from __future__ import annotations

import argparse
import sys
import time


def cmd_warmup(args: argparse.Namespace) -> int:
    from explorer.warmup import warm_up

    def progress(message: str) -> None:
        if not args.quiet:
            print(message, file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    timings = warm_up(progress=progress)
    failed = [name for name, seconds in timings.items() if seconds < 0]
    progress(f"warm-up done in {time.perf_counter() - t0:.1f} s ({len(timings) - len(failed)} of {len(timings)} "
             f"steps){'; failed: ' + ', '.join(failed) if failed else ''}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("warmup", help="compile every numba kernel once so later commands start at once")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_warmup)
