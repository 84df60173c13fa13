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
