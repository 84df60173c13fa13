"""The memory guard: estimate what a request will allocate before allocating, and refuse what cannot fit.

Commands that allocate in proportion to a number the user gives (``simulate --n``, ``explore --scps``,
``scene from-dimap --compare-points x --compare-layers``) or a file declares (a GeoTIFF header's width x
height) call :func:`check_allocation` with their estimate first.  A request larger than the memory the
machine can give (``MemAvailable`` of ``/proc/meminfo``, else the physical memory; at most the address space
limit of ``ulimit -v``) times :data:`USABLE_FRACTION` is refused with a
:class:`~explorer.errors.InputError` that gives the figure, what is available, and the option to change.
The environment variable ``PUSHBROOM_MEMORY_LIMIT`` (bytes, or with a ``K``/``M``/``G`` suffix) sets the
limit explicitly (tests, shared machines).
"""

from __future__ import annotations

import os
import re

from explorer.errors import InputError

__all__ = ["USABLE_FRACTION", "available_memory", "check_allocation", "format_bytes"]

#: Share of the available memory one request may take (the rest: the interpreter, numba, the OS cache).
USABLE_FRACTION = 0.8

_UNITS = {"": 1, "K": 1024, "M": 1024**2, "G": 1024**3, "T": 1024**4}


def format_bytes(n: float) -> str:
    """``n`` bytes in words (``"84.0 GiB"``)."""
    for unit, size in (("TiB", 1024**4), ("GiB", 1024**3), ("MiB", 1024**2), ("KiB", 1024)):
        if abs(n) >= size:
            return f"{n / size:.1f} {unit}"
    return f"{int(n)} bytes"


def _from_environment() -> int | None:
    text = os.environ.get("PUSHBROOM_MEMORY_LIMIT", "").strip().upper().removesuffix("B").removesuffix("I")
    match = re.fullmatch(r"(\d+(?:\.\d+)?)\s*([KMGT]?)", text)
    return int(float(match.group(1)) * _UNITS[match.group(2)]) if match else None


def available_memory() -> int:
    """Bytes this process may still allocate (see the module docstring for where the figure comes from)."""
    explicit = _from_environment()
    if explicit is not None:
        return explicit
    available = None
    try:
        with open("/proc/meminfo", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    available = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        pass
    if available is None:
        try:
            available = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES")
        except (ValueError, OSError, AttributeError):
            available = 8 * 1024**3
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft not in (resource.RLIM_INFINITY, -1) and soft > 0:
            available = min(available, soft)
    except (ImportError, OSError, ValueError):
        pass
    return int(available)


def check_allocation(n_bytes: float, what: str, option: str) -> None:
    """Refuse a request whose estimated allocation does not fit in memory.

    Parameters
    ----------
    n_bytes : float
        The estimate, in bytes (the peak the request needs, not one array).
    what : str
        What the memory is for, with the user's figures (``"1000000000 SCPs"``).
    option : str
        The option that sets the size, and how to change it (``"lower --n"``).

    Raises
    ------
    InputError
        If ``n_bytes`` exceeds :data:`USABLE_FRACTION` of :func:`available_memory`.
    """
    limit = USABLE_FRACTION * available_memory()
    if n_bytes > limit:
        raise InputError(f"{what} needs about {format_bytes(n_bytes)} of memory, more than the "
                         f"{format_bytes(limit)} this machine can give; {option}")
