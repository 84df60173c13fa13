"""RPC00B text writer: reading the written file gives the same model bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from explorer.rpc import read_rpc
from explorer.rpc.writers import write_rpc00b_text
from tests.rpc.conftest import RPC_DIR

FIELDS = ("row_offset", "col_offset", "lat_offset", "lon_offset", "height_offset",
          "row_scale", "col_scale", "lat_scale", "lon_scale", "height_scale")


@pytest.mark.parametrize("name", ["RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML", "rpc_WV2.xml",
                                  "PHRDIMAP_P1BP--2017030824934340CP.XML", "rpc_PLANET_L1B.txt"])
def test_round_trip_is_exact(name, tmp_path):
    model = read_rpc(RPC_DIR / name)
    back = read_rpc(write_rpc00b_text(model, tmp_path / "rpc.txt"))
    assert back.source_format == "rpc00b_txt"
    for key in ("row_num", "row_den", "col_num", "col_den"):
        assert np.array_equal(getattr(model, key), getattr(back, key))
    for key in FIELDS:
        assert getattr(model, key) == getattr(back, key), key
