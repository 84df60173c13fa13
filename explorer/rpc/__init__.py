"""Rational function models (RPC00B): evaluation, readers and fitting.

Pixel convention: 0-based rows/columns, integer = pixel centre (see ``docs/conventions.md``
and ``docs/rpc.md``).
"""

from explorer.rpc._kernels import project as project_compiled
from explorer.rpc.model import (
    ConvergenceError,
    InverseRFM,
    RationalFunctionModel,
    ValidityDomain,
)
from explorer.rpc.readers import (
    RPCFormatError,
    detect_format,
    read_dg_rpb,
    read_dg_xml,
    read_dimap_v1,
    read_dimap_v2,
    read_gdal_vrt,
    read_ossim_geom,
    read_rpc,
    read_rpc00b_text,
    read_rpc_from_raster,
)

__all__ = [
    "ConvergenceError",
    "InverseRFM",
    "RPCFormatError",
    "RationalFunctionModel",
    "ValidityDomain",
    "detect_format",
    "project_compiled",
    "read_dg_rpb",
    "read_dg_xml",
    "read_dimap_v1",
    "read_dimap_v2",
    "read_gdal_vrt",
    "read_ossim_geom",
    "read_rpc",
    "read_rpc00b_text",
    "read_rpc_from_raster",
]
