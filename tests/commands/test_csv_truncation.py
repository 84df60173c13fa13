"""A CSV of points cut anywhere in its last line (issue 25, class 5): ``...,123.45`` cut to ``...,12`` is still a
number, so a cut file is caught by its missing final newline (every CSV writer ends its last record with one) and
by its field count, never read as if complete.  One stderr line names the file and the line.

Truth: the byte offsets of the cuts, and the numbers of the complete file (read back unchanged).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from explorer.cli import main
from explorer.errors import InputError
from explorer.io_input import read_points_csv

ROOT = Path(__file__).resolve().parents[2]
IKONOS = ROOT / "tests" / "data" / "rpc" / "rpc_IKONOS.txt"
TEXT = "lon,lat,h\n-56.17,-34.90,28.25\n-56.16,-34.91,30.125\n-56.165,-34.905,123.45\n"


def _one_line(capsys) -> str:
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and "Traceback" not in err[0], err
    return err[0]


def test_the_complete_file_is_read_with_its_numbers(tmp_path):
    path = tmp_path / "points.csv"
    path.write_text(TEXT)
    _, arrays = read_points_csv(path, ("lon", "lat", "h"))
    assert arrays["h"].tolist() == [28.25, 30.125, 123.45]


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_a_cut_anywhere_in_the_last_line_is_refused_naming_file_and_line(tmp_path, newline):
    text = TEXT.replace("\n", newline)
    last_line_start = text.rstrip(newline).rindex(newline) + len(newline)
    for cut in range(last_line_start + 1, len(text) - len(newline) + 1):  # "-", "-5", ..., "...,12", "...,123.45"
        path = tmp_path / "cut.csv"
        path.write_text(text[:cut], newline="")
        with pytest.raises(InputError) as info:
            read_points_csv(path, ("lon", "lat", "h"))
        message = str(info.value)
        assert str(path) in message and "line 4" in message, (cut, message)


def test_a_cut_line_with_a_final_newline_is_caught_by_its_field_count(tmp_path):
    path = tmp_path / "short.csv"
    path.write_text("lon,lat,h\n-56.17,-34.90,28.25\n-56.16,-34.91\n")
    with pytest.raises(InputError, match=r"line 3 has 2 fields, the header 3"):
        read_points_csv(path, ("lon", "lat", "h"))


def test_a_file_cut_inside_a_quoted_field_is_refused(tmp_path):
    path = tmp_path / "quoted.csv"
    path.write_text('id,lon,lat,h\n"a",-56.17,-34.90,28.25\n"b\n')
    with pytest.raises(InputError, match=r"quoted.csv: line \d+: malformed CSV"):
        read_points_csv(path, ("lon", "lat", "h"))


def test_line_numbers_are_the_files_own_across_blank_lines(tmp_path):
    path = tmp_path / "blank.csv"
    path.write_text("lon,lat,h\n\n-56.17,-34.90,28.25\n\n\n-56.16,-34.91,nan\n")
    with pytest.raises(InputError, match=r"line 6, column 'h'"):
        read_points_csv(path, ("lon", "lat", "h"))


def test_every_csv_command_refuses_a_cut_file_in_one_line_and_writes_nothing(tmp_path, capsys):
    cut = tmp_path / "cut.csv"
    cut.write_text(TEXT[:-4])  # "...,123.45\n" -> "...,123"
    digest = hashlib.sha256(cut.read_bytes()).hexdigest()
    out = tmp_path / "out.csv"
    assert main(["rpc", "project", str(IKONOS), "--points", str(cut), "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert str(cut) in line and "line 4" in line and "newline" in line
    matches = tmp_path / "matches.csv"
    matches.write_text("left_row,left_col,right_row,right_col\n10,20,11,21\n30,40,31,4")
    pair = [str(ROOT / "tests" / "data" / "rpc" / f"PHR1B_P_20170928103{n}_SEN_PRG_FC_17860{k}-001.geom")
            for n, k in (("8045", 8), ("8393", 9))]
    assert main(["stereo", "triangulate", *pair, "--matches", str(matches), "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert str(matches) in line and "line 3" in line
    assert not out.exists() and hashlib.sha256(cut.read_bytes()).hexdigest() == digest


def test_refines_reader_refuses_a_cut_file(tmp_path):
    pytest.importorskip("torch")
    from explorer.refine.points_io import read_points_csv as read_control_points

    text = "id,lon,lat,h,row,col\ng1,2.2,30.5,100,10.5,20.25\ng2,2.21,30.51,101,30.5,40.125\n"
    path = tmp_path / "gcps.csv"
    path.write_text(text)
    table = read_control_points(path)
    assert np.allclose(table.col, [20.25, 40.125])
    path.write_text(text[:-3])  # "40.125\n" -> "40.1"
    with pytest.raises(InputError, match=r"gcps.csv: line 3 .* does not end in a newline"):
        read_control_points(path)
