"""residuals.csv text (explorer.app.export.residuals_csv) against a column-wise formatting of the same numbers
(numpy's ``%.17g`` per element, the format the export documents): the same bytes, non-finite numbers as empty
fields, and every number read back exactly."""

import csv
import io
from types import SimpleNamespace

import numpy as np

from explorer.app.export import CSV_COLUMNS, NATIVE_PIXEL_COLUMNS, residuals_csv
from explorer.app.model import STATUS_NAMES


def _column_wise(evaluations, status, scps, xyz, native):
    def num(a):
        a = np.asarray(a, dtype=np.float64)
        return np.where(np.isfinite(a), np.char.mod("%.17g", a), "")

    lines = [",".join(CSV_COLUMNS + (NATIVE_PIXEL_COLUMNS if native else ()))]
    for name, ev in evaluations.items():
        idx = ev.evaluated_index
        cols = [np.full(idx.size, name), idx.astype(str), num(scps.row[idx]), num(scps.col[idx]),
                num(ev.residual_row), num(ev.residual_col), np.array(STATUS_NAMES)[status[name]],
                num(xyz[idx, 0]), num(xyz[idx, 1]), num(xyz[idx, 2])]
        if native:
            cols += [num(scps.row[idx] + 0.5), num(scps.col[idx] + 0.5)]
        lines.extend(",".join(str(c[i]) for c in cols) for i in range(idx.size))
    return ("\n".join(lines) + "\n").encode()


def test_csv_bytes_and_exact_round_trip():
    rng = np.random.default_rng(0)
    n = 500
    scps = SimpleNamespace(row=rng.uniform(0, 4e4, n), col=rng.uniform(0, 4e4, n))
    xyz = rng.normal(0, 6.4e6, (n, 3))
    evs, status = {}, {}
    for k, name in enumerate(["lrm", "nr", "stand-in", "odd%name"]):
        idx = np.sort(rng.choice(n, 300 + 50 * k, replace=False))
        r = rng.normal(0, 10.0 ** rng.uniform(-12, 3, idx.size))
        c = rng.normal(0, 1e-3, idx.size)
        r[::37] = np.nan
        c[::41] = np.inf
        c[5] = -np.inf
        r[7] = 0.1  # 17 digits: 0.10000000000000001
        evs[name] = SimpleNamespace(evaluated_index=idx, residual_row=r, residual_col=c)
        status[name] = rng.integers(0, len(STATUS_NAMES), idx.size).astype(np.int8)
    for native in (False, True):
        text = residuals_csv(evs, status, scps, xyz, native_pixels=native)
        assert text == _column_wise(evs, status, scps, xyz, native)
    # non-finite shared columns (a check point's body-fixed coordinates, its row) and runs of non-finite fields
    xyz2, row2 = xyz.copy(), scps.row.copy()
    xyz2[3] = np.nan
    xyz2[11, 1:] = [np.inf, -np.inf]
    row2[4] = np.nan
    scps2 = SimpleNamespace(row=row2, col=scps.col)
    evs2 = {}
    for name, ev in evs.items():
        r, c = ev.residual_row.copy(), ev.residual_col.copy()
        r[:3], c[:3] = [np.nan, -np.inf, np.inf], np.nan
        evs2[name] = SimpleNamespace(evaluated_index=ev.evaluated_index, residual_row=r, residual_col=c)
    for native in (False, True):
        assert residuals_csv(evs2, status, scps2, xyz2, native_pixels=native) == _column_wise(evs2, status, scps2,
                                                                                              xyz2, native)
    rows = list(csv.DictReader(io.StringIO(text.decode())))
    assert len(rows) == sum(e.evaluated_index.size for e in evs.values())
    first = evs["lrm"]
    for i in range(first.evaluated_index.size):
        row = rows[i]
        want = first.residual_row[i]
        assert row["row_residual_px"] == "" if not np.isfinite(want) else float(row["row_residual_px"]) == want
        assert float(row["x_m"]) == xyz[first.evaluated_index[i], 0]
    assert ",0.10000000000000001," in text.decode()
    assert "nan" not in text.decode() and "inf" not in text.decode()


class _Points(SimpleNamespace):
    def __len__(self) -> int:
        return len(self.row)


def test_csv_awkward_numbers_single_and_empty_maps():
    """The column-interleaving writer on -0.0, 1e-17, subnormals, huge and integral values, a method with one
    point, one with none, unsorted and repeated check point indices, and no body-fixed coordinates (empty x, y, z):
    the bytes of the column-wise reference, every finite number read back exactly."""
    rng = np.random.default_rng(5)
    n = 40
    scps = _Points(row=rng.uniform(-1, 4e4, n), col=rng.uniform(0, 4e4, n))
    scps.row[:6] = [-0.0, 1e-17, 5e-324, 1.7976931348623157e308, 12345.0, -2.5e-310]
    xyz = rng.normal(0, 6.4e6, (n, 3))
    xyz[0] = [-0.0, 1e300, -1e-300]
    awkward = np.array([-0.0, 0.0, 1e-17, -1e-17, 5e-324, 1e308, -1.7976931348623157e308, 0.1, 1 / 3, 2.0 ** 60,
                        np.nan, np.inf])
    idx = np.array([5, 3, 3, 0, 39, 1, 2, 4, 6, 7, 8, 9])  # unsorted, one repeated
    evs = {"a": SimpleNamespace(evaluated_index=idx, residual_row=awkward, residual_col=awkward[::-1].copy()),
           "one": SimpleNamespace(evaluated_index=np.array([17]), residual_row=np.array([-0.0]),
                                  residual_col=np.array([1e-17])),
           "none": SimpleNamespace(evaluated_index=np.zeros(0, np.int64), residual_row=np.zeros(0),
                                   residual_col=np.zeros(0))}
    status = {"a": rng.integers(0, len(STATUS_NAMES), idx.size), "one": np.array([2]), "none": np.zeros(0, np.int64)}
    for native in (False, True):
        assert residuals_csv(evs, status, scps, xyz, native_pixels=native) == _column_wise(evs, status, scps, xyz,
                                                                                           native)
    nan_xyz = np.full((n, 3), np.nan)
    text = residuals_csv(evs, status, scps, None)
    assert text == _column_wise(evs, status, scps, nan_xyz, False)
    rows = list(csv.DictReader(io.StringIO(text.decode())))
    assert [r["method"] for r in rows] == ["a"] * idx.size + ["one"]
    for r, i, v in zip(rows, idx, awkward, strict=False):
        assert int(r["scp_index"]) == i and r["x_m"] == ""
        assert (r["row_residual_px"] == "") if not np.isfinite(v) else (float(r["row_residual_px"]) == v)
        assert float(r["row_px"]) == scps.row[i]
    assert rows[0]["row_residual_px"] == "-0" and rows[-1]["col_residual_px"] == "1.0000000000000001e-17"
    assert residuals_csv({}, {}, scps, xyz) == (",".join(CSV_COLUMNS) + "\n").encode()
