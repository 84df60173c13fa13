"""benchmarks/rpc_perf.py on 10,000 points: ours, rpcm and shareloc agree on the same points."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rpcm")
pytest.importorskip("shareloc")

BENCH = Path(__file__).resolve().parent.parent / "benchmarks" / "rpc_perf.py"


def _rpc_perf():
    spec = importlib.util.spec_from_file_location("rpc_perf", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_rpc_perf_quick_logic_three_libraries_agree():
    rp = _rpc_perf()
    files = rp.rpc_files()
    names = {p.name for p in files}
    assert {"rpc_PLEIADES.xml", "rpc_WV1.xml", "rpc_IKONOS.txt"} <= names  # rpcm reads these
    assert "rpc_unsupported.xml" not in names  # read_rpc rejects it (a VRT under an .xml name)
    data = rp.run(files, n=10_000, seed=0, repeats=1)
    sources = {r["file"]: r["shareloc_source"] for r in data["files"]}
    assert sources["rpc_PLEIADES.xml"] == "file"  # shareloc reads the DIMAP files itself
    for rec in data["files"]:
        a = rec["agreement"]
        for other in ("ours-numpy", "rpcm", "shareloc"):
            assert a[other]["max_drow_px"] < 1e-6, (rec["file"], other)
            assert a[other]["max_dcol_px"] < 1e-6, (rec["file"], other)
        assert a["all_agree_1e-6_px"]
        # shareloc's pixel-corner convention: its (row, col) = ours + 0.5, to round-off
        offset = a["shareloc_offset"]
        for key in ("row_min", "row_max", "col_min", "col_max"):
            assert offset[key] == pytest.approx(rp.SHARELOC_SHIFT, abs=1e-6)
        assert a["ours-numpy"]["max_drow_px"] <= 1e-12 and a["ours-numpy"]["max_dcol_px"] <= 1e-12
        for impl in rp.IMPLS:
            t = rec["timings"][impl]
            assert len(t["wall_s"]) == 1 and t["median_s"] > 0 and np.isfinite(t["points_per_s"])
        assert set(rec["ratios"]) == {"ours/ours-numpy", "ours/rpcm", "ours/shareloc"}
    section = rp.markdown(data)
    assert section.startswith(rp.HEADING) and "rpc_PLEIADES.xml" in section


def test_points_are_seeded_and_inside_the_normalisation_box():
    rp = _rpc_perf()
    from explorer.rpc import read_rpc

    model = read_rpc(rp.RPC_DIR / "rpc_SPOT6.xml")  # its declared lon/lat box is swapped
    lon, lat, h = rp.draw_points(model, 1000, seed=5)
    lon2, _, _ = rp.draw_points(model, 1000, seed=5)
    np.testing.assert_array_equal(lon, lon2)
    assert np.all(np.abs(lon - model.lon_offset) <= abs(model.lon_scale))
    assert np.all(np.abs(lat - model.lat_offset) <= abs(model.lat_scale))
    assert np.all(np.abs(h - model.height_offset) <= abs(model.height_scale))


def test_append_doc_only_touches_its_own_section(tmp_path, monkeypatch):
    rp = _rpc_perf()
    doc = tmp_path / "performance.md"
    doc.write_text("# Performance\n\nother text\n\n## Another section\n\nkept\n")
    monkeypatch.setattr(rp, "DOC", doc)
    rp.append_doc(rp.HEADING + "\n\nfirst\n")
    rp.append_doc(rp.HEADING + "\n\nsecond\n")
    text = doc.read_text()
    assert text.startswith("# Performance\n\nother text\n\n## Another section\n\nkept\n\n")
    assert text.count(rp.HEADING) == 1 and text.endswith("second\n") and "first" not in text
