"""USGS CSM line-scan ISDs whose ephemeris tables do not cover the image, and physically impossible ISDs.

Truths: the real CTX ISD of usgscsm's tests (tests/data/usgscsm/ctxLineScan.json, checked against
usgscsm's asserted values in test_csm.py) edited in the test into an HRSC-like camera (4 x 4 summing,
two line rates, the second running past the tables) whose covered lines must give exactly the CTX
camera's geometry at the corresponding CTX line and sample (same tables, same times); and the tables'
own times for the lines that must be flagged or refused.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from explorer.errors import SceneFileError
from explorer.real.csm import camera_from_isd
from explorer.real.csm_camera import STATUS_OUTSIDE_TABLES

DATA = Path(__file__).resolve().parents[1] / "data" / "usgscsm"
CTX = json.loads((DATA / "ctxLineScan.json").read_text())
DT = CTX["line_scan_rate"][0][2]  # CTX seconds per line
T0 = CTX["line_scan_rate"][0][1]  # the first line's start, seconds from center_ephemeris_time
SPLIT = 1408  # HRSC-like lines in the first segment (4 CTX lines each)


def hrsc_like() -> dict:
    """CTX re-read as a 4 x 4 summed camera: 1408 lines at 4 CTX periods, then 6 CTX periods per line.

    The second segment runs past the tables (which end with CTX's last line, 5632 + 6 (L - 1408) CTX lines
    in): HRSC-like lines up to 1408 + 5632 / 6 = 2346.67 are covered, the rest are not."""
    isd = copy.deepcopy(CTX)
    isd["image_lines"] = 2816
    isd["image_samples"] = 1250
    isd["detector_sample_summing"] = 4
    isd["detector_line_summing"] = 4
    isd["line_scan_rate"] = [[0.5, T0, 4 * DT], [SPLIT + 0.5, T0 + 4 * SPLIT * DT, 6 * DT]]
    return isd


def ctx_line(line: np.ndarray) -> np.ndarray:
    """The CTX line exposed at the same time as an HRSC-like line (closed form of the two rates)."""
    return np.where(line < SPLIT + 0.5, 4 * line, 4 * SPLIT + 6 * (line - SPLIT))


@pytest.fixture(scope="module")
def ctx():
    return camera_from_isd(copy.deepcopy(CTX), source="ctxLineScan.json")


@pytest.fixture(scope="module")
def hrsc():
    return camera_from_isd(hrsc_like(), source="hrsc_like.json")


def test_hrsc_like_covered_lines_are_the_ctx_geometry(ctx, hrsc):
    rng = np.random.default_rng(11)
    n = 600
    lines = np.concatenate([rng.uniform(0, SPLIT, n // 2), rng.uniform(SPLIT + 0.5, 2346.0, n // 2)])
    samples = rng.uniform(0, 1250, n)
    heights = rng.uniform(-800, 800, n)
    g = hrsc.image_to_ground(lines, samples, heights)
    assert g.hit.all()
    truth = ctx.image_to_ground(ctx_line(lines), 4 * samples, heights)
    assert truth.hit.all()
    np.testing.assert_allclose(g.ground, truth.ground, rtol=0, atol=1e-6)
    r = hrsc.ground_to_image(truth.ground)
    assert r.valid.all()
    np.testing.assert_allclose(r.line, lines, rtol=0, atol=1e-6)
    np.testing.assert_allclose(r.sample, samples, rtol=0, atol=1e-6)


def test_hrsc_like_lines_past_the_tables_are_flagged(hrsc):
    # the tables end with CTX's last line: 1408 + 5632 / 6 = 2346.67 HRSC-like lines, plus half a line
    assert hrsc.covered_line_ranges() == [(0.0, 2347.0)]
    assert hrsc.covered_fraction() == pytest.approx(2347 / 2816)
    assert "tables cover 83.3 % of the lines (0-2347)" in hrsc.describe()
    lines = np.array([2340.0, 2346.5, 2348.5, 2400.0, 2815.5])
    g = hrsc.image_to_ground(lines, np.full(5, 600.0), 0.0)
    np.testing.assert_array_equal(g.hit, [True, True, False, False, False])
    assert np.isnan(g.ground[2:]).all()
    centre, look = hrsc.rays(lines, np.full(5, 600.0))
    np.testing.assert_array_equal(np.isnan(centre).all(axis=1), [False, False, True, True, True])
    np.testing.assert_array_equal(np.isnan(look).all(axis=1), [False, False, True, True, True])
    t = hrsc.line_time(lines)
    np.testing.assert_array_equal(hrsc.time_covered(t), [True, True, False, False, False])
    # ground points the camera would see there if its tables were extrapolated: flagged, not returned valid
    past = np.linspace(2360.0, 2815.0, 40)
    ground, hit = hrsc._image_to_ground_raw(past, np.full(past.size, 600.0), 0.0)
    assert hit.all()
    r = hrsc.ground_to_image(ground)
    assert not r.valid.any()
    assert (r.status == STATUS_OUTSIDE_TABLES).all()
    # the residual's search still found the (extrapolated) line: the flag is the tables', not the solver's
    np.testing.assert_allclose(r.line, past, rtol=0, atol=1e-6)


def test_pointing_table_after_the_last_line_is_refused_with_the_times():
    """MOC-like: the pointing table starts 30 s after the image's last line (the image spans 21.1 s)."""
    isd = copy.deepcopy(CTX)
    times = isd["instrument_pointing"]["ephemeris_times"]
    isd["instrument_pointing"]["ephemeris_times"] = [t + 10.571264 + 30.0 + (t - times[0]) for t in times]
    with pytest.raises(SceneFileError) as exc:
        camera_from_isd(isd, source="moc_like.json")
    msg = str(exc.value)
    assert "moc_like.json" in msg and "'instrument_pointing'" in msg and "do not cover the image" in msg
    start = isd["instrument_pointing"]["ephemeris_times"][0]
    image_start = CTX["center_ephemeris_time"] + T0
    assert f"{start:.6f}" in msg and f"{image_start:.6f}" in msg
    assert "\n" not in msg


def test_pointing_table_starting_mid_image_flags_the_lines_before():
    isd = copy.deepcopy(CTX)
    table = isd["instrument_pointing"]
    keep = [k for k, t in enumerate(table["ephemeris_times"]) if t >= CTX["center_ephemeris_time"]]
    table["ephemeris_times"] = [table["ephemeris_times"][k] for k in keep]
    table["quaternions"] = [table["quaternions"][k] for k in keep]
    cam = camera_from_isd(isd, source="half.json")
    first = (table["ephemeris_times"][0] - CTX["center_ephemeris_time"] - T0) / DT  # line of the table's start
    (a, b), = cam.covered_line_ranges()
    assert b == CTX["image_lines"] and abs(a - np.ceil(first - 1.0)) <= 1
    g = cam.image_to_ground([first - 5.0, first + 5.0], [2500.0, 2500.0], 0.0)
    np.testing.assert_array_equal(g.hit, [False, True])


@pytest.mark.parametrize(
    ("edit", "key", "reason"),
    [
        (lambda d: d["instrument_position"].__setitem__(
            "positions", [[0.0, 0.0, 0.0]] * len(d["instrument_position"]["positions"])),
         "instrument_position.positions", "inside the body"),
        (lambda d: d["instrument_position"]["positions"].__setitem__(5, [100.0, 200.0, 50.0]),
         "instrument_position.positions", "row 5"),
        (lambda d: d["instrument_pointing"].__setitem__(
            "constant_rotation", [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0]),
         "instrument_pointing.constant_rotation", "reflection"),
        (lambda d: d["instrument_pointing"]["quaternions"].__setitem__(
            3, [1.5 * v for v in d["instrument_pointing"]["quaternions"][3]]),
         "instrument_pointing.quaternions", "row 3 has norm 1.5"),
        (lambda d: d["body_rotation"]["quaternions"].__setitem__(0, [0.0, 0.0, 0.0, 0.0]),
         "body_rotation.quaternions", "not a unit quaternion"),
        (lambda d: d["instrument_position"].__setitem__(
            "ephemeris_times", [t + 100.0 for t in d["instrument_position"]["ephemeris_times"]]),
         "instrument_position", "do not cover the image"),
        (lambda d: d["reference_height"].__setitem__("minheight", -2e6), "reference_height", "half the body"),
        (lambda d: d["reference_height"].__setitem__("maxheight", 1e9), "reference_height", "half the body"),
        (lambda d: d.__setitem__("radii", {"semimajor": 3669.6, "semiminor": 3669.5, "unit": "km"}),
         "reference_height", "not below the sensor"),
        (lambda d: d.__setitem__("image_lines", 1e-300), "image_lines", "whole number"),
        (lambda d: d.__setitem__("image_samples", 5000.5), "image_samples", "whole number"),
    ],
    ids=["body-centre", "one-inside", "reflection", "non-unit", "zero-quaternion", "ephemeris-after",
         "terrain-below-half-body", "terrain-above-half-body", "sensor-below-terrain", "tiny-lines", "half-sample"],
)
def test_impossible_isd_is_one_line_naming_file_and_key(edit, key, reason):
    isd = copy.deepcopy(CTX)
    edit(isd)
    with pytest.raises(SceneFileError) as exc:
        camera_from_isd(isd, source="bad_ctx.json")
    msg = str(exc.value)
    assert msg.startswith("bad_ctx.json: ") and key in msg and reason in msg and "\n" not in msg


@pytest.mark.parametrize(
    ("rates", "pointing_window"),
    [
        ([[0.5, -1.0, 0.005], [200.5, 0.0, 0.0025]], None),
        ([[0.5, -1.0, 0.005], [100.5, -0.5, 0.01]], None),  # the second rate runs past the tables
        ([[0.5, -0.9, 0.004], [50.5, -0.7, 0.009], [120.5, -0.07, 0.001]], None),
        ([[0.5, -1.0, 0.005], [200.5, 0.0, 0.0025]], (-0.7, 0.6)),  # the pointing table starts mid-image
        ([[0.5, -1.0, 0.005], [100.5, -0.5, 0.0025]], (-0.3, 0.2)),  # covered in the middle only
    ],
)
def test_covered_ranges_are_the_lines_line_covered_accepts(rates, pointing_window):
    """covered_line_ranges (closed form per rate segment) against line_covered evaluated at every line's
    centre (brute force)."""
    from tests.real.test_csm import flyby_isd

    isd = flyby_isd(rates=rates)
    if pointing_window is not None:
        table = isd["instrument_pointing"]
        keep = [k for k, t in enumerate(table["ephemeris_times"])
                if pointing_window[0] <= t - isd["center_ephemeris_time"] <= pointing_window[1] + 1e-9]
        table["ephemeris_times"] = [table["ephemeris_times"][k] for k in keep]
        table["quaternions"] = [table["quaternions"][k] for k in keep]
    cam = camera_from_isd(isd, source="rates")
    ok = cam.line_covered(np.arange(cam.n_lines) + 0.5)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    brute = [(float(a), float(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]
    assert cam.covered_line_ranges() == brute
    assert cam.covered_fraction() == pytest.approx(ok.mean(), abs=1e-15)
    if pointing_window is not None:
        assert ok.mean() < 1.0


def test_search_methods_run_on_the_covered_lines(hrsc):
    """The CSM camera as the project's sensor: grids (SCOPs, SCPs, the exact method's seed) keep the covered
    lines only, and exact / csm-secant find the camera's own lines there (1e-6 px) instead of failing on the
    flagged ones (issue 25, class 1)."""
    from explorer.methods import create
    from explorer.points import image_grid
    from explorer.real.csm_sensor import csm_scene

    scene = csm_scene(hrsc)
    grid = image_grid(scene, 600, layers=3)
    assert len(grid) > 0 and np.all(np.isfinite(grid.ground))
    assert grid.row.max() <= 2347.0 - 0.5  # scene rows are CSM lines - 0.5: only covered lines
    for name in ("exact", "csm-secant"):
        r = create(name, scene).ground_to_image(grid.ground)
        assert r.valid.all(), name
        assert np.max(np.abs(r.row - grid.row)) < 1e-6, name
        assert np.max(np.abs(r.col - grid.col)) < 1e-6, name


def test_sensor_projection_flags_lines_past_the_tables(hrsc):
    """Through the Sensor (CsmScene.project / ground_to_image), a ground point the camera would see past its
    tables is flagged (invalid; no line from ground_to_image), one on a covered line is the camera's own."""
    from explorer.real.csm_sensor import csm_scene

    scene = csm_scene(hrsc)
    lines = np.array([1000.0, 2300.0, 2500.0, 2800.0])
    xyz, hit = hrsc._image_to_ground_raw(lines, np.full(4, 600.0), 0.0)
    assert hit.all()
    p = scene.project(scene.from_body_fixed(xyz))
    np.testing.assert_array_equal(p.valid, [True, True, False, False])
    np.testing.assert_allclose(p.row[:2], lines[:2] - 0.5, rtol=0, atol=1e-6)
    row, col = scene.ground_to_image(scene.from_body_fixed(xyz))
    np.testing.assert_allclose(row[:2], lines[:2] - 0.5, rtol=0, atol=1e-6)
    assert np.isnan(row[2:]).all() and np.isnan(col[2:]).all()


def test_scenes_of_a_camera_whose_centre_line_is_not_covered():
    """The pointing table starts after the image centre (the first 60 % of the lines flagged): the MPC scene
    and the camera's Sensor anchor their frame on the covered lines instead of refusing 'the image centre
    does not see the body', and the Sensor projects covered points to the camera's own lines."""
    from explorer.real.csm_scene import scene_from_camera
    from explorer.real.csm_sensor import csm_scene

    isd = copy.deepcopy(CTX)
    table = isd["instrument_pointing"]
    start = CTX["center_ephemeris_time"] + T0 + 0.6 * CTX["image_lines"] * DT
    keep = [k for k, t in enumerate(table["ephemeris_times"]) if t >= start]
    table["ephemeris_times"] = [table["ephemeris_times"][k] for k in keep]
    table["quaternions"] = [table["quaternions"][k] for k in keep]
    cam = camera_from_isd(isd, source="late_pointing.json")
    assert not cam.line_covered(np.array([0.5 * cam.n_lines]))[0]
    (a, b), = cam.covered_line_ranges()
    assert cam.covered_centre_line() == 0.5 * (a + b) and b == cam.n_lines
    mpc = scene_from_camera(cam, n_check=200)
    assert mpc.metadata["csm_fit"]["n"] > 0
    scene = csm_scene(cam)
    lines = np.array([a + 10.0, 0.5 * (a + b), b - 10.0])
    g = cam.image_to_ground(lines, np.full(3, 2500.0), 0.0)
    p = scene.project(scene.from_body_fixed(g.ground))
    assert p.valid.all()
    np.testing.assert_allclose(p.row, lines - 0.5, rtol=0, atol=1e-6)


def brute_force_lines(camera, ground: np.ndarray, step: float = 0.25, lo: float = -200.0,
                      hi: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The camera's line and sample of ground points (N, 3) by brute force: usgscsm's detector-line residual
    sampled every ``step`` lines over ``[lo, hi]`` (the tables extrapolated, as the residual is defined at any
    line), its one sign change bracketed, then bisected to 1e-10 line.  NaN where there is no sign change.
    Independent of every solver of the package (no seed, no secant, no Newton)."""
    hi = camera.n_lines + 200.0 if hi is None else hi
    grid = np.arange(lo, hi + step, step)
    n = ground.shape[0]
    res = camera.detector_residual(np.repeat(ground, grid.size, axis=0), np.tile(grid, n))[0].reshape(n, grid.size)
    change = np.signbit(res[:, :-1]) != np.signbit(res[:, 1:])
    found = change.any(axis=1)
    k = np.argmax(change, axis=1)
    a, b = grid[k], grid[k + 1]
    fa = res[np.arange(n), k]
    for _ in range(60):  # bisection: step / 2**60 << 1e-10 line
        m = 0.5 * (a + b)
        fm = camera.detector_residual(ground, m)[0]
        left = np.signbit(fm) == np.signbit(fa)
        a, fa = np.where(left, m, a), np.where(left, fm, fa)
        b = np.where(left, b, m)
    line = np.where(found, 0.5 * (a + b), np.nan)
    sample = camera.detector_residual(ground, np.where(found, line, 0.0))[1]
    return line, np.where(found, sample, np.nan)


def test_every_method_flags_a_row_outside_the_tables(hrsc):
    """Issue 23: on a CSM camera whose tables stop mid-image (HRSC-like: lines past 2347 not covered), a point the
    camera would see past the tables is flagged in every method's result -- status "outside tables", the camera's
    own status 5 -- never returned valid from the extrapolated tables; points on covered lines are found where the
    brute-force search along the line puts them (exact, csm-secant, nr: 1e-6 px)."""
    from explorer.app.model import STATUS_NAMES, point_status
    from explorer.methods import available, create
    from explorer.points import simulate_points
    from explorer.real.csm_sensor import csm_scene

    scene = csm_scene(hrsc)
    rng = np.random.default_rng(5)
    n = 160
    lines = np.concatenate([rng.uniform(20, 2330, n // 2), rng.uniform(2365, 2790, n // 2)])
    samples = rng.uniform(30, 1220, n)
    xyz, hit = hrsc._image_to_ground_raw(lines, samples, rng.uniform(-500, 500, n))
    assert hit.all()
    truth_line, truth_sample = brute_force_lines(hrsc, xyz)
    assert np.isfinite(truth_line).all()
    np.testing.assert_allclose(truth_line, lines, rtol=0, atol=1e-6)  # the brute force agrees with the set-up
    covered = hrsc.line_covered(truth_line)
    np.testing.assert_array_equal(covered, lines < 2347)
    ground = scene.from_body_fixed(xyz)
    # the sensor itself: covered points are its own, the others flagged
    p = scene.project(ground)
    np.testing.assert_array_equal(p.valid, covered)
    np.testing.assert_allclose(p.row[covered], truth_line[covered] - 0.5, rtol=0, atol=1e-6)

    scops = simulate_points(scene, 100, kind="scop", seed=3)
    outside_tables = STATUS_NAMES.index("outside tables")
    for name in available():
        method = create(name, scene)
        if method.needs_fit:
            method.fit(scops)
        r = method.ground_to_image(ground)
        assert r.covered is not None, name
        finite = np.isfinite(r.row)
        # a valid row is always on a covered line; every finite row on an uncovered line is flagged as such
        assert scene.rows_covered(r.row[r.valid]).all(), name
        flagged = finite & ~scene.rows_covered(np.where(finite, r.row, 0.0))
        np.testing.assert_array_equal(~r.covered, flagged, err_msg=name)
        status = point_status(r)
        assert (status[flagged & r.converged] == outside_tables).all(), name
        assert not (r.valid & (status != 0)).any(), name
        if name in ("exact", "csm-secant", "nr"):  # exact search methods: the camera's own lines
            np.testing.assert_array_equal(r.valid, covered, err_msg=name)
            np.testing.assert_allclose(r.row[covered], truth_line[covered] - 0.5, rtol=0, atol=1e-6, err_msg=name)
            np.testing.assert_allclose(r.col[covered], truth_sample[covered] - 0.5, rtol=0, atol=1e-6,
                                       err_msg=name)
            assert (status[~covered] == outside_tables).all(), name


def test_explore_export_of_an_isd_whose_tables_stop_mid_image(tmp_path):
    """``explore --isd --export`` on the HRSC-like ISD runs on the covered lines and says so (summary.json's
    source and the export page), every check point on a covered line, exact on the camera's own lines."""
    import csv

    from explorer.cli import main

    isd = tmp_path / "hrsc_like.json"
    isd.write_text(json.dumps(hrsc_like()))
    out = tmp_path / "export"
    assert main(["explore", "--isd", str(isd), "--methods", "exact,lrm", "--scops", "40", "--scps", "1500",
                 "--export", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["source"]["table_coverage"] == {"fraction": 2347 / 2816, "lines": [[0.0, 2347.0]]}
    assert "ephemeris tables cover 83.3 % of the lines (0-2347)" in (out / "panels.html").read_text()
    with open(out / "residuals.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["method"] == "exact"]
    assert rows and all(r["status"] == "valid" for r in rows)
    lines = np.array([float(r["line"]) for r in rows])
    assert lines.max() <= 2347.0  # usgscsm's line of every check point: covered
    assert max(abs(float(r["row_residual_px"])) for r in rows) < 1e-6
