"""Issue 24's export acceptance, run the way the outside checker runs it: on files this repository does not have.

The checker exports real scenes we have never seen.  We cannot have them, so this script *derives* other files
from the real ones in ``tests/data`` and ``assets/dem`` (written under a scratch folder, never committed) and
exports each one twice with the command's defaults (``pushbroom explore --<kind> FILE [--dem DEM] --export DIR``:
50,000 SCPs, 100 SCOPs, every method, the accuracy-vs-SCOPs sweep), in a fresh process, as a user would.

Variants built (each from a real file; see :func:`build_cases`):

* DEMs for the 2017 Pleiades DIMAP (its rigorous model, and its vendor RPC read from the same DIMAP v1.4
  file): reprojected to UTM (Float32, a no-data value, tiled and DEFLATE-compressed), a geographic grid at
  another spacing (Float32), no-data holes with a declared no-data value (Int16), a DEM covering only part of
  the footprint, the heights declared above EGM96 by the file's vertical CRS (EPSG:4326+5773) and the same
  heights read as above the ellipsoid, a DEM far larger than the footprint (an SRTM-like 1-arcsecond tile), a
  tiled/compressed copy of the original, an SRTM ``.hgt`` tile with a void, and a DEM that does not cover the
  footprint at all (must be a one-line error);
* RPC files of another Pleiades image (``RPC_PHR1B_P_201709281038045``, DIMAP v2, Nice) in every format the
  package reads, written by GDAL (GeoTIFF RPC tags, a ``.RPB`` and an ``_RPC.TXT`` sidecar, via rasterio) and by
  hand (a GDAL VRT, an OSSIM ``.geom``, a DIMAP v2 XML with its validity boxes removed), 0-based and 1-based
  conventions (docs/conventions.md);
* usgscsm's CTX ISD with the other lens distortion models (transverse, lrolrocnac, radtan);
* every other RPC, DG XML and ISD of the repository's test data, exported with its defaults.

Checks on each export (the issue's acceptance line, plus the "What to build" lines an export can show):

1. every method finite (RMSE and max of rows and columns, the stand-in map too) and reporting every check point
   (valid + flagged = the check points used); mlp finite at every SCOP density of the sweep
   (:data:`explorer.app.model.SCOP_DENSITIES`, the GUI's choices);
2. the chosen SCOP count (100) used by every learned method, each sweep entry at its own density;
3. ``panels.html`` under 5 MB, no script or stylesheet loaded from the network (the one script file is the
   export's ``timing.js``);
4. the Timing panel filled: ``timing.json`` has a fit and an evaluation time for every method that ran, and the
   page loads ``timing.js``;
5. two exports byte-identical (``summary.json``, ``residuals.csv``, ``panels.html``);

and: no "1e+02%", no NaN RMSE in a title, every training line the sweep logs names the sweep.

Independent truth across variants: a file that describes the *same* model as another (the RPC rewritten by GDAL
in another format and convention; a DEM stored in another layout or type with the same heights) must export
the same residuals as its twin: ``residuals.csv`` compared number by number (pixel coordinates and residuals to
1e-6 px, ground points to 1e-6 m).  The RPC's twins test the 0-/1-based conventions of each reader against
GDAL's writer.

Usage::

    python benchmarks/acceptance_probe.py --work /tmp/probe --json out/acceptance_probe.json
    python benchmarks/acceptance_probe.py --only 'dem-utm|rpc-rpb' --scps 5000   # a quicker subset

Prints one line per case and writes JSON (with ``uptime``'s load before and after each case).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import resource
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data"
RPC_DIR = DATA / "rpc"
DEM_DIR = ROOT / "assets" / "dem"
PHR_2017 = RPC_DIR / "PHRDIMAP_P1BP--2017030824934340CP.XML"
PHR_2018 = RPC_DIR / "PHRDIMAP_P1BP--2018122638935449CP.XML"
DEM_2017 = DEM_DIR / "MNT_P1BP--2017030824934340CP.tif"
DEM_2018 = DEM_DIR / "MNT_P1BP--2018122638935449CP.tif"
RPC_2017 = RPC_DIR / "RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML"
REPRODUCIBLE = ("summary.json", "residuals.csv", "panels.html")
EXPORTED = (*REPRODUCIBLE, "timing.json", "timing.js")
MAX_PAGE_BYTES = 5_000_000


@dataclass
class Case:
    """One ``explore`` command: its arguments, and an error it must give (``error`` words) or none."""

    name: str
    args: list[str]
    error: str | None = None
    twin: str | None = None  #: a case whose residuals.csv must be the same numbers
    note: str = ""
    result: dict = field(default_factory=dict)


# ------------------------------------------------------------------------------------------------ variants
def _read(path: Path):
    import rasterio

    with rasterio.open(path) as d:
        return d.read(1), d.profile.copy()


def _write(path: Path, data: np.ndarray, profile: dict, **kw) -> Path:
    import rasterio

    profile = {**profile, **kw, "driver": "GTiff", "count": 1, "height": data.shape[0], "width": data.shape[1],
               "dtype": str(data.dtype)}
    with rasterio.open(path, "w", **profile) as d:
        d.write(data, 1)
    return path


def build_dems(work: Path) -> dict[str, Path]:
    """Other DEMs of the 2017 DIMAP's area, from its real DEM (Int16 heights above EGM96, EPSG:4269, no nodata)."""
    import rasterio
    from rasterio.crs import CRS
    from rasterio.transform import Affine
    from rasterio.warp import Resampling, calculate_default_transform, reproject

    heights, prof = _read(DEM_2017)
    tr: Affine = prof["transform"]
    out: dict[str, Path] = {}
    plain = {k: v for k, v in prof.items() if k not in ("blockxsize", "blockysize", "tiled", "compress",
                                                         "interleave")}
    # tiled, DEFLATE with a predictor: the same heights in another layout
    out["tiled"] = _write(work / "dem_tiled_deflate.tif", heights, plain, tiled=True, blockxsize=16, blockysize=16,
                          compress="deflate", predictor=2)
    # Float32 with a declared no-data value: the same heights in another type
    out["float32"] = _write(work / "dem_float32.tif", heights.astype(np.float32), plain, nodata=-9999.0)
    # UTM zone 40N, 30 m, Float32, bilinear, tiled + compressed
    dst_crs = CRS.from_epsg(32640)
    with rasterio.open(DEM_2017) as src:
        t, w, h = calculate_default_transform(src.crs, dst_crs, src.width, src.height, *src.bounds, resolution=30.0)
        utm = np.full((h, w), -9999.0, np.float32)
        reproject(heights.astype(np.float32), utm, src_transform=tr, src_crs=src.crs, dst_transform=t,
                  dst_crs=dst_crs, resampling=Resampling.bilinear, src_nodata=None, dst_nodata=-9999.0)
    out["utm"] = _write(work / "dem_utm40n_30m.tif", utm, {**plain, "crs": dst_crs, "transform": t},
                        nodata=-9999.0, tiled=True, blockxsize=256, blockysize=256, compress="deflate")
    # geographic WGS84 at another spacing (about 3x finer), Float32
    fine = Affine(tr.a / 3.0, 0.0, tr.c, 0.0, tr.e / 3.0, tr.f)
    geo = np.full((heights.shape[0] * 3, heights.shape[1] * 3), -9999.0, np.float32)
    reproject(heights.astype(np.float32), geo, src_transform=tr, src_crs=prof["crs"], dst_transform=fine,
              dst_crs=CRS.from_epsg(4326), resampling=Resampling.bilinear, dst_nodata=-9999.0)
    out["geo_fine"] = _write(work / "dem_wgs84_fine.tif", geo, {**plain, "crs": CRS.from_epsg(4326),
                                                                "transform": fine}, nodata=-9999.0)
    # Int16 with no-data holes (a declared no-data value): a block and 3 % random cells
    rng = np.random.default_rng(24)
    holes = heights.copy()
    holes[60:75, 10:20] = -32767
    holes[rng.random(holes.shape) < 0.03] = -32767
    out["holes"] = _write(work / "dem_int16_holes.tif", holes, plain, nodata=-32767)
    # covering only part of the footprint (latitudes 21.92..22.14): the DEM's rows north of 22.0 degrees
    keep = int(math.ceil((tr.f - 22.0) / -tr.e))
    out["partial"] = _write(work / "dem_partial.tif", heights[:keep], plain)
    # declared above EGM96 by a compound vertical CRS
    out["egm96_declared"] = _write(work / "dem_egm96_declared.tif", heights, {**plain, "crs": CRS.from_user_input(
        "EPSG:4326+5773")})
    # not covering the footprint at all: the same grid 3 degrees east
    out["elsewhere"] = _write(work / "dem_elsewhere.tif", heights, {**plain, "transform": Affine(
        tr.a, 0.0, tr.c + 3.0, 0.0, tr.e, tr.f)})
    # far larger than the footprint: a 1-arcsecond SRTM-like tile of 2 x 2 degrees (7201 x 7201 Int16, 104 MB),
    # the real heights inside their own bounds, a smooth synthetic relief elsewhere
    n = 7201
    step = 1.0 / 3600.0
    big_tr = Affine(step, 0.0, 56.5 - step / 2, 0.0, -step, 22.75 + step / 2)
    big = np.empty((n, n), np.float32)
    reproject(heights.astype(np.float32), big, src_transform=tr, src_crs=prof["crs"], dst_transform=big_tr,
              dst_crs=CRS.from_epsg(4326), resampling=Resampling.bilinear, dst_nodata=np.nan, init_dest_nodata=True)
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float32) / n
    synthetic = 400.0 + 300.0 * np.sin(6.0 * xx) * np.cos(5.0 * yy)
    big = np.where(np.isfinite(big), big, synthetic).round().astype(np.int16)
    out["huge"] = _write(work / "dem_srtm1_2x2deg.tif", big, {**plain, "crs": CRS.from_epsg(4326),
                                                              "transform": big_tr}, tiled=True,
                         blockxsize=512, blockysize=512, compress="lzw")
    # an SRTM .hgt tile (3 arc-seconds, 1201 x 1201 big-endian Int16, -32768 voids, placed by its name): the
    # real heights where the DEM has them; N22E057 covers latitudes 22..23 of the footprint's 21.92..22.14
    side = 1201
    hgt_tr = Affine(1.0 / (side - 1), 0.0, 57.0 - 0.5 / (side - 1), 0.0, -1.0 / (side - 1), 23.0 + 0.5 / (side - 1))
    tile = np.empty((side, side), np.float32)
    reproject(heights.astype(np.float32), tile, src_transform=tr, src_crs=prof["crs"], dst_transform=hgt_tr,
              dst_crs=CRS.from_epsg(4326), resampling=Resampling.bilinear, dst_nodata=np.nan, init_dest_nodata=True)
    tile[1000:1020, 300:330] = np.nan  # a void inside the footprint
    hgt = np.where(np.isfinite(tile), np.round(tile), -32768).astype(">i2")
    (work / "srtm").mkdir(exist_ok=True)
    out["hgt"] = work / "srtm" / "N22E057.hgt"
    hgt.tofile(out["hgt"])
    return out


def _rpc_of(path: Path):
    from explorer.rpc import read_rpc

    return read_rpc(path)


def build_rpcs(work: Path) -> dict[str, Path]:
    """The 2017 Pleiades image's vendor RPC (DIMAP v2, 1-based) in the other formats, written by GDAL and by hand."""
    import rasterio
    from rasterio.rpc import RPC

    model = _rpc_of(RPC_2017)  # 0-based pixel centre
    if model.image_size is None:
        raise SystemExit(f"{RPC_2017.name} declares no image size")
    rows, cols = model.image_size
    out: dict[str, Path] = {}
    line_off, samp_off = float(model.row_offset), float(model.col_offset)
    rpc = RPC(height_off=float(model.height_offset), height_scale=float(model.height_scale),
              lat_off=float(model.lat_offset), lat_scale=float(model.lat_scale),
              long_off=float(model.lon_offset), long_scale=float(model.lon_scale),
              line_off=line_off, line_scale=float(model.row_scale),
              samp_off=samp_off, samp_scale=float(model.col_scale),
              line_num_coeff=[float(v) for v in model.row_num], line_den_coeff=[float(v) for v in model.row_den],
              samp_num_coeff=[float(v) for v in model.col_num], samp_den_coeff=[float(v) for v in model.col_den])
    # GDAL writes a GeoTIFF with the RPC tag, and the .RPB and _RPC.TXT sidecars (creation options RPB / RPCTXT)
    tif_dir = work / "gdal_tif"
    tif_dir.mkdir(exist_ok=True)
    profile = {"driver": "GTiff", "width": int(cols), "height": int(rows), "count": 1, "dtype": "uint8",
               "tiled": True, "compress": "deflate", "sparse_ok": True}
    with rasterio.open(tif_dir / "phr.tif", "w", rpcs=rpc, **profile):
        pass
    out["tif"] = tif_dir / "phr.tif"
    for opt, name in (("RPB", "phr_rpb"), ("RPCTXT", "phr_txt")):
        d_ = work / name
        d_.mkdir(exist_ok=True)
        with rasterio.open(d_ / "img.tif", "w", rpcs=rpc, **{**profile, opt: "YES", "PROFILE": "BASELINE"}):
            pass
    rpb = sorted((work / "phr_rpb").glob("*.RPB")) + sorted((work / "phr_rpb").glob("*.rpb"))
    txt = sorted((work / "phr_txt").glob("*_RPC.TXT")) + sorted((work / "phr_txt").glob("*_rpc.txt"))
    if rpb:
        out["rpb"] = rpb[0]
    if txt:
        out["txt"] = txt[0]
    # by hand: GDAL VRT metadata, OSSIM keyword list, DIMAP v2 without its validity box
    coeffs = {"LINE_NUM_COEFF": model.row_num, "LINE_DEN_COEFF": model.row_den,
              "SAMP_NUM_COEFF": model.col_num, "SAMP_DEN_COEFF": model.col_den}
    scal = {"LINE_OFF": line_off, "SAMP_OFF": samp_off, "LAT_OFF": model.lat_offset, "LONG_OFF": model.lon_offset,
            "HEIGHT_OFF": model.height_offset, "LINE_SCALE": model.row_scale, "SAMP_SCALE": model.col_scale,
            "LAT_SCALE": model.lat_scale, "LONG_SCALE": model.lon_scale, "HEIGHT_SCALE": model.height_scale}
    items = "".join(f'    <MDI key="{k}">{float(v)!r}</MDI>\n' for k, v in scal.items())
    items += "".join(f'    <MDI key="{k}">{" ".join(repr(float(c)) for c in v)}</MDI>\n' for k, v in coeffs.items())
    vrt = work / "phr_rpc.vrt"
    vrt.write_text(f'<VRTDataset rasterXSize="{int(cols)}" rasterYSize="{int(rows)}">\n'
                   f'  <Metadata domain="RPC">\n{items}  </Metadata>\n</VRTDataset>\n')
    out["vrt"] = vrt
    geom_keys = {"line_off": line_off, "samp_off": samp_off, "lat_off": model.lat_offset, "long_off": model.lon_offset,
                 "height_off": model.height_offset, "line_scale": model.row_scale, "samp_scale": model.col_scale,
                 "lat_scale": model.lat_scale, "long_scale": model.lon_scale, "height_scale": model.height_scale}
    lines = ["type:  ossimRpcModel", "polynomial_format:  B", "image_id:  phr"]
    lines += [f"{k}:  {float(v)!r}" for k, v in geom_keys.items()]
    for key, vals in (("line_num_coeff", model.row_num), ("line_den_coeff", model.row_den),
                      ("samp_num_coeff", model.col_num), ("samp_den_coeff", model.col_den)):
        lines += [f"{key}_{i:02d}:  {float(c)!r}" for i, c in enumerate(vals)]
    geom = work / "phr.geom"
    geom.write_text("\n".join(lines) + "\n")
    out["geom"] = geom
    text = RPC_2017.read_text()
    no_box = re.sub(r"<(Direct|Inverse)_Model_Validity_Domain>.*?</\1_Model_Validity_Domain>\s*", "", text,
                    flags=re.S)
    if no_box != text:
        (work / "nobox").mkdir(exist_ok=True)
        out["nobox"] = work / "nobox" / RPC_2017.name
        out["nobox"].write_text(no_box)
    return out


def build_isds(work: Path) -> dict[str, Path]:
    """usgscsm's CTX ISD with the other lens distortion models usgscsm reads (small real-sized terms)."""
    ctx = json.loads((DATA / "usgscsm" / "ctxLineScan.json").read_text())
    models = {
        "transverse": {"x": [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1e-6, 0.0, 0.0, 0.0],
                       "y": [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1e-6]},
        "lrolrocnac": {"coefficients": [1.81e-5]},
        "radtan": {"coefficients": [-2e-3, 1e-5, 1e-5, -1e-5, 0.0]},
    }
    out = {}
    for name, params in models.items():
        ctx["optical_distortion"] = {name: params}
        out[name] = work / f"ctx_{name}.json"
        out[name].write_text(json.dumps(ctx))
    return out


def build_cases(work: Path) -> list[Case]:
    work.mkdir(parents=True, exist_ok=True)
    dems = build_dems(work)
    rpcs = build_rpcs(work)
    dimap = ["--dimap", str(PHR_2017)]
    rpc = ["--rpc", str(RPC_2017)]  # another Pleiades image (Nice), 1-based DIMAP v2
    vendor = ["--rpc", str(PHR_2017)]  # the 2017 DIMAP's own RPC (DIMAP v1.4), inside its DEM
    cases = [
        Case("dimap2017-dem", [*dimap, "--dem", str(DEM_2017), "--dem-datum", "egm96"], note="the reference"),
        Case("dimap2017-dem-tiled", [*dimap, "--dem", str(dems["tiled"]), "--dem-datum", "egm96"],
             twin="dimap2017-dem"),
        Case("dimap2017-dem-float32", [*dimap, "--dem", str(dems["float32"]), "--dem-datum", "egm96"],
             twin="dimap2017-dem"),
        Case("dimap2017-dem-egm96-declared", [*dimap, "--dem", str(dems["egm96_declared"])], twin="dimap2017-dem"),
        Case("dimap2017-dem-as-ellipsoid", [*dimap, "--dem", str(DEM_2017), "--dem-datum", "ellipsoid"]),
        Case("dimap2017-dem-utm", [*dimap, "--dem", str(dems["utm"]), "--dem-datum", "egm96"]),
        Case("dimap2017-dem-wgs84-fine", [*dimap, "--dem", str(dems["geo_fine"]), "--dem-datum", "egm96"]),
        Case("dimap2017-dem-holes", [*dimap, "--dem", str(dems["holes"]), "--dem-datum", "egm96"]),
        Case("dimap2017-dem-partial", [*dimap, "--dem", str(dems["partial"]), "--dem-datum", "egm96"]),
        Case("dimap2017-dem-huge", [*dimap, "--dem", str(dems["huge"]), "--dem-datum", "egm96"]),
        Case("dimap2017-srtm-hgt", [*dimap, "--dem", str(dems["hgt"])], note="SRTM .hgt, EGM96 by format"),
        Case("rpc-dimap2017-srtm-hgt", [*vendor, "--dem", str(dems["hgt"])]),
        Case("dimap2017-dem-elsewhere", [*dimap, "--dem", str(dems["elsewhere"]), "--dem-datum", "egm96"],
             error="covers"),
        Case("dimap2017", dimap),
        Case("dimap2018-dem", ["--dimap", str(PHR_2018), "--dem", str(DEM_2018)]),
        Case("rpc-dimap2017-dem", [*vendor, "--dem", str(DEM_2017), "--dem-datum", "egm96"],
             note="the DIMAP v1.4's vendor RPC on its DEM"),
        Case("rpc-dimap2017-dem-utm", [*vendor, "--dem", str(dems["utm"]), "--dem-datum", "egm96"]),
        Case("rpc-dimap2017-dem-holes", [*vendor, "--dem", str(dems["holes"]), "--dem-datum", "egm96"]),
        Case("rpc-dimap2017-dem-huge", [*vendor, "--dem", str(dems["huge"]), "--dem-datum", "egm96"]),
        Case("rpc2017", rpc, note="DIMAP v2 XML, 1-based (Nice: no DEM of ours covers it)"),
        Case("rpc2017-as-mpc", [*rpc, "--as-mpc"]),
    ]
    for key, what in (("tif", "GeoTIFF RPC tags (GDAL)"), ("rpb", ".RPB (GDAL)"), ("txt", "_RPC.TXT (GDAL)"),
                      ("vrt", "GDAL VRT (by hand)"), ("geom", "OSSIM .geom (by hand)"),
                      ("nobox", "DIMAP v2 without its validity box")):
        if key in rpcs:
            cases.append(Case(f"rpc2017-{key}", ["--rpc", str(rpcs[key])], twin="rpc2017", note=what))
    for f in sorted(RPC_DIR.iterdir()):
        if f.suffix.lower() in (".xml", ".txt", ".rpb", ".vrt", ".geom") and f != RPC_2017 and "PHRDIMAP" not in \
                f.name and f.name not in ("rpc_unsupported.xml",):
            cases.append(Case(f"rpc-{f.name}", ["--rpc", str(f)]))
    cases.append(Case("rpc-rpc_unsupported.xml", ["--rpc", str(RPC_DIR / "rpc_unsupported.xml")],
                      error="rpc_unsupported.xml"))
    cases.append(Case("dg-WV1", ["--dg", str(RPC_DIR / "rpc_WV1.xml")]))
    for name, path in build_isds(work).items():
        cases.append(Case(f"isd-ctx-{name}", ["--isd", str(path)], note=f"CTX with {name} distortion"))
    for f in ("usgscsm/ctxLineScan.json", "usgscsm/orbitalLineScan.json", "usgscsm/constVelocityLineScan.json",
              "ale/nhmvic_tdi_isd.json"):
        cases.append(Case(f"isd-{Path(f).stem}", ["--isd", str(DATA / f)]))
    return cases


# ------------------------------------------------------------------------------------------------ checks
def _load() -> str:
    return "{:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def export(args: list[str], out: Path, extra: list[str]) -> dict:
    """One ``explore ... --export out`` in a fresh process: return code, stderr, wall and CPU seconds."""
    cmd = [sys.executable, "-m", "explorer", "explore", *args, *extra, "--export", str(out)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd="/tmp", capture_output=True, text=True, timeout=3600)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"rc": proc.returncode, "stderr": proc.stderr, "stdout": proc.stdout, "wall_s": round(wall, 2),
            "cpu_s": round(cpu, 2)}


def _finite(*values) -> bool:
    return all(v is not None and math.isfinite(v) for v in values)


def check_export(a: Path, b: Path, stderr: str, densities: tuple[int, ...]) -> tuple[list[str], dict]:
    """The acceptance items on two exports of the same command; returns (problems, figures)."""
    problems: list[str] = []
    names = sorted(p.name for p in a.iterdir())
    if names != sorted(EXPORTED):
        return [f"exported files {names}"], {}
    summary = json.loads((a / "summary.json").read_text())
    timing = json.loads((a / "timing.json").read_text())
    page = (a / "panels.html").read_bytes()
    s = summary["settings"]
    n = s["scps_used"]
    ran = {k: m for k, m in summary["methods"].items() if not m.get("unavailable")}
    # 1. every method finite, on every check point
    for k, m in ran.items():
        if m.get("error"):
            problems.append(f"{k}: error {m['error']}")
        if not _finite(m["rmse_row_px"], m["rmse_col_px"], m["max_row_px"], m["max_col_px"]):
            problems.append(f"{k}: not finite (RMSE {m['rmse_row_px']} / {m['rmse_col_px']})")
        if m["n_valid"] + m["n_invalid"] != n or m["n_valid"] == 0:
            problems.append(f"{k}: {m['n_valid']} valid + {m['n_invalid']} flagged of {n} check points")
    st = summary.get("stand_in")
    if st and not (st.get("error") or _finite(st["rmse_row_px"], st["rmse_col_px"])):
        problems.append(f"stand-in not finite: {st}")
    sweep = summary.get("accuracy_vs_scops") or {}
    named = {k: {e["n_scops"]: e["error"] for e in v} for k, v in (summary.get("accuracy_vs_scops_failed") or
                                                                    {}).items()}
    for k, entries in sweep.items():
        if k not in ran or ran[k]["n_scops"] == 0:
            continue
        got = [e["n_scops"] for e in entries]
        # 2. (the sweep's counts): every density, or a density the method cannot fit, named with its reason
        want = [d for d in densities if not named.get(k, {}).get(d)]
        if got != want:
            problems.append(f"sweep {k}: SCOP counts {got}, not {want}")
        if k == "mlp":
            bad = [e["n_scops"] for e in entries if not _finite(e["rmse_px"])] + sorted(named.get(k, {}))
            if bad:
                problems.append(f"mlp not finite in the sweep at {bad} SCOPs")
    if "mlp" in summary["methods"] and not sweep.get("mlp"):
        problems.append("no mlp sweep")
    # 2. the chosen SCOP count
    if s["scops_used"] != s["scops"]:
        problems.append(f"SCOPs used {s['scops_used']} of {s['scops']} chosen")
    wrong = {k: m["n_scops"] for k, m in ran.items() if m["n_scops"] not in (0, s["scops"])}
    if wrong:
        problems.append(f"methods fitted on other SCOP counts: {wrong}")
    # 3. panels.html: size, no network script
    text = page.decode()
    srcs = re.findall(r"<script\b[^>]*\bsrc\s*=\s*[\"']?([^\"' >]+)", text, re.I)
    links = re.findall(r"<link\b[^>]*\bhref\s*=\s*[\"']?(https?:[^\"' >]+)", text, re.I)
    if len(page) >= MAX_PAGE_BYTES:
        problems.append(f"panels.html {len(page) / 1e6:.2f} MB")
    if srcs != ["timing.js"] or links:
        problems.append(f"scripts from {srcs}, links {links}")
    # 4. Timing panel filled
    if "window.PUSHBROOM_TIMING" not in text or set(timing["methods"]) != set(summary["methods"]):
        problems.append("timing.js not wired or methods missing from timing.json")
    for k in ran:
        t = timing["methods"].get(k, {})
        if not (_finite(t.get("fit_s"), t.get("eval_s")) and t["eval_s"] > 0 and t["n_evaluated"] == n):
            problems.append(f"timing {k}: {t}")
    # 5. two exports byte-identical
    for f in REPRODUCIBLE:
        if (a / f).read_bytes() != (b / f).read_bytes():
            problems.append(f"{f} differs between two exports")
    # the other lines an export shows
    if "e+02%" in text or "e+02%" in stderr:
        problems.append("a percentage printed as 1e+02%")
    if re.search(r"RMSE\s+nan", text, re.I):
        problems.append("a NaN RMSE in a title")
    for line in stderr.splitlines():
        if re.search(r"training|converge|accuracy goal", line) and re.search(r"\b\d+ SCOPs\b", line) is None \
                and not line.startswith("["):
            problems.append(f"log line without its origin: {line[:120]}")
    figures = {"scps_used": n, "scops_used": s["scops_used"], "page_mb": round(len(page) / 1e6, 2),
               "methods": len(ran), "unavailable": sorted(set(summary["methods"]) - set(ran)),
               "dem_coverage": (summary["source"].get("dem_coverage") or {}).get("fraction"),
               "truth": summary.get("truth", {}).get("model"),
               "sweep_failed": {k: sorted(v) for k, v in named.items()},
               "worst_rmse_px": max((max(m["rmse_row_px"], m["rmse_col_px"]) for m in ran.values()
                                     if _finite(m["rmse_row_px"], m["rmse_col_px"])), default=None)}
    return problems, figures


def compare_twins(a: Path, b: Path, tol_px: float = 1e-6, tol_m: float = 1e-6) -> list[str]:
    """Two exports of files that describe the same model: the same check points (ground to ``tol_m``), the same
    truth (the sensor's row / column to ``tol_px``) and the same status per point and method.  The methods'
    residuals are reported per method (a network trained iteratively may amplify a 1e-9 px difference in its
    training targets), not judged."""
    ra = list(csv.reader((a / "residuals.csv").open()))
    rb = list(csv.reader((b / "residuals.csv").open()))
    if ra[0] != rb[0] or len(ra) != len(rb):
        return [f"residuals.csv: {len(ra)} vs {len(rb)} rows, header {ra[0] == rb[0]}"]
    head = ra[0]
    truth = [head.index(k) for k in ("row_px", "col_px")]
    res = [head.index(k) for k in ("row_residual_px", "col_residual_px")]
    m = [head.index(k) for k in ("x_m", "y_m", "z_m")]
    keys = [head.index(k) for k in ("method", "scp_index", "status")]
    worst_px = worst_m = 0.0
    by_method: dict[str, float] = {}
    for x, y in zip(ra[1:], rb[1:], strict=True):
        if [x[i] for i in keys] != [y[i] for i in keys]:
            return [f"residuals.csv rows differ: {x[:3]} vs {y[:3]}"]
        for i in truth:
            worst_px = max(worst_px, abs(float(x[i]) - float(y[i])))
        for i in m:
            worst_m = max(worst_m, abs(float(x[i]) - float(y[i])))
        for i in res:
            if x[i] and y[i]:
                by_method[x[0]] = max(by_method.get(x[0], 0.0), abs(float(x[i]) - float(y[i])))
            elif x[i] != y[i]:
                return [f"residuals.csv: {head[i]} empty in one only ({x[:2]})"]
    out = []
    if worst_px > tol_px or worst_m > tol_m:
        out.append(f"truth differs from its twin's by {worst_px:.3g} px / {worst_m:.3g} m")
    moved = {k: float(f"{v:.3g}") for k, v in by_method.items() if v > tol_px}
    return out + [f"twin: truth max |d| {worst_px:.3g} px, points {worst_m:.3g} m; residuals moved > {tol_px:g} px: "
                  f"{moved or 'none'}"]


_PAGE_STATE = """() => {
  const gds = Array.from(document.querySelectorAll('.plotly-graph-div'));
  const timing = gds[gds.length - 1];
  return {figures: gds.length, drawn: gds.filter(gd => gd.querySelectorAll('.main-svg').length > 0).length,
          images: gds[0].querySelectorAll('.heatmaplayer image, .hm image').length,
          timing_x: timing.data[0].x, per_point: timing.data[1].y, fit: timing.data[0].y,
          headings: Array.from(document.querySelectorAll('h2')).map(h => h.innerText.split(' ')[0])};
}"""


def check_pages(pages: list[Path]) -> dict[str, list[str]]:
    """Each exported ``panels.html`` opened from disk in headless Chromium with the network cut (every request
    that is not a local file is aborted and recorded): no request, no JavaScript error, every figure drawn, one
    raster image per map, and the Timing panel filled from ``timing.js`` (a per-point time for every method of
    ``timing.json``).  Returns the problems per page."""
    from playwright.sync_api import sync_playwright

    out: dict[str, list[str]] = {}
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path="/usr/bin/chromium", args=["--headless", "--no-sandbox",
                                                                               "--disable-gpu"])
        for page_path in pages:
            problems: list[str] = []
            context = browser.new_context(viewport={"width": 1300, "height": 900}, offline=True)
            requests: list[str] = []

            def route(r, requests=requests) -> None:
                if r.request.url.startswith(("file:", "data:", "blob:", "about:")):
                    r.continue_()
                else:
                    requests.append(r.request.url)
                    r.abort()

            context.route("**/*", route)
            page = context.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda exc, errors=errors: errors.append(str(exc)[:200]))
            t0 = time.perf_counter()
            page.goto(page_path.resolve().as_uri(), wait_until="load")
            try:
                page.wait_for_function("() => Array.from(document.querySelectorAll('.plotly-graph-div'))"
                                       ".every(gd => gd.querySelectorAll('.main-svg').length > 0)", timeout=120_000)
                page.wait_for_timeout(300)
                opened_s = time.perf_counter() - t0
                st = page.evaluate(_PAGE_STATE)
            except Exception as exc:  # noqa: BLE001 -- reported, the next page is checked
                problems.append(f"not drawn: {exc}"[:300])
                context.close()
                out[str(page_path)] = problems
                continue
            context.close()
            timing = json.loads((page_path.parent / "timing.json").read_text())["methods"]
            summary = json.loads((page_path.parent / "summary.json").read_text())
            ran = [k for k, m in summary["methods"].items() if not m.get("unavailable")]
            n_maps = 2 * len(ran) + (2 if summary.get("stand_in") else 0)
            if requests or errors:
                problems.append(f"network requests {requests[:3]}, JavaScript errors {errors[:3]}")
            if st["drawn"] != st["figures"] or st["headings"][-1] != "Timing":
                problems.append(f"{st['drawn']} of {st['figures']} figures drawn, headings {st['headings']}")
            if st["images"] < n_maps:  # one raster per map, plus one per map with flagged points (their layer)
                problems.append(f"{st['images']} map rasters drawn, {n_maps} maps")
            filled = dict(zip(st["timing_x"], st["per_point"], strict=True))
            for k in ran:
                t = timing[k]
                want = 1e6 * t["eval_s"] / t["n_evaluated"]
                if filled.get(k) is None or abs(filled[k] - want) > 1e-9 * want:
                    problems.append(f"Timing panel: {k} per point {filled.get(k)}, timing.json {want}")
            out[str(page_path)] = problems + [f"opened in {opened_s:.2f} s"]
        browser.close()
    return out


def run_case(case: Case, out_root: Path, extra: list[str], densities: tuple[int, ...]) -> dict:
    res: dict = {"name": case.name, "args": case.args, "note": case.note, "load_before": _load()}
    dirs = [out_root / case.name / x for x in ("a", "b")]
    runs = []
    for d in dirs:
        if d.exists():
            for f in d.iterdir():
                f.unlink()
        runs.append(export(case.args, d, extra))
        if case.error is not None:
            break
    res["wall_s"] = [r["wall_s"] for r in runs]
    res["cpu_s"] = [r["cpu_s"] for r in runs]
    res["load_after"] = _load()
    problems: list[str] = []
    if case.error is not None:
        r = runs[0]
        lines = [ln for ln in r["stderr"].splitlines() if ln.strip()]
        if r["rc"] != 2 or len(lines) != 1 or case.error not in r["stderr"] or "Traceback" in r["stderr"]:
            problems.append(f"expected a one-line error naming {case.error!r}: rc {r['rc']}, {r['stderr'][-600:]}")
        res["message"] = lines[-1] if lines else ""
    elif any(r["rc"] != 0 for r in runs):
        problems.append(f"rc {[r['rc'] for r in runs]}: {runs[-1]['stderr'][-800:]}")
    else:
        p, figures = check_export(dirs[0], dirs[1], runs[0]["stderr"], densities)
        problems += p
        res["figures"] = figures
        res["log_lines"] = [ln for ln in runs[0]["stderr"].splitlines() if ln.strip()][-3:]
        (dirs[1] / "residuals.csv").unlink()  # ~120 MB at the default 50,000 SCPs; compared above
    res["problems"] = problems
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="/tmp/acceptance_probe", help="scratch folder for the variants and exports")
    ap.add_argument("--only", default=None, help="regular expression of case names to run")
    ap.add_argument("--scps", type=int, default=None, help="fewer check points than the default (quicker)")
    ap.add_argument("--json", default=None)
    ap.add_argument("--list", action="store_true", help="list the cases and stop")
    ap.add_argument("--keep", action="store_true", help="keep the first export's residuals.csv of every case")
    ap.add_argument("--browser", action="store_true",
                    help="also open every export's panels.html in headless Chromium offline (check_pages)")
    ap.add_argument("--pages", nargs="+", default=None,
                    help="only open these exported panels.html in headless Chromium offline and check them")
    args = ap.parse_args(argv)
    if args.pages:
        checked = check_pages([Path(p) for p in args.pages])
        bad = 0
        for page, problems in checked.items():
            bad += len(problems) > 1
            print(f"{'FAIL' if len(problems) > 1 else 'ok  '} {page}: {'; '.join(problems)}", flush=True)
        return 1 if bad else 0
    sys.path.insert(0, str(ROOT))
    from explorer.app.model import SCOP_DENSITIES

    work = Path(args.work)
    cases = build_cases(work / "files")
    if args.only:
        cases = [c for c in cases if re.search(args.only, c.name)]
    if args.list:
        for c in cases:
            print(c.name, " ".join(c.args))
        return 0
    extra = ["--scps", str(args.scps)] if args.scps else []
    results = {}
    failed = 0
    for case in cases:
        res = run_case(case, work / "exports", extra, tuple(SCOP_DENSITIES))
        twin = results.get(case.twin) if case.twin else None
        if twin is not None and not twin["problems"] and not res["problems"]:
            res["twin"] = compare_twins(work / "exports" / case.twin / "a", work / "exports" / case.name / "a")
            res["problems"] += [t for t in res["twin"] if not t.startswith("twin")]
        results[case.name] = res
        failed += bool(res["problems"])
        f = res.get("figures", {})
        print(f"{'FAIL' if res['problems'] else 'ok  '} {case.name:36s} wall {res['wall_s']} s cpu {res['cpu_s']} s "
              f"load {res['load_before']} -> {res['load_after']}  "
              f"{f.get('page_mb', '')} MB {f.get('scops_used', '')} SCOPs {f.get('scps_used', '')} SCPs "
              f"cover {f.get('dem_coverage')} {res.get('message', '')[:100]} {(res.get('twin') or [''])[-1]}",
              flush=True)
        for p in res["problems"]:
            print(f"       - {p}", flush=True)
    if args.browser:
        pages = [work / "exports" / c.name / "a" / "panels.html" for c in cases
                 if c.error is None and (work / "exports" / c.name / "a" / "panels.html").exists()]
        for page, problems in check_pages(pages).items():
            name = Path(page).parent.parent.name
            results[name]["page"] = problems
            results[name]["problems"] += problems[:-1]  # the last item is the time it took to open
            print(f"{'FAIL' if len(problems) > 1 else 'ok  '} page {name}: {'; '.join(problems)}", flush=True)
    failed = sum(bool(r["problems"]) for r in results.values())
    print(f"{len(cases) - failed} of {len(cases)} cases pass")
    if not args.keep:  # ~120 MB each at the default 50,000 SCPs (the other files stay for a look)
        for c in cases:
            (work / "exports" / c.name / "a" / "residuals.csv").unlink(missing_ok=True)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(results, indent=1, sort_keys=True))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
