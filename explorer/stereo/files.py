"""One image geometry file -> the :class:`explorer.sensor.Sensor` the stereo functions take (the model itself,
never a fitted stand-in): :func:`load_sensor`.

========  ===============================================================================================
kind      sensor
========  ===============================================================================================
rpc       :class:`explorer.rpc.sensor.RPCSensor` over :func:`explorer.read_rpc` (any RPC format)
scene     a scene JSON (:func:`explorer.real.linescan.load_scene`: MPC or rigorous line-scan)
dimap     the rigorous Pleiades/SPOT DIMAP model (:func:`explorer.real.dimap.rigorous_scene_from_dimap`)
dg        the rigorous DigitalGlobe model (:func:`explorer.real.worldview.rigorous_scene_from_dg`)
isd       the USGS CSM line-scan camera of an ALE ISD (:func:`explorer.real.csm_sensor.csm_scene`)
auto      ``.json``: an ISD when it holds ``instrument_pointing``, else a scene; anything else: an RPC
========  ===============================================================================================
"""

from __future__ import annotations

from pathlib import Path

from explorer.errors import InputError
from explorer.sensor import Sensor

SENSOR_KINDS = ("auto", "rpc", "scene", "dimap", "dg", "isd")


def json_kind(path: str | Path) -> str:
    """"isd" for an ALE ISD (it holds ``instrument_pointing``), else "scene" (a JSON file)."""
    from explorer.io_input import load_json_file

    data = load_json_file(path, "JSON file")
    return "isd" if isinstance(data, dict) and "instrument_pointing" in data else "scene"


def load_sensor(path: str | Path, kind: str = "auto") -> Sensor:
    """The sensor of one image geometry file (see the module table).

    Raises
    ------
    InputError
        An unknown kind; the readers raise their own errors naming the file and field.
    """
    if kind not in SENSOR_KINDS:
        raise InputError(f"unknown sensor kind {kind!r}; one of {', '.join(SENSOR_KINDS)}")
    path = Path(path)
    if kind == "auto":
        kind = json_kind(path) if path.suffix.lower() == ".json" else "rpc"
    if kind == "rpc":
        from explorer.rpc import read_rpc
        from explorer.rpc.sensor import RPCSensor

        return RPCSensor(read_rpc(path), name=path.name)
    if kind == "scene":
        from explorer.real.linescan import load_scene

        return load_scene(path)
    if kind == "dimap":
        from explorer.real.dimap import rigorous_scene_from_dimap

        return rigorous_scene_from_dimap(path)[0]
    if kind == "dg":
        from explorer.real.worldview import rigorous_scene_from_dg

        return rigorous_scene_from_dg(path)
    from explorer.real.csm_camera import read_isd
    from explorer.real.csm_sensor import csm_scene

    return csm_scene(read_isd(path))


__all__ = ["SENSOR_KINDS", "json_kind", "load_sensor"]
