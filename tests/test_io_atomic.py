"""explorer.io_atomic: the file appears under its name only when complete; killed writers' leftovers go."""

from __future__ import annotations

import os
import stat
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
    other = tmp_path / f".other.json.partial-{dead}"  # another file's leftover (issue 25: any write cleans up)
    other.write_text("x")
    folder = tmp_path / f".export.partial-{dead}"  # a killed folder writer's temporary folder
    folder.mkdir()
    (folder / "summary.json").write_text("{}")
    unrelated = tmp_path / ".notes.partial"  # not a leftover's name: kept
    unrelated.write_text("x")
    write_text_atomic(target, "{}")
    assert target.read_text() == "{}"
    assert not stale.exists() and not other.exists() and not folder.exists()
    assert live.exists() and unrelated.exists()


# ---------------------------------------------------------------------------------------------- issue 25
def test_non_regular_targets_are_refused_and_left_as_they_are(tmp_path):
    from explorer.errors import OutputError

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    for target in (fifo, "/dev/null"):
        with pytest.raises(OutputError, match="FIFO|character device"):
            write_text_atomic(target, "x")
    assert stat.S_ISFIFO(os.stat(fifo).st_mode) and stat.S_ISCHR(os.stat("/dev/null").st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe"]


def test_inputs_of_the_running_command_are_protected(tmp_path):
    from explorer.errors import OutputError
    from explorer.io_atomic import note_input, protect_inputs

    src = tmp_path / "in.json"
    src.write_text("original")
    write_text_atomic(src, "library code may overwrite")  # outside protect_inputs: allowed
    src.write_text("original")
    with protect_inputs():
        note_input(src)
        with pytest.raises(OutputError, match="is an input of this command"):
            write_text_atomic(src, "overwritten")
        write_text_atomic(tmp_path / "out.json", "fine")
    assert src.read_text() == "original"


WRITER = r"""
import signal, sys, time
from pathlib import Path
from explorer.errors import OutputError
from explorer.io_atomic import atomic_folder

def on_term(*_):
    raise KeyboardInterrupt
signal.signal(signal.SIGTERM, on_term)
run, target, pause = sys.argv[1], Path(sys.argv[2]), float(sys.argv[3])
try:
    with atomic_folder(target, ("summary.json", "residuals.csv")) as tmp:
        (tmp / "summary.json").write_text(run)
        print("writing", flush=True)
        time.sleep(pause)
        (tmp / "residuals.csv").write_text(run)
except OutputError as exc:
    print(exc, file=sys.stderr)
    sys.exit(2)
except KeyboardInterrupt:
    sys.exit(143)
"""


def test_concurrent_folder_writers_never_mix_their_files(tmp_path):
    """Four writers into one folder, three trials: each ends 0 (written whole) or 2 (refused, locked), and the
    folder holds the two files of one run; nothing else is left beside it."""
    target = tmp_path / "export"
    for trial in range(3):
        procs = [subprocess.Popen([sys.executable, "-c", WRITER, f"run{trial}-{k}", str(target), "0.3"],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for k in range(4)]
        codes = [p.wait(timeout=120) for p in procs]
        assert set(codes) <= {0, 2} and 0 in codes, codes
        summary, residuals = (target / "summary.json").read_text(), (target / "residuals.csv").read_text()
        assert summary == residuals and summary.startswith(f"run{trial}-")
        assert sorted(p.name for p in tmp_path.iterdir()) == ["export"]


def test_sigterm_and_full_disk_leave_the_previous_folder_and_nothing_else(tmp_path, monkeypatch):
    import errno
    import signal
    import time

    from explorer.io_atomic import atomic_folder

    target = tmp_path / "export"
    with atomic_folder(target, ("summary.json", "residuals.csv")) as tmp:
        (tmp / "summary.json").write_text("old")
        (tmp / "residuals.csv").write_text("old")
    proc = subprocess.Popen([sys.executable, "-c", WRITER, "new", str(target), "30"], stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout.readline().strip() == "writing"
    time.sleep(0.1)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=60) == 143
    assert sorted(p.name for p in tmp_path.iterdir()) == ["export"]
    assert (target / "summary.json").read_text() == "old"

    def full(self, data):  # noqa: ANN001 - the second file meets a full disk
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OSError, match="No space"), atomic_folder(target, ("summary.json", "residuals.csv")) as tmp:
        (tmp / "summary.json").write_text("new")
        monkeypatch.setattr(type(tmp), "write_text", full)
        (tmp / "residuals.csv").write_text("new")
    monkeypatch.undo()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["export"]
    assert (target / "residuals.csv").read_text() == "old"


def test_a_folder_holding_other_files_is_not_replaced(tmp_path):
    from explorer.errors import OutputError
    from explorer.io_atomic import atomic_folder

    (tmp_path / "mine.txt").write_text("the user's")
    with pytest.raises(OutputError, match="holds other files"), atomic_folder(tmp_path, ("summary.json",)):
        pass
    assert (tmp_path / "mine.txt").read_text() == "the user's"
