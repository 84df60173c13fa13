"""Fuzzing every reader with what a file system and an editor can do to a valid file (issue 25).

For the RPC readers (every real file of tests/data/rpc), the scene JSON readers, the CSV points reader and the
SRTM ``.hgt`` reader:

- **encodings**: the same content saved as UTF-8 with a byte-order mark, UTF-16 (BOM, little and big endian
  without one) or Latin-1 reads to exactly the model of the UTF-8 original (the independent truth);
- **truncation** at every 10 % of the file: refused with the package's error naming the file, or (a cut in
  trailing metadata the model does not use) exactly the original model, never another one;
- **byte flips** anywhere: a model or the package's error, never another exception;
- **special files** (a FIFO, ``/dev/null``, ``/dev/zero``, a directory, a symbolic link to a FIFO): refused by
  kind at once (an alarm fails the test if a reader blocks).

Deterministic (``derandomize=True``); ``FUZZ_EXAMPLES`` scales the count.
"""

from __future__ import annotations

import json
import os
import signal
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st

from explorer.errors import ExplorerError
from explorer.io_input import read_points_csv
from explorer.presets import build_scene
from explorer.real import load_scene
from explorer.rpc import read_rpc
from explorer.scene import Scene
from explorer.terrain_io import read_hgt

from .conftest import EXAMPLES, FUZZ

RPC_DIR = Path(__file__).resolve().parents[1] / "data" / "rpc"
RPC_FILES = sorted(p.name for p in RPC_DIR.iterdir() if p.suffix.lower() in (".txt", ".xml", ".rpb", ".geom", ".vrt")
                   and p.name != "rpc_unsupported.xml")
ENCODINGS = ["utf-8-sig", "utf-16", "utf-16-le", "utf-16-be", "latin-1"]
TMP = Path(tempfile.mkdtemp(prefix="fuzz_files_"))
FEW = settings(FUZZ, max_examples=max(20, EXAMPLES // 10))
SCENES = {p: build_scene(p, **kw).to_json() for p, kw in (("WSU", {}), ("agile", {}), ("QII", {"relief_m": 300.0}))}


def _same_rpc(a, b) -> bool:
    return all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("row_num", "row_den", "col_num", "col_den")) \
        and all(getattr(a, f"{k}_{s}") == getattr(b, f"{k}_{s}") for k in ("row", "col", "lat", "lon", "height")
                for s in ("offset", "scale"))


ORIGINAL_RPC = {name: read_rpc(RPC_DIR / name) for name in RPC_FILES}


@contextmanager
def _no_blocking(seconds: int = 10):
    def fail(*_):
        raise AssertionError(f"a reader blocked for {seconds} s on a special file")

    previous = signal.signal(signal.SIGALRM, fail)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _with_accent(name: str, text: str) -> str:
    """The text with a non-ASCII comment the format allows (so that Latin-1 differs from UTF-8)."""
    if name.lower().endswith((".xml", ".vrt")):
        end = text.index("?>") + 2 if text.lstrip().startswith("<?") else 0
        return text[:end] + "<!-- café Zürich -->" + text[end:]
    if name.lower().endswith(".rpb"):
        return text.replace("\n", '\n  note = "café";\n', 1)
    return text.replace("\n", "\nNOTE_CAFÉ: Zürich\n", 1)


@FUZZ
@given(st.sampled_from(RPC_FILES), st.sampled_from(ENCODINGS))
def test_rpc_files_in_any_text_encoding_read_to_the_same_model(name, encoding):
    text = _with_accent(name, (RPC_DIR / name).read_bytes().decode("utf-8"))
    path = TMP / f"enc_{name}"
    path.write_bytes(text.encode(encoding))
    assert _same_rpc(read_rpc(path), ORIGINAL_RPC[name])


@pytest.mark.parametrize("name", RPC_FILES)
def test_rpc_files_cut_at_every_tenth_are_refused_or_unchanged(name):
    data = (RPC_DIR / name).read_bytes()
    for pct in range(0, 100, 10):
        path = TMP / f"cut{pct}_{name}"
        path.write_bytes(data[: len(data) * pct // 100])
        try:
            model = read_rpc(path)
        except ExplorerError as exc:
            assert path.name in str(exc)
            continue
        assert _same_rpc(model, ORIGINAL_RPC[name]), f"{name} cut at {pct} % gave another model"


@FUZZ
@given(st.sampled_from(RPC_FILES), st.data())
def test_rpc_files_with_flipped_bytes_give_a_model_or_the_packages_error(name, data):
    raw = bytearray((RPC_DIR / name).read_bytes())
    for _ in range(data.draw(st.integers(1, 4))):
        pos = data.draw(st.integers(0, len(raw) - 1))
        raw[pos] ^= data.draw(st.integers(1, 255))
    path = TMP / f"flip_{name}"
    path.write_bytes(bytes(raw))
    try:
        read_rpc(path)
        event("read")
    except ExplorerError as exc:
        assert path.name in str(exc)
        event("refused")


@FEW
@given(st.sampled_from(sorted(SCENES)), st.sampled_from(ENCODINGS))
def test_scene_json_in_any_text_encoding_reads_to_the_same_scene(preset, encoding):
    text = SCENES[preset].replace(f'"name": "{preset}"', f'"name": "{preset} café"')
    path = TMP / f"{preset}_{encoding}.json"
    path.write_bytes(text.encode(encoding))
    for loader in (Scene.load, load_scene):
        scene = loader(path)
        assert scene.name == f"{preset} café"
        assert json.loads(scene.to_json())["exterior"] == json.loads(SCENES[preset])["exterior"]


@pytest.mark.parametrize("preset", sorted(SCENES))
def test_scene_json_cut_at_every_tenth_is_refused(preset):
    data = SCENES[preset].encode()
    for pct in range(0, 100, 10):
        path = TMP / f"cut{pct}_{preset}.json"
        path.write_bytes(data[: len(data) * pct // 100])
        for loader in (Scene.load, load_scene):
            with pytest.raises(ExplorerError, match=path.name):
                loader(path)


CSV_TEXT = "lon,lat,h\n-56.17,-34.90,28\n7.25,43.70,150.5\n"


@FEW
@given(st.sampled_from(["utf-8", *ENCODINGS]), st.sampled_from(["\n", "\r\n"]))
def test_points_csv_in_any_text_encoding_gives_the_same_numbers(encoding, newline):
    path = TMP / "points.csv"
    path.write_bytes(CSV_TEXT.replace("\n", newline).encode(encoding))
    _, arrays = read_points_csv(path, ("lon", "lat", "h"))
    assert arrays["lat"].tolist() == [-34.90, 43.70] and arrays["h"].tolist() == [28.0, 150.5]


@FUZZ
@given(st.binary(min_size=1, max_size=400))
def test_arbitrary_bytes_as_csv_rpc_or_scene_give_the_packages_error(blob):
    path = TMP / "blob.txt"
    path.write_bytes(blob)
    for read in (lambda p: read_points_csv(p, ("lon", "lat", "h")), read_rpc, load_scene):
        try:
            read(path)
        except ExplorerError as exc:
            assert "blob.txt" in str(exc)


def test_hgt_tiles_cut_or_little_endian_are_refused(tmp_path):
    n = 1201
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    heights = (200 + i + 2 * j).astype(">i2")
    good = tmp_path / "N43E007.hgt"
    heights.tofile(good)
    assert read_hgt(good).height(7.5, 43.5) == pytest.approx(200 + 600 + 1200)
    data = good.read_bytes()
    for pct in range(0, 100, 10):
        good.write_bytes(data[: len(data) * pct // 100])
        with pytest.raises(ExplorerError, match="N43E007"):
            read_hgt(good)
    heights.astype("<i2").tofile(good)
    with pytest.raises(ExplorerError, match="little-endian"):
        read_hgt(good)


@pytest.fixture(scope="module")
def special_files():
    folder = Path(tempfile.mkdtemp(prefix="fuzz_special_"))
    fifo = folder / "pipe.json"
    os.mkfifo(fifo)
    link = folder / "link.txt"
    link.symlink_to(fifo)
    return [fifo, link, Path("/dev/null"), Path("/dev/zero"), folder]


READERS = {
    "rpc": read_rpc, "scene": Scene.load, "load_scene": load_scene, "hgt": read_hgt,
    "csv": lambda p: read_points_csv(p, ("lon", "lat", "h")),
}


@pytest.mark.parametrize("reader", sorted(READERS))
def test_special_files_are_refused_without_blocking(reader, special_files):
    for path in special_files:
        with _no_blocking(), pytest.raises(ExplorerError):
            READERS[reader](path)


@FEW
@given(st.sampled_from(["utf-8", *ENCODINGS]))
def test_refine_control_points_csv_in_any_text_encoding_gives_the_same_table(encoding):
    from explorer.refine.points_io import read_points_csv as read_control_points

    text = "id,lon,lat,h,row,col\nA1,-56.17,-34.90,28,5237.5,6704.25\nA2,7.25,43.70,150.5,10,20\n"
    path = TMP / "gcps.csv"
    path.write_bytes(text.encode(encoding))
    table = read_control_points(path)
    assert list(table.ids) == ["A1", "A2"]
    assert np.array_equal(table.row, [5237.5, 10.0]) and np.array_equal(table.col, [6704.25, 20.0])
