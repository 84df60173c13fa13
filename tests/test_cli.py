import json

import numpy as np

from explorer.cli import main


def test_presets_json(capsys):
    assert main(["presets", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["id"] for r in rows} >= {"ISB", "PMA", "PAU", "QII", "SJB", "SAN", "SCB", "WBU", "WSA", "WSU",
                                       "linear", "agile"}


def test_simulate_writes_npz(tmp_path, capsys):
    out = tmp_path / "p.npz"
    assert main(["simulate", "--preset", "WSU", "--n", "100", "--layers", "2", "--relief", "0",
                 "--seed", "1", "--out", str(out)]) == 0
    assert "simulated 200" in capsys.readouterr().out
    with np.load(out) as z:
        assert z["ground"].shape == (200, 3) and z["row"].shape == (200,)
        assert json.loads(str(z["scene_json"]))["name"] == "WSU"


def test_unknown_preset_is_a_clear_error(capsys):
    assert main(["simulate", "--preset", "NOPE", "--n", "10"]) == 2
    assert "unknown preset" in capsys.readouterr().err


def _script_result(tmp_path, body: str):
    import subprocess
    import sys

    script = tmp_path / "script.py"
    script.write_text(body)
    return subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120,
                          cwd=tmp_path)


def test_exit_after_command_keeps_the_status_the_output_and_the_exit_handlers(tmp_path):
    """The fast exit of a finished command (explorer.cli.exit_after_command, no Python teardown) still runs the
    exit handlers, delivers buffered output to a pipe and ends with the command's status."""
    done = tmp_path / "handler_ran"
    proc = _script_result(tmp_path, f"""
import atexit, sys
from explorer.cli import exit_after_command
atexit.register(lambda: open({str(done)!r}, "w").write("yes"))
print("buffered line")
sys.stderr.write("error line")
exit_after_command(3)
print("never reached")
""")
    assert proc.returncode == 3
    assert proc.stdout == "buffered line\n"
    assert proc.stderr == "error line"
    assert done.read_text() == "yes"


def test_exit_after_command_waits_for_a_running_thread(tmp_path):
    """A thread that is not a daemon still runs: the normal exit (which waits for it) is taken."""
    done = tmp_path / "thread_done"
    proc = _script_result(tmp_path, f"""
import threading, time
from explorer.cli import exit_after_command
def work():
    time.sleep(0.5)
    open({str(done)!r}, "w").write("finished")
threading.Thread(target=work).start()
exit_after_command(0)
""")
    assert proc.returncode == 0, proc.stderr
    assert done.read_text() == "finished"


def test_the_command_line_entry_point_exits_with_the_commands_status(tmp_path):
    import subprocess
    import sys

    ok = subprocess.run([sys.executable, "-m", "explorer", "presets", "--json"], capture_output=True, text=True,
                        timeout=120)
    assert ok.returncode == 0 and {r["id"] for r in json.loads(ok.stdout)} >= {"WSU", "agile"}
    bad = subprocess.run([sys.executable, "-m", "explorer", "simulate", "--preset", "NOPE", "--n", "10"],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "unknown preset" in bad.stderr


def test_a_profiled_command_still_writes_its_statistics(tmp_path):
    """``python -m cProfile -o F -m explorer ...`` writes F after the command returns: under a profiler the
    command exits normally (explorer.cli.exit_after_command)."""
    import pstats
    import subprocess
    import sys

    out = tmp_path / "stats.prof"
    proc = subprocess.run([sys.executable, "-m", "cProfile", "-o", str(out), "-m", "explorer", "presets", "--json"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert pstats.Stats(str(out)).total_calls > 0
