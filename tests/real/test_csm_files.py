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

from explorer.errors import SceneFileError
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
