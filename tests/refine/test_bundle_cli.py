"""``pushbroom refine --images A B --kinds ... --ties ... --gcps ... --check ...`` on images of different kinds:
the rigorous model of the 2017 Pleiades DIMAP file (``--kinds dimap``) and an RPC file of the same ground seen
from ~20 degrees away (an RPC fitted to the off-nadir copy of tests/refine/linescan_pair.py and written as RPC00B
text, ``--kinds rpc``), each with its default correction model (attitude for the line scanner, affine for the RPC).

Truths: A biased by known roll / pitch / yaw offsets, B by a known image-space affine; ties, GCPs and check points
simulated by the biased models with 0.3 px of seeded noise.  The recovered parameters lie within 3 a-posteriori
sigmas; the triangulated check points within 1.5x the error propagated from the adjusted covariance; the sidecar
written for A loads back (its base file's SHA-256 checked) as the adjusted sensor.
"""

from __future__ import annotations

import csv
import json
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("torch")

from explorer.cli import main  # noqa: E402
from explorer.refine.corrections import apply_correction  # noqa: E402
from explorer.refine.line_adjust import adjusted_sensor, correction_for, load_adjusted  # noqa: E402
from explorer.rpc.fit import fit_rfm_from_gcps  # noqa: E402
from explorer.rpc.writers import write_rpc00b_text  # noqa: E402
from tests.refine.linescan_pair import DIMAP_2017, NOISE_PX, load_dimap_2017, off_nadir_copy, simulate  # noqa: E402

pytestmark = pytest.mark.slow

ATTITUDE_A = np.array([3e-5, -2e-5, 4e-5])
AFFINE_B = np.array([3.0, 1.0e-4, -1.0e-4, -2.0, 1.0e-4, 1.0e-4])


class _BiasedRPC:
    """An RPC with an image-space affine as a ground (local ENU of ``frame``) to image function."""

    def __init__(self, rpc, frame, affine):
        self.rpc, self.frame, self.affine = rpc, frame, affine
        self.n_rows, self.n_columns = rpc.image_size

    def ground_to_image(self, enu):
        lon, lat, h = self.frame.enu_to_geodetic(enu)
        return apply_correction("affine", self.affine, *self.rpc.projection(lon, lat, h))


def fit_rpc(sensor, rng: np.random.Generator):
    """A third-order RPC fitted to ``sensor`` over its whole image (3,000 points, heights -400 .. 1,000 m)."""
    n = 3000
    row = rng.uniform(0, sensor.n_rows - 1, n)
    col = rng.uniform(0, sensor.n_columns - 1, n)
    h = rng.uniform(-400.0, 1000.0, n)
    lon, lat, hh = sensor.frame.enu_to_geodetic(sensor.image_to_ground(row, col, height=h))
    fit = fit_rfm_from_gcps(lon, lat, hh, row, col, order=3)
    assert fit.rms_px < 0.05  # (the RPC is its own truth below; a good fit only keeps the scene realistic)
    return replace(fit.model, image_size=(int(sensor.n_rows), int(sensor.n_columns)))


def write_table(path, table, names, ground: bool):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "lon", "lat", "h", "row", "col", "image"] if ground else ["id", "image", "row", "col"])
        for i, pid in enumerate(table.ids):
            name = names[int(table.image[i])]
            if ground:
                w.writerow([pid, f"{table.lon[i]:.12f}", f"{table.lat[i]:.12f}", f"{table.h[i]:.6f}",
                            f"{table.row[i]:.6f}", f"{table.col[i]:.6f}", name])
            else:
                w.writerow([pid, name, f"{table.row[i]:.6f}", f"{table.col[i]:.6f}"])
    return path


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bundle_cli")
    a = load_dimap_2017()
    rng = np.random.default_rng(2812)
    rpc_b = fit_rpc(off_nadir_copy(a), rng)
    rpc_file = write_rpc00b_text(rpc_b, folder / "B_rpc.txt")
    truths = [adjusted_sensor(a, correction_for(a, "attitude"), ATTITUDE_A), _BiasedRPC(rpc_b, a.frame, AFFINE_B)]
    names = [DIMAP_2017.name, rpc_file.name]
    files = {
        "ties": write_table(folder / "ties.csv", simulate(truths, a.frame, 150, rng, "t", ground_known=False), names,
                            False),
        "gcps": write_table(folder / "gcps.csv", simulate(truths, a.frame, 6, rng, "g", ground_known=True), names,
                            True),
        "check": write_table(folder / "check.csv", simulate(truths, a.frame, 40, rng, "c", ground_known=True), names,
                             True),
    }
    out = folder / "out"
    code = main(["refine", "--images", str(DIMAP_2017), str(rpc_file), "--kinds", "dimap,rpc",
                 "--ties", str(files["ties"]), "--gcps", str(files["gcps"]), "--check", str(files["check"]),
                 "--sigma-px", str(NOISE_PX), "--no-panels", "--out", str(out)])
    assert code == 0
    return a, rpc_b, rpc_file, files, out


def test_mixed_kinds_default_models_and_files(mixed):
    a, rpc_b, rpc_file, files, out = mixed
    report = json.loads((out / "report.json").read_text())
    assert report["model"] == "attitude,affine"
    assert [(im["kind"], im["model"], im["adjusted_model"]) for im in report["images"]] == [
        ("linescan", "attitude", "adjusted_model_0.json"), ("rpc", "affine", "adjusted_rpc_1.txt")]
    assert {p.name for p in out.iterdir()} == {"report.json", "points.csv", "parameters.csv", "adjusted_model_0.json",
                                               "adjusted_rpc_1.txt"}
    with open(out / "points.csv") as f:
        roles = {row["role"] for row in csv.DictReader(f)}
    assert roles == {"control", "check", "tie"}


def test_recovered_within_three_sigmas_and_check_ground(mixed):
    a, rpc_b, rpc_file, files, out = mixed
    report = json.loads((out / "report.json").read_text())
    values = np.array([p["value"] for p in report["parameters"]])
    sigmas = np.array([p["sigma"] for p in report["parameters"]])
    z = (values - np.concatenate([ATTITUDE_A, AFFINE_B])) / sigmas
    assert np.all(np.abs(z) < 3.0), z
    assert np.abs(ATTITUDE_A / sigmas[:3]).min() > 3.0  # resolved: no adjustment at all would fail
    ground = report["check_ground"]
    assert ground["n"] == 40 and ground["rmse_3d_m"] <= 1.5 * ground["predicted_rmse_3d_m"], ground
    assert report["sigma0"] == pytest.approx(1.0, abs=0.2)
    assert report["check_rmse_px_before"] > 10.0


def test_sidecar_loads_back_as_the_adjusted_sensor(mixed):
    a, rpc_b, rpc_file, files, out = mixed
    sidecar = json.loads((out / "adjusted_model_0.json").read_text())
    assert sidecar["base_file"] == DIMAP_2017.name and sidecar["source_kind"] == "dimap"
    values = np.array([p["value"] for p in sidecar["parameters"]])
    loaded = load_adjusted(out / "adjusted_model_0.json", DIMAP_2017)
    want = adjusted_sensor(a, correction_for(a, "attitude"), values)
    g = a.image_to_ground(np.array([100.0, 20000.0, 40000.0]), np.array([300.0, 20000.0, 39000.0]))
    np.testing.assert_array_equal(loaded.ground_to_image(g)[0], want.ground_to_image(g)[0])


def test_bad_input_is_one_line(mixed, tmp_path, capsys):
    a, rpc_b, rpc_file, files, out = mixed
    isd = DIMAP_2017.parents[1] / "usgscsm" / "ctxLineScan.json"
    scene = tmp_path / "scene.json"
    scene.write_text("{}")
    cases = [
        (["--images", str(DIMAP_2017), str(isd), "--kinds", "dimap,isd"], "images on different bodies"),
        (["--images", str(DIMAP_2017), str(rpc_file), "--kinds", "dimap,rpc", "--model", "affine"],
         "unknown rigorous line-scan model correction model 'affine'"),
        (["--images", str(DIMAP_2017), str(rpc_file), "--kinds", "dimap,rpc,scene"], "3 kinds for 2 images"),
        (["--images", str(DIMAP_2017), str(rpc_file), "--model", "attitude,affine,shift"],
         "3 correction models for 2 images"),
        (["--images", str(DIMAP_2017), str(scene), "--kinds", "dimap,scene"], str(scene)),
        (["--dimap", str(DIMAP_2017), "--kinds", "rpc"], "--kinds goes with SOURCE or --images"),
    ]
    for extra, message in cases:
        code = main(["refine", *extra, "--ties", str(files["ties"]), "--out", str(tmp_path / "o")])
        err = capsys.readouterr().err
        assert code == 2 and message in err and len(err.strip().splitlines()) == 1, (extra, err)
    # a tie point in one image, a tie naming an image that is not given
    lines = files["ties"].read_text().splitlines()
    one = tmp_path / "one.csv"
    one.write_text("\n".join([lines[0], lines[1], lines[151], lines[2]]) + "\n")  # t0 in A and B, t1 in A only
    unknown = tmp_path / "unknown.csv"
    unknown.write_text("\n".join(lines[:3] + [lines[151].replace(rpc_file.name, "C.txt")]) + "\n")
    for ties, message in ((one, "tie point 't1' is measured in one image only"),
                          (unknown, "image 'C.txt' is not one of the images")):
        code = main(["refine", "--images", str(DIMAP_2017), str(rpc_file), "--kinds", "dimap,rpc", "--ties",
                     str(ties), "--gcps", str(files["gcps"]), "--out", str(tmp_path / "o")])
        err = capsys.readouterr().err
        assert code == 2 and message in err and len(err.strip().splitlines()) == 1, (ties, err)


def write_isd_copy(isd_path, camera, path):
    """The ISD of ``isd_path`` carrying the state of ``camera`` (a CsmCamera read from it, then corrected): the
    reader's usgscsm state -- body-fixed positions on even nodes, sensor pointing quaternions with an identity body
    rotation -- written back as such (positions in the body frame, km; one identity body-rotation sample), so that
    reading it gives the same tables."""
    d = json.loads(isd_path.read_text())
    centre = float(d["center_ephemeris_time"])
    body_frame = d["body_rotation"]["time_dependent_frames"][0]
    d["instrument_position"] = {"ephemeris_times": (camera.position_times + centre).tolist(),
                                "positions": (camera.positions_m / 1000.0).tolist(), "reference_frame": body_frame}
    d["instrument_pointing"] = {"ephemeris_times": (camera.pointing_times + centre).tolist(),
                                "quaternions": camera.pointing_quaternions.tolist(),
                                "constant_rotation": np.eye(3).ravel().tolist(), "reference_frame": 1}
    d["body_rotation"] = {"ephemeris_times": [float(camera.pointing_times[0] + centre)],
                          "quaternions": [[1.0, 0.0, 0.0, 0.0]], "constant_rotation": np.eye(3).ravel().tolist(),
                          "time_dependent_frames": [body_frame], "reference_frame": 1}
    path.write_text(json.dumps(d))
    return path


def test_isd_pair_found_by_auto_kinds(tmp_path):
    """Two ISD files (the CTX ISD and a copy written with the tables of its off-nadir copy, 100 km along the
    orbit), kinds found by ``auto`` (an ISD .json), default model attitude on both, attitude biases recovered
    within 3 sigmas, triangulated checks within 1.5x the propagated error, one sidecar per image."""
    from explorer.sources import load_source
    from tests.refine.linescan_pair import PAIRS

    isd_a = PAIRS["isd"][0]
    a = load_source("isd", str(isd_a), stand_in=False).scene
    b_mem = off_nadir_copy(a, PAIRS["isd"][1])
    isd_b = write_isd_copy(isd_a, b_mem.camera, tmp_path / "ctx_b.json")
    b = load_source("isd", str(isd_b), stand_in=False).scene
    g = a.image_to_ground(np.array([1000.0, 5600.0, 10000.0]), np.array([1200.0, 2500.0, 3800.0]))
    np.testing.assert_allclose(np.stack(b.ground_to_image(b.frame.geodetic_to_enu(*a.frame.enu_to_geodetic(g)))),
                               np.stack(b_mem.ground_to_image(g)), atol=1e-6)
    bias = (np.array([2e-4, -1.5e-4, 6e-4]), np.array([-2e-4, 1e-4, -5e-4]))  # (yaw: sigma ~1e-4 on CTX)
    truths = [adjusted_sensor(s, correction_for(s, "attitude"), p) for s, p in zip((a, b), bias, strict=True)]
    rng = np.random.default_rng(2813)
    names = [isd_a.name, isd_b.name]
    ties = write_table(tmp_path / "ties.csv", simulate(truths, a.frame, 100, rng, "t", ground_known=False), names,
                       False)
    gcps = write_table(tmp_path / "gcps.csv", simulate(truths, a.frame, 6, rng, "g", ground_known=True), names, True)
    check = write_table(tmp_path / "check.csv", simulate(truths, a.frame, 30, rng, "c", ground_known=True), names,
                        True)
    out = tmp_path / "out"
    assert main(["refine", "--images", str(isd_a), str(isd_b), "--ties", str(ties), "--gcps", str(gcps), "--check",
                 str(check), "--sigma-px", str(NOISE_PX), "--no-panels", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["model"] == "attitude" and [im["kind"] for im in report["images"]] == ["linescan", "linescan"]
    values = np.array([p["value"] for p in report["parameters"]])
    sigmas = np.array([p["sigma"] for p in report["parameters"]])
    z = (values - np.concatenate(bias)) / sigmas
    assert np.all(np.abs(z) < 3.0), z
    assert np.abs(np.concatenate(bias) / sigmas).min() > 3.0
    ground = report["check_ground"]
    assert ground["rmse_3d_m"] <= 1.5 * ground["predicted_rmse_3d_m"], ground
    for k, path in enumerate((isd_a, isd_b)):
        sidecar = json.loads((out / f"adjusted_model_{k}.json").read_text())
        assert sidecar["source_kind"] == "isd" and sidecar["base_file"] == path.name
