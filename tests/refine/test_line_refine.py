"""Refinement of rigorous (Pleiades DIMAP) and CSM (MRO CTX ISD) line scanners: the issue's acceptance check
(known position and attitude offsets recovered within 3 a-posteriori sigmas from GCPs simulated by the sensor
itself with 0.3 px of seeded noise; check RMSE within 10 % of the noise), the sidecar JSON round trip and the
``refine --dimap/--dg/--isd`` command."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

from explorer.cli import main  # noqa: E402
from explorer.errors import InputError, SceneFileError  # noqa: E402
from explorer.refine.adjust import refine_images  # noqa: E402
from explorer.refine.line_adjust import adjusted_sensor, correction_for, load_adjusted  # noqa: E402
from explorer.refine.points_io import PointTable  # noqa: E402
from explorer.sources import load_source  # noqa: E402
from tests.refine.cases import write_points_csv  # noqa: E402

DATA = Path(__file__).resolve().parents[1] / "data"
DIMAP = DATA / "rpc" / "PHRDIMAP_P1BP--2018122638935449CP.XML"
CTX = DATA / "usgscsm" / "ctxLineScan.json"
NOISE = 0.3
#: Known offsets: along / cross / radial metres, roll / pitch / yaw radians (several sigmas each, so that a
#: refinement that did not move would fail the 3-sigma test)
TRUTH = {"ctx": np.array([300.0, -200.0, 150.0, 4e-4, -3e-4, 5e-4]),
         "dimap": np.array([120.0, -80.0, 40.0, 6e-5, -4e-5, 5e-5])}


def simulate(sensor, truth_sensor, n: int, seed: int, prefix: str) -> PointTable:
    """Ground points seen by ``truth_sensor`` (random pixels, heights +-300 m), measured by it + 0.3 px noise."""
    rng = np.random.default_rng(seed)
    rows, cols = sensor.n_rows - 1, sensor.n_columns - 1  # 5 % margins: seen by the unadjusted sensor too
    g = truth_sensor.image_to_ground(rng.uniform(0.05 * rows, 0.95 * rows, n), rng.uniform(0.05 * cols, 0.95 * cols, n),
                                     height=rng.uniform(-300.0, 300.0, n))
    row, col = truth_sensor.ground_to_image(g)
    ok = np.isfinite(row) & np.isfinite(g).all(axis=1)
    lon, lat, h = sensor.frame.enu_to_geodetic(g[ok])
    ids = [f"{prefix}{i}" for i in range(int(ok.sum()))]
    return PointTable(ids, row[ok] + rng.normal(0, NOISE, ok.sum()), col[ok] + rng.normal(0, NOISE, ok.sum()),
                      lon, lat, h)


@pytest.fixture(scope="module", params=["ctx", "dimap"])
def acceptance(request):
    which = request.param
    kind, path = ("isd", CTX) if which == "ctx" else ("dimap", DIMAP)
    sensor = load_source(kind, str(path)).scene
    corr = correction_for(sensor, "position-attitude")
    truth = adjusted_sensor(sensor, corr, TRUTH[which])
    control = simulate(sensor, truth, 120, 11, "gcp")
    check = simulate(sensor, truth, 600, 12, "chk")
    ref = refine_images([sensor], model="position-attitude", control=control, check=check, sigma_px=NOISE,
                        image_files=[str(path)], source_kinds=[kind])
    return which, sensor, ref, control, check, path, kind


@pytest.mark.slow
def test_recovers_known_position_and_attitude_offsets(acceptance):
    which, sensor, ref, *_ = acceptance
    sigma = ref.result.parameter_sigma
    z = (ref.parameters - TRUTH[which]) / sigma
    assert np.all(np.abs(z) < 3.0), dict(zip(ref.parameter_names, z, strict=True))
    assert np.any(np.abs(TRUTH[which]) / sigma > 3.0)  # the offsets are resolved: zero would fail
    assert ref.result.sigma0 == pytest.approx(1.0, abs=0.25)
    assert not ref.result.outlier.any()


@pytest.mark.slow
def test_check_rmse_within_ten_percent_of_the_noise(acceptance):
    which, sensor, ref, *_ = acceptance
    rep = ref.report()
    assert abs(rep["check_rmse_px"] - NOISE) < 0.1 * NOISE
    assert rep["check_rmse_px_before"] > 3.0  # the offsets moved the image by pixels


@pytest.mark.slow
def test_sidecar_round_trip(acceptance, tmp_path):
    """The written sidecar, loaded back with its base file, projects as the adjusted sensor of the refinement;
    a different base file is refused (hash)."""
    which, sensor, ref, control, check, path, kind = acceptance
    ref.write(tmp_path)
    sidecar = json.loads((tmp_path / "adjusted_model.json").read_text())
    assert sidecar["base_file"] == path.name and len(sidecar["base_sha256"]) == 64
    assert [p["name"] for p in sidecar["parameters"]] == list(ref.parameter_names)
    loaded = load_adjusted(tmp_path / "adjusted_model.json", path)
    ground = sensor.frame.geodetic_to_enu(check.lon, check.lat, check.h)
    want = ref.images[0].adjusted.ground_to_image(ground)
    got = loaded.ground_to_image(ground)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    other = tmp_path / ("copy" + path.suffix)
    other.write_bytes(path.read_bytes() + b" ")
    with pytest.raises(SceneFileError, match="SHA-256"):
        load_adjusted(tmp_path / "adjusted_model.json", other)
    shutil.copy(path, tmp_path / path.name)  # beside the sidecar: found by its name
    np.testing.assert_array_equal(load_adjusted(tmp_path / "adjusted_model.json").ground_to_image(ground)[0], want[0])


@pytest.mark.slow
@pytest.mark.parametrize("kind, path", [("dimap", DIMAP), ("dg", DATA / "rpc" / "rpc_WV1.xml"), ("isd", CTX)])
def test_refine_cli_on_line_scanner_sources(tmp_path, capsys, kind, path):
    """``refine --dimap/--dg/--isd`` (the sources' loader): attitude offsets recovered from 40 simulated GCPs."""
    sensor = load_source(kind, str(path)).scene
    corr = correction_for(sensor, "attitude")
    truth = adjusted_sensor(sensor, corr, np.array([3e-5, -2e-5, 4e-5]))
    write_points_csv(tmp_path / "gcps.csv", simulate(sensor, truth, 40, 5, "g"))
    assert main(["refine", f"--{kind}", str(path), "--gcps", str(tmp_path / "gcps.csv"), "--sigma-px", "0.3",
                 "--out", str(tmp_path / "out"), "--no-panels"]) == 0
    out = capsys.readouterr().out
    assert "model attitude" in out and "roll_rad" in out
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    assert rep["model"] == "attitude" and [p["name"] for p in rep["parameters"]] == ["roll_rad", "pitch_rad", "yaw_rad"]
    assert {p.name for p in (tmp_path / "out").iterdir()} == {"report.json", "points.csv", "parameters.csv",
                                                               "adjusted_model.json"}
    assert rep["control_rmse_px"] < 0.5
    values = np.array([p["value"] for p in rep["parameters"]])
    sigmas = np.array([p["sigma"] for p in rep["parameters"]])
    assert np.all(np.abs(values - [3e-5, -2e-5, 4e-5]) < 3 * sigmas)
    assert json.loads((tmp_path / "out" / "adjusted_model.json").read_text())["source_kind"] == kind


@pytest.mark.parametrize("extra, message", [
    (["--model", "affine"], "unknown rigorous line-scan model correction model 'affine'"),
    (["--model", "jitter", "--jitter-hz", "50"], "Nyquist"),
    (["--images", str(CTX)], "exclude each other"),
])
def test_refine_line_scanner_bad_input_is_one_line(tmp_path, capsys, extra, message):
    (tmp_path / "g.csv").write_text("id,lon,lat,h,row,col\na,1,1,0,1,1\n")
    code = main(["refine", "--dimap", str(DIMAP), "--gcps", str(tmp_path / "g.csv"), *extra,
                 "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and message in err and len(err.splitlines()) == 1


def test_jitter_frequencies_must_be_sampled():
    sensor = load_source("dimap", str(DIMAP)).scene
    with pytest.raises(InputError, match="Nyquist"):
        correction_for(sensor, "jitter", (100.0,))
    corr = correction_for(sensor, "jitter")
    t0, t1 = sensor.time_range()
    assert corr.frequencies_hz == pytest.approx((1 / (t1 - t0), 2 / (t1 - t0)))
    assert len(corr.parameter_names) == 6 + 6 * 2


@pytest.mark.slow
def test_recovers_attitude_jitter_harmonics():
    """Pleiades DIMAP biased by attitude offsets, drifts and harmonics at 1/T and 2/T (1-3 px each): the
    ``jitter`` model recovers all 18 parameters within 3 sigmas and the amplitude / phase it reports are those of
    the truth's harmonics."""
    sensor = load_source("dimap", str(DIMAP)).scene
    corr = correction_for(sensor, "jitter")
    names = corr.parameter_names
    truth = np.zeros(corr.n_parameters)
    values = {"roll_rad": 2e-5, "pitch_rad": -1e-5, "yaw_rad": 3e-5, "roll_rad_per_s": 1e-6,
              "pitch_rad_per_s": -2e-6, "roll_sin1_rad": 2e-6, "roll_cos1_rad": -1e-6, "pitch_sin2_rad": 1.5e-6,
              "yaw_cos1_rad": 4e-6}
    for k, v in values.items():
        truth[names.index(k)] = v
    biased = adjusted_sensor(sensor, corr, truth)
    control = simulate(sensor, biased, 300, 21, "gcp")
    check = simulate(sensor, biased, 600, 22, "chk")
    ref = refine_images([sensor], model="jitter", control=control, check=check, sigma_px=NOISE)
    z = (ref.parameters - truth) / ref.result.parameter_sigma
    assert np.all(np.abs(z) < 3.0), dict(zip(names, np.round(z, 2), strict=True))
    assert abs(ref.check_rmse_px - NOISE) < 0.1 * NOISE
    harmonics = ref.report()["images"][0]["harmonics"]
    roll1 = next(h for h in harmonics if h["axis"] == "roll" and h["frequency_hz"] == corr.frequencies_hz[0])
    assert roll1["amplitude_rad"] == pytest.approx(np.hypot(2e-6, -1e-6), abs=3 * float(
        np.max(ref.result.parameter_sigma[[names.index("roll_sin1_rad"), names.index("roll_cos1_rad")]])))
