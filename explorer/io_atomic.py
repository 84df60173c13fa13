"""Atomic result files: a writer fills a temporary file beside the target and renames it into place only
when it is complete, so a failed, interrupted (Ctrl-C, SIGTERM) or killed run never leaves a file under the
final name. A killed run (SIGKILL) can leave only the hidden ``.<name>.partial-<pid>`` file, which the next
write of the same name removes once no process with that pid is alive."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from explorer.errors import OutputError

__all__ = ["atomic_path", "check_output_path", "write_text_atomic"]


def check_output_path(path: str | os.PathLike[str], *, make_parents: bool = False) -> Path:
    """Validate that ``path`` can be written as a result file before any work starts.

    Parameters
    ----------
    path : path-like
        The target file.
    make_parents : bool
        Create missing parent folders instead of failing.

    Returns
    -------
    pathlib.Path
        The path.

    Raises
    ------
    OutputError
        If the path is a directory, its folder is missing (and ``make_parents`` is false) or not writable.
    """
    target = Path(path)
    if str(path).strip() == "":
        raise OutputError("output path is empty")
    if target.is_dir():
        raise OutputError(f"output path {str(path)!r} is a directory; give a file name")
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.exists():
        if not make_parents:
            raise OutputError(f"output folder {str(parent)!r} of {str(path)!r} does not exist")
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"cannot create the output folder {str(parent)!r}: {exc.strerror}") from exc
    if not parent.is_dir():
        raise OutputError(f"output folder {str(parent)!r} of {str(path)!r} is not a folder")
    if not os.access(parent, os.W_OK):
        raise OutputError(f"output folder {str(parent)!r} is not writable")
    return target


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` when the block ends without an error.

    On any exception (``KeyboardInterrupt`` and ``SystemExit`` included) the temporary file is removed and
    the exception propagates; an existing file at ``path`` is left untouched.

    Examples
    --------
    >>> with atomic_path("out.json") as tmp:  # doctest: +SKIP
    ...     tmp.write_text("{}")
    """
    target = check_output_path(path)
    _remove_stale_partials(target)
    tmp = target.with_name(f".{target.name}.partial-{os.getpid()}")
    try:
        yield tmp
        if not tmp.exists():
            raise OutputError(f"the writer of {str(path)!r} produced no file")
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # it exists but is not ours (EPERM)
        return True
    return True


def _remove_stale_partials(target: Path) -> None:
    """Remove ``.<name>.partial-<pid>`` files of ``target`` left by killed writers (their pid is not alive)."""
    prefix = f".{target.name}.partial-"
    parent = target.parent if str(target.parent) else Path(".")
    try:
        entries = list(parent.iterdir())
    except OSError:
        return
    for entry in entries:
        pid_text = entry.name[len(prefix):] if entry.name.startswith(prefix) else ""
        if pid_text.isdigit() and int(pid_text) != os.getpid() and not _pid_alive(int(pid_text)):
            entry.unlink(missing_ok=True)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically and return the path."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)
