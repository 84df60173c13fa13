"""Atomic result files: a writer fills a temporary file beside the target and renames it into place only
when it is complete, so a failed, interrupted (Ctrl-C, SIGTERM) or killed run never leaves a file under the
final name. A killed run (SIGKILL) can leave only the hidden ``.<name>.partial-<pid>`` file, which the next
write into the same folder (of any name, by any command) removes once no process with that pid is alive.

Safety rules (``docs/validation.md``): an output is never written over an existing non-regular file (a
device such as ``/dev/null``, a FIFO, a socket: refused by its kind, never replaced by a file), nor over a
file the running command reads (:func:`protect_inputs`, switched on by the command line: ``scene from-isd
X.json --out X.json`` is refused).  A multi-file output (a folder) is written by :func:`atomic_folder`: into
a temporary folder renamed as a whole, under a lock that a concurrent writer of the same folder meets.
"""

from __future__ import annotations

import os
import re
import shutil
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from explorer.errors import OutputError

__all__ = [
    "atomic_folder", "atomic_path", "check_output_folder", "check_output_path", "file_kind", "note_input",
    "protect_inputs", "remove_stale_partials", "write_folder_atomic", "write_text_atomic",
]

#: (device, inode) of the files the running command reads, when :func:`protect_inputs` is on (else None).
_INPUTS: dict[tuple[int, int], str] | None = None


@contextmanager
def protect_inputs() -> Iterator[None]:
    """Within the block, refuse to write an output over any file read through :func:`note_input`.

    The command line runs every command inside it; library code (a notebook that loads a scene, edits it and
    saves it under the same name) is not restricted.
    """
    global _INPUTS
    previous, _INPUTS = _INPUTS, {}
    try:
        yield
    finally:
        _INPUTS = previous


def note_input(path: str | os.PathLike[str]) -> None:
    """Record ``path`` as an input of the running command (no effect outside :func:`protect_inputs`)."""
    if _INPUTS is None:
        return
    try:
        st = os.stat(path)
    except OSError:
        return
    _INPUTS[(st.st_dev, st.st_ino)] = str(path)


def file_kind(mode: int) -> str:
    """What a non-regular file is, in words (``"a FIFO (named pipe)"``, ``"a character device"``...), from its
    ``st_mode``: the one wording of every refusal of a special file (readers, writers, the CLI's path options)."""
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _check_existing_target(target: Path, path: str | os.PathLike[str]) -> None:
    """Refuse an existing non-regular file or an input of the running command at ``target``."""
    try:
        st = os.stat(target)
    except OSError:
        return
    if stat.S_ISDIR(st.st_mode):
        raise OutputError(f"output path {str(path)!r} is a directory; give a file name")
    if not stat.S_ISREG(st.st_mode):
        raise OutputError(f"output path {str(path)!r} is {file_kind(st.st_mode)}, not a regular file; "
                          "refusing to replace it")
    if _INPUTS is not None and (st.st_dev, st.st_ino) in _INPUTS:
        raise OutputError(f"output path {str(path)!r} is an input of this command "
                          f"({_INPUTS[(st.st_dev, st.st_ino)]!r}); refusing to overwrite it")


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
        If the path is a directory, an existing non-regular file (device, FIFO, socket), an input of the
        running command (:func:`protect_inputs`), or its folder is missing (and ``make_parents`` is false)
        or not writable.
    """
    target = Path(path)
    if str(path).strip() == "":
        raise OutputError("output path is empty")
    _check_existing_target(target, path)
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
        _check_existing_target(target, path)  # nothing took its place meanwhile (a FIFO, an input)
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


_LEFTOVER = re.compile(r"^\.(?P<name>.+)\.(?:partial|old)-(?P<pid>\d+)$")


def remove_stale_partials(folder: str | os.PathLike[str]) -> list[Path]:
    """Remove what killed writers left in ``folder``: ``.<name>.partial-<pid>`` files and folders (and the
    ``.<name>.old-<pid>`` folder of a folder swap) whose process is no longer alive.  Every atomic write
    calls it for its folder, so the next run of any command that writes there cleans up after a SIGKILL.

    Returns
    -------
    list of Path
        What was removed.
    """
    parent = Path(folder) if str(folder) else Path(".")
    try:
        entries = list(parent.iterdir())
    except OSError:
        return []
    removed = []
    for entry in entries:
        match = _LEFTOVER.match(entry.name)
        if match is None:
            continue
        pid = int(match.group("pid"))
        if pid == os.getpid() or _pid_alive(pid):
            continue
        try:
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
        except OSError:
            continue
        removed.append(entry)
    return removed


def _remove_stale_partials(target: Path) -> None:
    remove_stale_partials(target.parent if str(target.parent) else Path("."))


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically and return the path."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


_FOLDER_LOCKS: dict[str, int] = {}


def _lock_folder(target: Path) -> int:
    """Take the lock of the output folder ``target`` (a ``.<name>.lock`` file beside it), or refuse."""
    import fcntl

    lock = target.with_name(f".{target.name}.lock")
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        try:
            owner = os.read(fd, 32).decode(errors="replace").strip() or "?"
        except OSError:
            owner = "?"
        os.close(fd)
        raise OutputError(f"output folder {str(target)!r} is being written by another run (pid {owner}); "
                          "wait for it to end or choose another folder") from None
    try:
        same = os.stat(lock).st_ino == os.fstat(fd).st_ino
    except OSError:
        same = False
    if not same:  # the previous holder removed the lock file between our open and our lock
        os.close(fd)
        raise OutputError(f"output folder {str(target)!r} is being written by another run; "
                          "wait for it to end or choose another folder")
    os.ftruncate(fd, 0)
    os.write(fd, str(os.getpid()).encode())
    return fd


def _unlock_folder(target: Path, fd: int) -> None:
    """Remove the lock file (while still holding the lock) and release it."""
    try:
        target.with_name(f".{target.name}.lock").unlink(missing_ok=True)
    finally:
        os.close(fd)


def check_output_folder(path: str | os.PathLike[str]) -> Path:
    """Validate a folder output before any work starts: not an existing file or device, a writable parent.

    Raises
    ------
    OutputError
        Naming the path and the problem.
    """
    target = Path(path)
    if str(path).strip() == "":
        raise OutputError("output folder is empty")
    if target.exists() and not target.is_dir():
        raise OutputError(f"output folder {str(path)!r} exists and is not a folder")
    parent = target.parent if str(target.parent) else Path(".")
    existing = next((p for p in (parent, *parent.parents) if p.exists()), Path("/"))
    if not existing.is_dir() or not os.access(existing, os.W_OK):
        raise OutputError(f"output folder {str(path)!r} cannot be created ({str(existing)!r} is not writable)")
    return target


@contextmanager
def atomic_folder(path: str | os.PathLike[str], names: tuple[str, ...]) -> Iterator[Path]:
    """Yield a temporary folder beside ``path``; when the block ends without an error it becomes ``path``.

    The folder is written as a whole: readers see either the previous complete output or the new one,
    never a mix of two runs.  A concurrent writer of the same folder is refused
    (:class:`~explorer.errors.OutputError`, the lock ``.<name>.lock`` beside the folder); an interrupted,
    failed or out-of-disk run leaves no temporary folder, and a killed run's leftovers are removed by the
    next write.

    Parameters
    ----------
    path : path-like
        The output folder; created, or replaced if it holds only files of ``names`` (a previous output).
    names : tuple of str
        The files this output consists of; an existing folder holding anything else is refused (it is not
        ours to replace).

    Raises
    ------
    OutputError
        ``path`` is a file, a folder holding other files, or locked by another run; its parent is missing
        or not writable.
    """
    target = check_output_folder(path)
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"cannot create the folder {str(parent)!r}: {exc.strerror}") from exc
    if not os.access(parent, os.W_OK):
        raise OutputError(f"output folder {str(parent)!r} is not writable")
    fd = _lock_folder(target)
    tmp = target.with_name(f".{target.name}.partial-{os.getpid()}")
    old = target.with_name(f".{target.name}.old-{os.getpid()}")
    try:
        _remove_stale_partials(target)
        if target.is_dir():
            foreign = sorted(p.name for p in target.iterdir() if p.name not in names)
            if foreign:
                raise OutputError(f"output folder {str(path)!r} holds other files ({', '.join(foreign[:3])}"
                                  f"{', ...' if len(foreign) > 3 else ''}); give a new or empty folder")
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        yield tmp
        if target.is_dir():
            os.replace(target, old)
        os.replace(tmp, target)
        shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if old.is_dir() and not target.exists():
            os.replace(old, target)  # put the previous output back
        raise
    finally:
        _unlock_folder(target, fd)


def write_folder_atomic(path: str | os.PathLike[str], files: dict[str, bytes]) -> dict[str, Path]:
    """Write ``{name: bytes}`` as the folder ``path``, as a whole (:func:`atomic_folder`).

    Returns
    -------
    dict
        Name -> final path of each file.
    """
    out = Path(path)
    with atomic_folder(out, tuple(files)) as tmp:
        for name, data in files.items():
            (tmp / name).write_bytes(data)
    return {name: out / name for name in files}
