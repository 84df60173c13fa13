"""RPC projection (ground lon/lat/height -> image row/col) throughput: ours vs rpcm vs CNES shareloc.

Usage::

    python benchmarks/rpc_perf.py                  # 5,000,000 points per RPC file, every file rpcm reads (~5 min)
    python benchmarks/rpc_perf.py --quick          # 200,000 points per file (well under a minute)
    python benchmarks/rpc_perf.py --files rpc_PLEIADES.xml,rpc_WV1.xml --points 1000000
    python benchmarks/rpc_perf.py --append-doc     # also put the section at the end of docs/performance.md
    python benchmarks/rpc_perf.py --report --append-doc   # only rebuild that section from rpc_perf.json

For every RPC file in ``tests/data/rpc`` that both rpcm (``rpc_from_rpc_file``) and our ``read_rpc`` read,
the same process draws ``--points`` seeded random ground points uniformly inside the model's normalisation
box, offset +- |scale| in longitude, latitude and height (not the file's declared validity box, see
:func:`sampling_box`), and projects the *same* arrays with

* ours: ``RationalFunctionModel.projection(lon, lat, h)`` -> ``(row, col)`` (compiled numba loop), and the
  same method with ``backend="numpy"`` (the numpy path, for reference);
* rpcm: ``RPCModel.projection(lon, lat, alt)`` -> ``(col, row)``, same 0-based pixel-centre convention;
* shareloc: ``RPC.inverse_loc(lon, lat, alt)`` -> ``(row, col, alt)`` (its numba kernel), pixel-corner
  convention: shareloc ``(row, col)`` = ours + 0.5 (its readers add 0.5 to the offsets).  shareloc 0.3 reads
  only the DIMAP files here; for the others its ``RPC`` class is built from our model's coefficients with
  that +0.5 (``shareloc_source`` in the records), so the timing is still its evaluator on the same numbers.

Timing: one warm-up call per implementation on the full set (numba compiles or loads its cache there), then
``--repeats`` rounds (default 5), each calling the implementations one after another (round-robin, so load
changes on the shared machine hit all of them alike); the median wall time (``time.perf_counter``) and
process CPU time (``time.process_time``, all threads) are reported.  Memory: one more untimed call each,
after resetting the process's peak RSS (``/proc/self/clear_refs``, Linux), gives the peak RSS
(``resource.getrusage``) during that call and how much above the resident size before it.  The
agreement of the three is measured on all the points (max |d row|, max |d col| in pixels, our convention),
with the shareloc offset checked numerically.  Results: ``benchmarks/results/rpc_perf.json`` and a markdown
section ``benchmarks/results/rpc_perf.md`` (``--append-doc`` puts it at the end of ``docs/performance.md``,
replacing an earlier copy of the same section; nothing else in that file is touched).

The machine is shared: every record keeps the load average before and after.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import logging
import os
import platform
import resource
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from explorer.rpc import RationalFunctionModel, read_rpc  # noqa: E402

RPC_DIR = ROOT / "tests" / "data" / "rpc"
RESULTS = ROOT / "benchmarks" / "results" / "rpc_perf.json"
SECTION_MD = ROOT / "benchmarks" / "results" / "rpc_perf.md"
DOC = ROOT / "docs" / "performance.md"
HEADING = "## RPC projection: ours vs rpcm vs shareloc"
IMPLS = ("ours", "ours-numpy", "rpcm", "shareloc")
SHARELOC_SHIFT = 0.5  # shareloc (row, col) = ours + 0.5 (pixel corner vs pixel centre), docs/rpc.md
AGREE_PX = 1e-6


# ------------------------------------------------------------------------------------------ models and points
def rpc_files(names: list[str] | None = None) -> list[Path]:
    """Files of tests/data/rpc that rpcm and :func:`read_rpc` both read (all of them, or ``names``)."""
    import rpcm

    candidates = [RPC_DIR / n for n in names] if names else sorted(RPC_DIR.iterdir())
    out = []
    for path in candidates:
        if path.suffix.lower() not in (".xml", ".txt", ".rpb", ".vrt", ".geom"):
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                rpcm.rpc_from_rpc_file(str(path))
            read_rpc(path)
        except Exception:  # noqa: BLE001 - "rpcm cannot read it" takes many forms
            if names:
                raise
            continue
        out.append(path)
    return out


def shareloc_params(model: RationalFunctionModel) -> dict:
    """Parameters of shareloc's ``RPC`` for our model, in shareloc's pixel-corner convention (+0.5)."""
    return {
        "driver_type": "explorer",
        "offset_x": model.lon_offset, "scale_x": model.lon_scale,
        "offset_y": model.lat_offset, "scale_y": model.lat_scale,
        "offset_alt": model.height_offset, "scale_alt": model.height_scale,
        "offset_row": model.row_offset + SHARELOC_SHIFT, "scale_row": model.row_scale,
        "offset_col": model.col_offset + SHARELOC_SHIFT, "scale_col": model.col_scale,
        "num_row": list(model.row_num), "den_row": list(model.row_den),
        "num_col": list(model.col_num), "den_col": list(model.col_den),
        "num_x": None, "den_x": None, "num_y": None, "den_y": None,
    }  # fmt: skip


def load_models(path: Path) -> dict:
    """Our model, rpcm's and shareloc's for one file; ``shareloc_source`` says how shareloc got it."""
    import rpcm
    from shareloc.geomodels import GeoModel
    from shareloc.geomodels.rpc import RPC

    ours = read_rpc(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        peer = rpcm.rpc_from_rpc_file(str(path))
    logging.getLogger().setLevel(max(logging.getLogger().level, logging.WARNING))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sl = GeoModel(str(path), "RPC")
        source = "file"
    except (ValueError, KeyError, IndexError):
        sl = RPC(shareloc_params(ours))
        source = "our coefficients (+0.5)"
    return {"ours": ours, "rpcm": peer, "shareloc": sl, "shareloc_source": source}


def sampling_box(model: RationalFunctionModel) -> dict:
    """The normalisation box offset +- |scale| (lon, lat in degrees, h in metres).

    Not ``model.domain``: that takes a file's declared box as written, and ``rpc_SPOT6.xml`` (from rpcm's
    tests) declares ``FIRST_LON``/``LAST_LON`` = 18.39..18.76 and ``FIRST_LAT``/``LAST_LAT`` = -72.44..-72.10
    while ``LONG_OFF`` = -72.27, ``LAT_OFF`` = 18.58: its longitude and latitude are swapped, and points drawn
    there are hundreds of normalised units outside the fit.
    """
    return {
        "lon": [model.lon_offset - abs(model.lon_scale), model.lon_offset + abs(model.lon_scale)],
        "lat": [model.lat_offset - abs(model.lat_scale), model.lat_offset + abs(model.lat_scale)],
        "h": [model.height_offset - abs(model.height_scale), model.height_offset + abs(model.height_scale)],
    }


def draw_points(model: RationalFunctionModel, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` ground points uniform in :func:`sampling_box` (lon, lat in degrees, h in metres), seeded."""
    box = sampling_box(model)
    rng = np.random.default_rng(seed)
    lon = rng.uniform(*box["lon"], n)
    lat = rng.uniform(*box["lat"], n)
    h = rng.uniform(*box["h"], n)
    return lon, lat, h


def calls(models: dict, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> dict:
    """The raw library call of each implementation on the same arrays (what is timed)."""
    ours, peer, sl = models["ours"], models["rpcm"], models["shareloc"]
    return {
        "ours": lambda: ours.projection(lon, lat, h),
        "ours-numpy": lambda: ours.projection(lon, lat, h, backend="numpy"),
        "rpcm": lambda: peer.projection(lon, lat, h),
        "shareloc": lambda: sl.inverse_loc(lon, lat, h),
    }


def to_ours(name: str, result: tuple) -> tuple[np.ndarray, np.ndarray]:
    """A library's output as (row, col) in our 0-based pixel-centre convention."""
    if name in ("ours", "ours-numpy"):
        return result[0], result[1]
    if name == "rpcm":
        col, row = result
        return np.asarray(row), np.asarray(col)
    row, col, _alt = result  # shareloc, pixel corner
    return np.asarray(row) - SHARELOC_SHIFT, np.asarray(col) - SHARELOC_SHIFT


def agreement(models: dict, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> dict:
    """Max |d row|, |d col| (pixels) of every implementation against ``ours``, and the shareloc offset."""
    fns = calls(models, lon, lat, h)
    raw = {name: fns[name]() for name in IMPLS}
    row0, col0 = to_ours("ours", raw["ours"])
    out: dict = {}
    for name in IMPLS[1:]:
        row, col = to_ours(name, raw[name])
        out[name] = {"max_drow_px": float(np.max(np.abs(row - row0))), "max_dcol_px": float(np.max(np.abs(col - col0)))}
    out["ours-numpy"]["bit_identical"] = bool(
        np.array_equal(raw["ours"][0], raw["ours-numpy"][0]) and np.array_equal(raw["ours"][1], raw["ours-numpy"][1])
    )
    sl_row, sl_col, _ = raw["shareloc"]
    out["shareloc_offset"] = {  # measured shareloc - ours: SHARELOC_SHIFT on both axes
        "row_min": float(np.min(sl_row - row0)), "row_max": float(np.max(sl_row - row0)),
        "col_min": float(np.min(sl_col - col0)), "col_max": float(np.max(sl_col - col0)),
    }  # fmt: skip
    out["max_disagreement_px"] = max(max(v["max_drow_px"], v["max_dcol_px"]) for k, v in out.items() if k in IMPLS)
    out["all_agree_1e-6_px"] = out["max_disagreement_px"] < AGREE_PX
    return out


# ------------------------------------------------------------------------------------------------ measuring
def _rss_mb() -> tuple[float, float]:
    """(peak RSS from getrusage, current RSS from /proc/self/statm), MB."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kilobytes
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
        current = pages * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        current = float("nan")
    return peak, current


def _reset_peak_rss() -> bool:
    try:
        Path("/proc/self/clear_refs").write_text("5")  # Linux >= 4.0: peak RSS := current RSS
        return True
    except OSError:
        return False


def time_round_robin(fns: dict, repeats: int) -> dict:
    """One warm-up call each, then ``repeats`` rounds calling every function once; wall and CPU times."""
    for fn in fns.values():
        fn()
    walls: dict = {k: [] for k in fns}
    cpus: dict = {k: [] for k in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            t0, c0 = time.perf_counter(), time.process_time()
            fn()
            walls[name].append(time.perf_counter() - t0)
            cpus[name].append(time.process_time() - c0)
    return {k: {"wall_s": walls[k], "cpu_s": cpus[k], "median_s": statistics.median(walls[k]),
                "median_cpu_s": statistics.median(cpus[k])} for k in fns}  # fmt: skip


def memory_per_call(fns: dict) -> dict:
    """Peak RSS (getrusage) during one call of each function, and its rise above the RSS before the call."""
    out = {}
    for name, fn in fns.items():
        reset = _reset_peak_rss()
        _, before = _rss_mb()
        result = fn()
        peak, _ = _rss_mb()
        del result
        out[name] = {"peak_rss_mb": peak, "rss_before_mb": before, "call_extra_mb": peak - before, "reset": reset}
    return out


def bench_file(path: Path, n: int, seed: int = 0, repeats: int = 5) -> dict:
    """Time and compare the implementations on ``n`` points of one RPC file."""
    models = load_models(path)
    lon, lat, h = draw_points(models["ours"], n, seed)
    rec: dict = {"file": path.name, "format": models["ours"].source_format, "n": n, "seed": seed,
                 "shareloc_source": models["shareloc_source"], "load_before": os.getloadavg()}  # fmt: skip
    rec["sampling_box"] = sampling_box(models["ours"])
    fns = calls(models, lon, lat, h)
    rec["timings"] = time_round_robin(fns, repeats)
    rec["load_after"] = os.getloadavg()
    mem = memory_per_call(fns)
    for name, t in rec["timings"].items():
        t["points_per_s"] = n / t["median_s"] if t["median_s"] > 0 else float("nan")
        t.update(mem[name])
    t_ours = rec["timings"]["ours"]["median_s"]
    rec["ratios"] = {f"ours/{k}": t_ours / rec["timings"][k]["median_s"] for k in IMPLS[1:]}
    rec["agreement"] = agreement(models, lon, lat, h)
    return rec


def versions() -> dict:
    import numba
    import rpcm
    import shareloc

    def version(mod) -> str:
        try:
            from importlib.metadata import version as v

            return v({"rpcm": "rpcm", "shareloc": "shareloc"}.get(mod.__name__, mod.__name__))
        except Exception:  # noqa: BLE001
            return getattr(mod, "__version__", "?")

    try:
        layer = numba.threading_layer()
    except ValueError:  # no parallel region run yet
        layer = "not initialised"
    return {"numpy": np.__version__, "numba": numba.__version__, "rpcm": version(rpcm), "shareloc": version(shareloc),
            "numba_threads": numba.get_num_threads(), "numba_threading_layer": layer,
            "python": platform.python_version()}  # fmt: skip


def run(files: list[Path], n: int, seed: int = 0, repeats: int = 5, progress: bool = False) -> dict:
    """The whole benchmark (every file in this process); returns the JSON-able record."""
    data: dict = {"date": _dt.datetime.now().isoformat(timespec="seconds"), "n": n, "seed": seed, "repeats": repeats,
                  "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
                  "load_start": os.getloadavg(), "files": []}  # fmt: skip
    for path in files:
        rec = bench_file(path, n, seed, repeats)
        data["files"].append(rec)
        if progress:
            t = rec["timings"]
            print(f"{path.name}: ours {t['ours']['median_s']:.4f} s, numpy {t['ours-numpy']['median_s']:.4f} s, "
                  f"rpcm {t['rpcm']['median_s']:.4f} s, shareloc {t['shareloc']['median_s']:.4f} s; "
                  f"max |d| {rec['agreement']['max_disagreement_px']:.1e} px", flush=True)  # fmt: skip
    data["load_end"] = os.getloadavg()
    data["versions"] = versions()
    return data


# ------------------------------------------------------------------------------------------------ report
def markdown(data: dict) -> str:
    v = data["versions"]
    recs = data["files"]
    loads = [x for r in recs for x in (r["load_before"][0], r["load_after"][0])]
    cmd = "python benchmarks/rpc_perf.py" + ("" if data["n"] == 5_000_000 else f" --points {data['n']}")
    lines = [
        HEADING,
        "",
        f"Measured by `{cmd}` on {data['date']} ({data['machine']}; numpy {v['numpy']}, numba {v['numba']} "
        f"({v['numba_threads']} threads, threading layer `{v['numba_threading_layer']}`), rpcm {v['rpcm']}, "
        f"shareloc {v['shareloc']}).  Raw records: `benchmarks/results/rpc_perf.json`.",
        "",
        f"{data['n']:,} seeded random ground points per file, uniform in the normalisation box (offset +- scale in "
        "longitude, latitude and height), projected "
        "ground -> image by the three libraries on the same arrays in one process: ours "
        "(`RationalFunctionModel.projection`, one compiled numba `prange` loop; *numpy* is the same method with "
        '`backend="numpy"`), rpcm (`RPCModel.projection`, numpy) and CNES shareloc (`RPC.inverse_loc`, numba '
        "`prange`, `fastmath=True`).  Times are the median of "
        f"{data['repeats']} warm runs after one warm-up run on the full set (round-robin over the implementations); "
        f"*CPU* is the process CPU time of that call (both threads).  Machine shared with another engineer's "
        f"timing jobs: 1-minute load average {data['load_start'][0]:.2f} at the start, {data['load_end'][0]:.2f} "
        f"at the end ({min(loads):.2f}-{max(loads):.2f} around the files) on 2 cores.",
        "",
        "| file | ours, s | ours CPU, s | ours numpy, s | rpcm, s | shareloc, s | ours, M points/s | ours / rpcm | "
        "ours / shareloc | load |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in recs:
        t = r["timings"]
        lines.append(
            f"| `{r['file']}` | {t['ours']['median_s']:.4f} | {t['ours']['median_cpu_s']:.4f} | "
            f"{t['ours-numpy']['median_s']:.3f} | {t['rpcm']['median_s']:.3f} | {t['shareloc']['median_s']:.3f} | "
            f"{t['ours']['points_per_s'] / 1e6:.0f} | {r['ratios']['ours/rpcm']:.3f} | "
            f"{r['ratios']['ours/shareloc']:.3f} | {r['load_before'][0]:.2f}-{r['load_after'][0]:.2f} |"
        )
    med = {k: statistics.median(r["ratios"][f"ours/{k}"] for r in recs) for k in IMPLS[1:]}
    lines += [
        "",
        f"Median over the {len(recs)} files of the time ratio ours / rpcm: {med['rpcm']:.3f} "
        f"(ours {1 / med['rpcm']:.0f}x faster), ours / shareloc: {med['shareloc']:.3f} "
        f"({1 / med['shareloc']:.1f}x faster), ours / our numpy path: {med['ours-numpy']:.3f}.",
        "",
        "Memory, one more call each after resetting the peak RSS (`resource.getrusage`): the call's rise above "
        "the resident size before it (inputs and earlier results already resident), MB, on the first file: "
        + ", ".join(f"{k} {recs[0]['timings'][k]['call_extra_mb']:+.0f}" for k in IMPLS)
        + f" (peak RSS of the process {max(recs[0]['timings'][k]['peak_rss_mb'] for k in IMPLS):.0f} MB).",
        "",
        "Agreement on all the points (pixels, our 0-based pixel-centre convention; shareloc's output minus "
        f"{SHARELOC_SHIFT}, the measured offset column gives shareloc - ours before that shift):",
        "",
        "| file | shareloc model from | max \\|d\\| ours vs numpy path | max \\|d row\\|, \\|d col\\| vs rpcm | "
        "max \\|d row\\|, \\|d col\\| vs shareloc | shareloc - ours (row; col) |",
        "|---|---|---|---|---|---|",
    ]
    for r in recs:
        a = r["agreement"]
        o = a["shareloc_offset"]
        npd = max(a["ours-numpy"]["max_drow_px"], a["ours-numpy"]["max_dcol_px"])
        same = " (bit-identical)" if a["ours-numpy"]["bit_identical"] else ""
        lines.append(
            f"| `{r['file']}` | {r['shareloc_source']} | {npd:.1e}{same} | "
            f"{a['rpcm']['max_drow_px']:.1e}, {a['rpcm']['max_dcol_px']:.1e} | "
            f"{a['shareloc']['max_drow_px']:.1e}, {a['shareloc']['max_dcol_px']:.1e} | "
            f"{o['row_min']:.9f}..{o['row_max']:.9f}; {o['col_min']:.9f}..{o['col_max']:.9f} |"
        )
    worst = max(r["agreement"]["max_disagreement_px"] for r in recs)
    lines += [
        "",
        f"Largest disagreement over all files and points: {worst:.1e} px.",
        "",
    ]
    return "\n".join(lines)


def append_doc(section: str) -> None:
    """Put ``section`` at the end of docs/performance.md, replacing an earlier copy of it (only that)."""
    text = DOC.read_text() if DOC.exists() else ""
    start = text.find(HEADING + "\n")
    if start >= 0:
        nxt = text.find("\n## ", start + len(HEADING))
        rest = text[nxt + 1 :] if nxt >= 0 else ""
        text = text[:start].rstrip("\n") + ("\n\n" + rest.rstrip("\n") if rest else "")
    DOC.write_text(text.rstrip("\n") + "\n\n" + section.rstrip("\n") + "\n")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="200,000 points per file")
    ap.add_argument("--points", type=int, default=None, help="points per file (default 5,000,000)")
    ap.add_argument("--files", default=None, help="comma-separated names in tests/data/rpc (default: all rpcm reads)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--append-doc", action="store_true", help="put the section at the end of docs/performance.md")
    ap.add_argument("--report", action="store_true", help="only rebuild the section from rpc_perf.json (no timing)")
    args = ap.parse_args(argv)
    if args.report:
        section = markdown(json.loads(RESULTS.read_text()))
        SECTION_MD.write_text(section)
        print(section)
        if args.append_doc:
            append_doc(section)
            print(f"appended to {DOC.relative_to(ROOT)}")
        return
    n = args.points or (200_000 if args.quick else 5_000_000)
    files = rpc_files(args.files.split(",") if args.files else None)
    data = run(files, n, args.seed, args.repeats, progress=True)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(data, indent=1))
    section = markdown(data)
    SECTION_MD.write_text(section)
    print(section)
    if args.append_doc:
        append_doc(section)
        print(f"appended to {DOC.relative_to(ROOT)}")
    if not all(r["agreement"]["all_agree_1e-6_px"] for r in data["files"]):
        sys.exit("disagreement above 1e-6 px (see the agreement table)")


if __name__ == "__main__":
    main()
