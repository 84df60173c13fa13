"""Writers of RPC files: a :class:`~explorer.rpc.model.RationalFunctionModel` as RPC00B key/value text.

The text is the ``_RPC.TXT`` layout that GDAL, rpcm and :func:`explorer.rpc.readers.read_rpc00b_text`
read (``LINE_OFF: ...``, ``LINE_NUM_COEFF_1`` .. ``SAMP_DEN_COEFF_20``), 0-based pixel-centre offsets
(the RPC00B convention and the package's, ``docs/conventions.md``).  Every number is written with 17
significant digits, so reading the file back gives the same model bit for bit.  The image-to-ground
functions of a DIMAP file and the image size are not part of RPC00B and are not written.
"""

from __future__ import annotations

import os
from pathlib import Path

from explorer.io_atomic import write_text_atomic
from explorer.rpc.model import RationalFunctionModel

__all__ = ["rpc00b_text", "write_rpc00b_text"]

_UNITS = {"OFF": {"LINE": "pixels", "SAMP": "pixels", "LAT": "degrees", "LONG": "degrees", "HEIGHT": "meters"}}


def rpc00b_text(model: RationalFunctionModel) -> str:
    """The model as RPC00B key/value text (one ``KEY: value`` per line, 17 significant digits)."""
    lines = []
    scalars = (
        ("LINE", model.row_offset, model.row_scale), ("SAMP", model.col_offset, model.col_scale),
        ("LAT", model.lat_offset, model.lat_scale), ("LONG", model.lon_offset, model.lon_scale),
        ("HEIGHT", model.height_offset, model.height_scale),
    )  # fmt: skip
    for key, offset, _ in scalars:
        lines.append(f"{key}_OFF: {offset:+.17g} {_UNITS['OFF'][key]}")
    for key, _, scale in scalars:
        lines.append(f"{key}_SCALE: {scale:+.17g} {_UNITS['OFF'][key]}")
    for key, coefficients in (("LINE_NUM_COEFF", model.row_num), ("LINE_DEN_COEFF", model.row_den),
                              ("SAMP_NUM_COEFF", model.col_num), ("SAMP_DEN_COEFF", model.col_den)):
        lines.extend(f"{key}_{k + 1}: {float(c):+.17e}" for k, c in enumerate(coefficients))
    return "\n".join(lines) + "\n"


def write_rpc00b_text(model: RationalFunctionModel, path: str | os.PathLike[str]) -> Path:
    """Write the model as an RPC00B text file (atomically) and return its path; see :func:`rpc00b_text`."""
    return write_text_atomic(path, rpc00b_text(model))
