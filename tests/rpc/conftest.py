"""Shared helpers for the RPC tests (data under tests/data/rpc, see its PROVENANCE.md)."""

from pathlib import Path

import numpy as np
import pytest

RPC_DIR = Path(__file__).resolve().parents[1] / "data" / "rpc"

#: Every file in tests/data/rpc that rpcm 1.4 reads with rpc_from_rpc_file.
RPCM_READABLE = [
    "RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML",
    "RPC_PHR1B_P_201709281038393_SEN_PRG_FC_178609-001.XML",
    "md_ge_rgb_0010000_rpc.txt",
    "md_ov_rpc.txt",
    "test_rpc.txt",
    "rpc_IKONOS.txt",
    "rpc_PLANET_L1A.txt",
    "rpc_PLANET_L1B.txt",
    "rpc_PLEIADES.xml",
    "rpc_SPOT6.xml",
    "rpc_WV1.xml",
    "rpc_WV2.xml",
]


def normalisation_grid(model, n_lon=9, n_lat=9, n_h=5):
    """3-D grid over offset +- scale in lon, lat and height (ij indexing)."""
    axes = [
        np.linspace(
            model.lon_offset - abs(model.lon_scale), model.lon_offset + abs(model.lon_scale), n_lon
        ),
        np.linspace(
            model.lat_offset - abs(model.lat_scale), model.lat_offset + abs(model.lat_scale), n_lat
        ),
        np.linspace(
            model.height_offset - abs(model.height_scale),
            model.height_offset + abs(model.height_scale),
            n_h,
        ),
    ]
    return np.meshgrid(*axes, indexing="ij")


@pytest.fixture
def rpc_dir() -> Path:
    return RPC_DIR
