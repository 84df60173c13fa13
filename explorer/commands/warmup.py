"""``pushbroom warmup``: compile every numba kernel once (numba's on-disk cache), see :mod:`explorer.warmup`."""

from __future__ import annotations

import argparse
import sys
import time


def cmd_warmup(args: argparse.Namespace) -> int:
    if args.check:
        return check_cache()
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


def check_cache() -> int:
    """``pushbroom warmup --check``: list the kernels (of every unit of the manifest) numba's cache lacks."""
    from explorer.kernel_cache import kernels, manifest, uncached, unrecorded_uncached

    every = kernels(list(manifest()))
    missing = uncached(every)
    unrecorded = unrecorded_uncached()  # kernels the manifest does not know: warmup cannot compile them
    if not missing:
        print(f"all {len(every)} kernel signatures of the manifest are in numba's cache")
    else:
        names = sorted({k.label for k in missing})
        print(f"{len(missing)} of {len(every)} kernel signatures are not in numba's cache ({len(names)} kernels: "
              f"{', '.join(names)}); `pushbroom warmup` compiles them")
    if unrecorded:
        print(f"{len(unrecorded)} kernel(s) of the package are not in the manifest and not in numba's cache; they "
              f"compile at first use (`pushbroom warmup` does not know them): {', '.join(sorted(unrecorded))}")
    elif not missing:
        print("nothing will compile")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("warmup", help="compile every numba kernel once so later commands start at once")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument("--check", action="store_true",
                   help="only say which kernels are not in numba's on-disk cache (compiles nothing)")
    p.set_defaults(func=cmd_warmup)
