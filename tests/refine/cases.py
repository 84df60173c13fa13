"""Simulated control, check and tie points on real RPCs (seeded; the truth is the biased model itself)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from explorer.refine.adjust import image_size
from explorer.refine.corrections import apply_correction
from explorer.refine.points_io import PointTable
from explorer.rpc import RationalFunctionModel, read_rpc

RPC_DIR = Path(__file__).resolve().parents[1] / "data" / "rpc"
#: Pleiades 1A, 2017-03-08 (CNES shareloc test data, see tests/data/rpc/PROVENANCE.md)
PLEIADES = RPC_DIR / "PHRDIMAP_P1BP--2017030824934340CP.XML"
#: The Pleiades 1B stereo pair of 2017-09-28 (shareloc)
PAIR = (RPC_DIR / "RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML",
        RPC_DIR / "RPC_PHR1B_P_201709281038393_SEN_PRG_FC_178609-001.XML")
#: Several px of shift, 1e-4 of scale and of rotation (row_per_col = -col_per_row)
TRUE_AFFINE = np.array([4.2, 1.0e-4, -1.0e-4, -3.1, 1.0e-4, 1.0e-4])


def pleiades() -> RationalFunctionModel:
    return read_rpc(PLEIADES)


def random_ground(rpc: RationalFunctionModel, n: int, rng: np.random.Generator, margin: float = 0.02) -> np.ndarray:
    """(n, 3) lon, lat, h of ground points seen inside the image (localised from random pixels)."""
    rows, cols = image_size(rpc)
    r = rng.uniform(margin * rows, (1 - margin) * rows, n)
    c = rng.uniform(margin * cols, (1 - margin) * cols, n)
    h = rng.uniform(*rpc.height_range(0.5), n)
    lon, lat, ok = rpc.localization(r, c, h)[:3]
    assert ok.all()
    return np.stack([lon, lat, h], axis=1)


def measure(rpc: RationalFunctionModel, ground: np.ndarray, model: str, params: np.ndarray, noise_px: float,
            rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Biased (model + correction) projection of ``ground`` plus Gaussian noise (per coordinate)."""
    row, col = rpc.projection(ground[:, 0], ground[:, 1], ground[:, 2])
    row, col = apply_correction(model, params, row, col)
    return row + rng.normal(0.0, noise_px, row.size), col + rng.normal(0.0, noise_px, col.size)


def simulate_points(rpc: RationalFunctionModel, n: int, *, model: str = "affine", params: np.ndarray = TRUE_AFFINE,
                    noise_px: float = 0.3, seed: int = 0, prefix: str = "p") -> PointTable:
    """``n`` control/check points: ground, and the biased model's pixels with ``noise_px`` noise."""
    rng = np.random.default_rng(seed)
    g = random_ground(rpc, n, rng)
    row, col = measure(rpc, g, model, params, noise_px, rng)
    return PointTable([f"{prefix}{i}" for i in range(n)], row, col, g[:, 0], g[:, 1], g[:, 2])


def write_points_csv(path: Path, table: PointTable, image: list[str] | None = None) -> Path:
    lines = ["id,lon,lat,h,row,col" + (",image" if image else "")]
    for i, pid in enumerate(table.ids):
        assert table.lon is not None and table.lat is not None and table.h is not None
        line = f"{pid},{table.lon[i]:.12f},{table.lat[i]:.12f},{table.h[i]:.6f},{table.row[i]:.6f},{table.col[i]:.6f}"
        lines.append(line + (f",{image[i]}" if image else ""))
    path.write_text("\n".join(lines) + "\n")
    return path


#: Biases of the two images of the pair (different in each: shift, scale, rotation, shear)
TRUE_PAIR = (np.array([3.0, 1.0e-4, -1.0e-4, -2.0, 1.0e-4, 1.0e-4]),
             np.array([-2.5, -5.0e-5, 8.0e-5, 4.0, -8.0e-5, 5.0e-5]))


def simulate_pair_points(rpcs: list[RationalFunctionModel], n: int, *, ground_known: bool, prefix: str,
                         rng: np.random.Generator, params=TRUE_PAIR, noise_px: float = 0.3) -> PointTable:
    """Points seen in both images of a pair: one row per image (``image`` 0 / 1), biased pixels + noise."""
    g = random_ground(rpcs[0], n, rng, margin=0.05)
    ids, rows, cols, image = [], [], [], []
    for k, rpc in enumerate(rpcs):
        r, c = measure(rpc, g, "affine", params[k], noise_px, rng)
        ids += [f"{prefix}{i}" for i in range(n)]
        rows.append(r)
        cols.append(c)
        image += [str(k)] * n
    gg = np.concatenate([g, g])
    return PointTable(ids, np.concatenate(rows), np.concatenate(cols), gg[:, 0] if ground_known else None,
                      gg[:, 1] if ground_known else None, gg[:, 2] if ground_known else None, image=image)
