"""Refinement of a real Pleiades RPC: the issue's acceptance check, the folded RPC file, the report files."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

pytest.importorskip("torch")

from explorer.errors import InputError  # noqa: E402
from explorer.refine.adjust import refine_images  # noqa: E402
from explorer.refine.corrections import apply_correction  # noqa: E402
from explorer.refine.fold import fold_correction  # noqa: E402
from explorer.refine.points_io import read_points_csv  # noqa: E402
from explorer.rpc import read_rpc  # noqa: E402
from tests.refine.cases import TRUE_AFFINE, pleiades, simulate_points, write_points_csv  # noqa: E402

NOISE = 0.3


@pytest.fixture(scope="module")
def acceptance():
    """Pleiades RPC biased by a known affine (4.2 / -3.1 px shift, 1e-4 scale and rotation), 40 GCPs and
    500 check points with 0.3 px noise (seeded), adjusted with the stated pixel sigma."""
    rpc = pleiades()
    control = simulate_points(rpc, 40, noise_px=NOISE, seed=101, prefix="gcp")
    check = simulate_points(rpc, 500, noise_px=NOISE, seed=202, prefix="chk")
    return rpc, control, check, refine_images([rpc], model="affine", control=control, check=check, sigma_px=NOISE)


def test_recovers_a_known_affine_bias_within_three_sigmas(acceptance):
    rpc, control, check, ref = acceptance
    z = (ref.parameters - TRUE_AFFINE) / ref.result.parameter_sigma
    assert np.all(np.abs(z) < 3.0), dict(zip(ref.parameter_names, z, strict=True))
    assert ref.result.sigma0 == pytest.approx(1.0, abs=0.25)  # the stated sigma is the true noise
    assert not ref.result.outlier.any()


def test_check_rmse_within_ten_percent_of_the_noise(acceptance):
    rpc, control, check, ref = acceptance
    assert abs(ref.check_rmse_px - NOISE) < 0.1 * NOISE
    rep = ref.report()
    assert rep["check_rmse_px_before"] > 3.0  # the bias the adjustment removed
    assert abs(rep["control_rmse_px"] - NOISE) < 0.2 * NOISE


def test_folded_rpc_file_reproduces_model_plus_correction(acceptance, tmp_path):
    rpc, control, check, ref = acceptance
    written = ref.write(tmp_path / "out")
    assert {p.name for p in written} == {"report.json", "points.csv", "parameters.csv", "adjusted_rpc.txt"}
    adjusted = read_rpc(tmp_path / "out" / "adjusted_rpc.txt")
    row, col = adjusted.projection(check.lon, check.lat, check.h)
    want = apply_correction("affine", ref.parameters, *rpc.projection(check.lon, check.lat, check.h))
    fold = ref.report()["images"][0]
    err = max(np.max(np.abs(row - want[0])), np.max(np.abs(col - want[1])))
    assert err <= fold["fold_max_residual_px"] * 1.01 + 1e-9
    assert fold["fold_max_residual_px"] < 1e-3
    # the adjusted file reproduces the check measurements as well as the correction does
    d = np.stack([check.row - row, check.col - col])
    assert abs(np.sqrt(np.mean(d**2)) - ref.check_rmse_px) < 1e-3


def test_shift_and_scale_fold_exactly():
    """A shift and row_per_row / col_per_col are a*num + b*den: the refit is exact to rounding."""
    rpc = pleiades()
    params = np.array([3.25, 2e-4, 0.0, -1.5, 0.0, -1e-4])
    fold = fold_correction(rpc, "affine", params)
    assert fold.max_residual_px < 1e-7
    for shift in (np.array([10.0, -7.5]),):
        assert fold_correction(rpc, "shift", shift).max_residual_px < 1e-7


def test_report_and_points_files(acceptance, tmp_path):
    rpc, control, check, ref = acceptance
    ref.write(tmp_path)
    report = json.loads((tmp_path / "report.json").read_text())
    for key in ("model", "sigma0", "control_rmse_px", "check_rmse_px", "parameters"):
        assert key in report
    assert [p["name"] for p in report["parameters"]] == ["row_shift", "row_per_row", "row_per_col",
                                                         "col_shift", "col_per_row", "col_per_col"]
    assert all(set(p) >= {"name", "value", "sigma"} for p in report["parameters"])
    with open(tmp_path / "points.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 540
    assert {r["role"] for r in rows} == {"control", "check"}
    assert set(rows[0]) >= {"id", "role", "residual_row_before", "residual_col_after", "outlier"}
    gcp0 = next(r for r in rows if r["id"] == "gcp0")
    r0, c0 = rpc.projection(control.lon[:1], control.lat[:1], control.h[:1])
    assert float(gcp0["residual_row_before"]) == pytest.approx(control.row[0] - r0[0], abs=1e-6)


def test_point_files_and_hostile_points(tmp_path):
    rpc = pleiades()
    pts = simulate_points(rpc, 10, seed=7)
    path = write_points_csv(tmp_path / "gcps.csv", pts)
    back = read_points_csv(path)
    np.testing.assert_allclose(back.row, pts.row, atol=1e-6)
    pts.row[4] = 60000.0
    with pytest.raises(InputError, match=r"control point 'p4' \(line 6\) .* outside the image \(49826 x 39951"):
        refine_images([rpc], control=pts)
    (tmp_path / "nan.csv").write_text("id,lon,lat,h,row,col\na,57.3,22.0,100,10,nan\n")
    with pytest.raises(InputError, match=r"nan.csv: line 2, column 'col': 'nan' is not a finite number"):
        read_points_csv(tmp_path / "nan.csv")
    (tmp_path / "cols.csv").write_text("id,lon,lat,row,col\na,57.3,22.0,10,10\n")
    with pytest.raises(InputError, match="missing column\\(s\\) h"):
        read_points_csv(tmp_path / "cols.csv")
    (tmp_path / "dup.csv").write_text("id,lon,lat,h,row,col\na,57.3,22.0,1,10,10\na,57.3,22.0,1,10,10\n")
    with pytest.raises(InputError, match="id 'a' appears twice"):
        read_points_csv(tmp_path / "dup.csv")
    far = simulate_points(rpc, 10, seed=7)
    far.lon[2] += 3.0
    with pytest.raises(InputError, match="'p2' .* outside the RPC's validity domain"):
        refine_images([rpc], control=far)


def test_torch_is_imported_only_when_an_adjustment_runs():
    import subprocess
    import sys

    code = ("import sys, explorer, explorer.refine.adjust, explorer.refine.bundle, explorer.commands.refine; "
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
