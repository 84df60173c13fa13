"""Unreadable ISD files (issue 25, class 2): every one a single-line SceneFileError naming the file and why.

Truth: the real CTX ISD of usgscsm's tests re-encoded (UTF-16 with and without a byte-order mark, UTF-8
with a mark, Latin-1 with a non-ASCII name) must read to the same camera as the original; junk, deep
nesting, 5,000-digit literals, truncation and special files must be refused, naming the file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from explorer.errors import ExplorerError, SceneFileError
from explorer.real.csm import read_isd

DATA = Path(__file__).resolve().parents[1] / "data" / "usgscsm"
CTX_TEXT = (DATA / "ctxLineScan.json").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def ctx():
    return read_isd(DATA / "ctxLineScan.json")


def _one_line_naming(exc: pytest.ExceptionInfo, path: Path, *words: str) -> None:
    msg = str(exc.value)
    assert msg.startswith(str(path)) and "\n" not in msg, msg
    for w in words:
        assert w in msg, msg


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "utf-8-sig", "latin-1"])
def test_reencoded_isd_reads_the_same_camera(ctx, tmp_path, encoding):
    data = json.loads(CTX_TEXT)
    data["name_sensor"] = "CONTEXT CAMERA é"  # a character outside ASCII: Latin-1 and UTF-8 differ
    p = tmp_path / f"ctx_{encoding}.json"
    p.write_bytes(json.dumps(data, ensure_ascii=False).encode(encoding))
    cam = read_isd(p)
    assert cam.metadata["sensor"] == "CONTEXT CAMERA é"
    lines, samples = np.array([10.0, 5000.0, 11000.0]), np.array([20.0, 2500.0, 4990.0])
    np.testing.assert_array_equal(cam.image_to_ground(lines, samples, 0.0).ground,
                                  ctx.image_to_ground(lines, samples, 0.0).ground)


@pytest.mark.parametrize(
    ("content", "words"),
    [
        (np.random.default_rng(3).integers(0, 256, 20000, dtype=np.uint8).tobytes(), ("binary",)),
        (b"\x00\x01\x02\x03" * 500, ("binary",)),
        (("[" * 100000 + "]" * 100000).encode(), ("nested",)),
        (CTX_TEXT.replace('"image_lines": 11264', '"image_lines": 1' + "0" * 5000).encode(), ("number literal",)),
        (CTX_TEXT.replace('"image_lines": 11264', '"image_lines": 1.' + "5" * 5000).encode(), ("number literal",)),
        (CTX_TEXT[: len(CTX_TEXT) // 2].encode(), ("not valid JSON",)),
        (b"", ("empty",)),
        (b'{"image_lines": NaN}', ("image_lines",)),
    ],
    ids=["random-bytes", "nul-bytes", "nested", "5000-digit-int", "5000-digit-float", "truncated", "empty", "nan"],
)
def test_unreadable_isd_is_one_line_naming_the_file(tmp_path, content, words):
    assert '"image_lines": 11264' in CTX_TEXT
    p = tmp_path / "bad_isd.json"
    p.write_bytes(content)
    with pytest.raises(SceneFileError) as exc:
        read_isd(p)
    _one_line_naming(exc, p, *words)


def test_special_files_are_refused_without_blocking(tmp_path):
    fifo = tmp_path / "isd.fifo"
    os.mkfifo(fifo)
    with pytest.raises(SceneFileError) as exc:
        read_isd(fifo)  # opening a FIFO with no writer would block forever
    _one_line_naming(exc, fifo, "FIFO")
    with pytest.raises(SceneFileError) as exc:
        read_isd(tmp_path)
    _one_line_naming(exc, tmp_path, "directory")
    with pytest.raises(SceneFileError) as exc:
        read_isd(tmp_path / "missing.json")
    _one_line_naming(exc, tmp_path / "missing.json", "no such file")


# ----------------------------------------------------------------------------- fuzz
ORBITAL = (DATA / "orbitalLineScan.json").read_bytes()
FLIPS = settings(max_examples=300, derandomize=True, database=None, deadline=None,
                 suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _read_or_package_error(path: Path) -> str:
    """'camera' or 'refused' (a SceneFileError / InputError naming the file); anything else fails the test."""
    try:
        cam = read_isd(path)
    except ExplorerError as exc:
        msg = str(exc)
        assert msg.startswith(str(path)) and "\n" not in msg, msg
        return "refused"
    # a camera that was built answers with finite numbers or flags, never raises
    g = cam.image_to_ground(np.array([8.0]), np.array([8.0]), 0.0)
    r = cam.ground_to_image(np.where(np.isfinite(g.ground), g.ground, 0.0))
    assert r.valid.dtype == bool and (not r.valid[0] or np.isfinite(r.line[0]))
    return "camera"


@FLIPS
@given(st.data())
def test_isd_with_flipped_bytes_gives_a_camera_or_one_line_naming_the_file(tmp_path_factory, data):
    raw = bytearray(ORBITAL)
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(raw) - 1))
        # half the flips write a character of a number, so that most files stay JSON and reach the checks
        raw[i] = data.draw(st.one_of(st.integers(0, 255), st.sampled_from(list(b"0123456789-.eE"))))
    p = tmp_path_factory.mktemp("flip") / "orbital_flipped.json"
    p.write_bytes(bytes(raw))
    event(_read_or_package_error(p))


@pytest.mark.parametrize("tenth", range(1, 10))
def test_isd_cut_at_every_tenth_is_refused(tmp_path, tenth):
    p = tmp_path / "orbital_cut.json"
    p.write_bytes(ORBITAL[: len(ORBITAL) * tenth // 10])
    with pytest.raises(SceneFileError) as exc:
        read_isd(p)
    _one_line_naming(exc, p)
