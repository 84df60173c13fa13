"""What every hostile-input test checks: one line on stderr, exit 2, nothing touched."""

from __future__ import annotations

import hashlib
import stat
from pathlib import Path


def snapshot(folder: Path) -> dict[str, str]:
    """Every regular file under ``folder`` with its SHA-256; special files (FIFO, socket, link) by kind."""
    out = {}
    for p in sorted(folder.rglob("*")):
        mode = p.lstat().st_mode
        out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest() if stat.S_ISREG(mode) else stat.filemode(mode)
    return out


def assert_one_line_refusal(status: int | str | None, err: str, words: list[str]) -> None:
    """Exit status 2 and exactly one stderr line (compile notices aside) containing every word, no traceback."""
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith("compiling")]
    assert status == 2, f"exit {status}; stderr: {err}"
    assert len(lines) == 1, f"expected one line on stderr, got:\n{err}"
    assert "Traceback" not in err
    for word in words:
        assert word.lower() in lines[0].lower(), f"{word!r} not in {lines[0]!r}"
