"""RationalFunctionModel.validate (issue 25 class 5): what a physical RPC is (docs/validation.md).

Truth: the rule itself, on a real file (rpcm's Pleiades RPC) changed in one place -- a denominator with its root
just past the normalised cube, a numerator that ignores the ground position, a scale of the wrong sign.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from explorer.errors import InputError
from explorer.rpc import read_rpc

PLEIADES = Path(__file__).resolve().parents[1] / "data" / "rpc" / "rpc_PLEIADES.xml"


def test_a_denominator_vanishing_inside_the_declared_validity_box_is_refused():
    model = read_rpc(PLEIADES)
    lon_max = (model.validity.lon_max - model.lon_offset) / model.lon_scale  # 1.04: the box reaches past the cube
    assert 1.0 < lon_max < 1.1
    den = np.zeros(20)
    den[0], den[1] = 1.0, -1.0 / (0.5 * (1.0 + lon_max))  # root at L = 1.02: outside the cube, inside the box
    with pytest.raises(InputError, match="LINE_DEN_COEFF .* vanishes inside the validity domain"):
        replace(model, row_den=den).validate()
    replace(model, row_den=den, validity=None).validate()  # without the box, the cube alone: accepted


def test_a_ground_to_image_map_that_ignores_the_ground_is_refused():
    model = read_rpc(PLEIADES)
    height_only = np.zeros(20)
    height_only[3] = 1.0  # row = H: the same row for every ground position
    with pytest.raises(InputError, match="degenerate"):
        replace(model, row_num=height_only).validate()
    swapped = replace(model, row_num=model.col_num, col_num=model.row_num)  # a valid map, mirrored: accepted
    swapped.validate()


@pytest.mark.parametrize(("field", "value", "words"), [
    ("row_scale", -5000.0, "LINE_SCALE"), ("col_scale", 0.1, "SAMP_SCALE"), ("height_scale", -80.0, "HEIGHT_SCALE"),
    ("lat_scale", 1e-12, "LAT_SCALE"), ("lon_scale", -3e-9, "LONG_SCALE"),
])
def test_scales_of_no_physical_image_are_refused(field, value, words):
    with pytest.raises(InputError, match=words):
        replace(read_rpc(PLEIADES), **{field: value}).validate()


def test_a_negative_latitude_scale_as_planetscope_writes_it_is_read():
    model = read_rpc(PLEIADES.parent / "rpc_PLANET_L1B.txt")
    assert model.lat_scale < 0
