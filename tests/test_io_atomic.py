"""explorer.io_atomic: the file appears under its name only when complete; killed writers' leftovers go."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from explorer.io_atomic import atomic_path, write_text_atomic


def test_failed_writer_leaves_nothing(tmp_path):
    target = tmp_path / "out.json"
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("writer failed")
    assert list(tmp_path.iterdir()) == []


def test_partial_of_a_killed_writer_is_removed_by_the_next_write(tmp_path):
    target = tmp_path / "out.json"
    # a real process that dies: its pid is then free (not alive)
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                          check=True)
    dead = int(proc.stdout)
    stale = tmp_path / f".out.json.partial-{dead}"
    stale.write_text("left by a SIGKILL")
    live = tmp_path / f".out.json.partial-{os.getppid()}"  # a live process (our parent): kept
    live.write_text("another writer, still running")
    other = tmp_path / f".other.json.partial-{dead}"  # another file's leftover: not ours to judge
    other.write_text("x")
    write_text_atomic(target, "{}")
    assert target.read_text() == "{}"
    assert not stale.exists()
    assert live.exists() and other.exists()
