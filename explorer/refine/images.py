"""The images a refinement adjusts: one adapter per sensor kind (RPC, MPC scene, line scanner), one interface.

Each adapter knows its image size, its correction models, the differentiable projector of
:mod:`explorer.refine.bundle`, how to localise a tie point for a start, how to project ground points
before and after the adjustment (the compiled paths), and how to write the adjusted model:

- :class:`RPCImage` -- image-space corrections (:mod:`explorer.refine.corrections`), the adjusted RPC
  folded and written as RPC00B text (:mod:`explorer.refine.fold`);
- :class:`SceneImage` -- corrections of the MPC polynomial coefficients (:mod:`explorer.refine.torch_scene`),
  the adjusted scene written as a scene JSON sidecar (``Scene.save``; ``pushbroom scene`` reads it);
- :class:`LineScanImage` -- rigorous DIMAP/DG models and CSM cameras: position / attitude offsets, drifts and
  jitter harmonics of their tables (:mod:`explorer.refine.line_corrections`), the adjusted model a JSON sidecar
  (:func:`explorer.refine.line_adjust.load_adjusted` reads it back).

Ground coordinates are geodetic (degrees, metres) on the sensor's body; an MPC scene converts them with
its frame.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from explorer.errors import InputError
from explorer.refine.corrections import CORRECTION_PARAMETERS, apply_correction
from explorer.rpc.model import RationalFunctionModel
from explorer.scene import Scene

__all__ = ["LineScanImage", "RPCImage", "SceneImage", "image_adapter"]

WGS84_AXES = (6378137.0, 6356752.314245179)


class RPCImage:
    """An RPC (:class:`~explorer.rpc.model.RationalFunctionModel`) being refined."""

    kind = "rpc"
    what = "RPC"
    models = tuple(CORRECTION_PARAMETERS)

    def __init__(self, rpc: RationalFunctionModel) -> None:
        self.sensor = rpc
        self.fold: Any = None

    @property
    def axes(self) -> tuple[float, float]:
        return WGS84_AXES

    @property
    def size(self) -> tuple[int, int]:
        """(rows, columns): the file's image size, else ``2 * offset + 1`` (as RPCSensor)."""
        rpc = self.sensor
        if rpc.image_size is not None:
            return int(rpc.image_size[0]), int(rpc.image_size[1])
        return int(round(2 * rpc.row_offset + 1)), int(round(2 * rpc.col_offset + 1))

    def ground_ok(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> np.ndarray:
        return self.sensor.ground_validity(lon, lat, h)

    def localise(self, row: np.ndarray, col: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(lon, lat, h, ok) of image points at the RPC's height offset."""
        h = np.full(row.shape, self.sensor.height_offset)
        lon, lat, ok = self.sensor.localization(row, col, h)[:3]
        return lon, lat, h, ok

    def projector(self, model: str) -> Any:
        from explorer.refine.torch_rpc import TorchRPC

        return TorchRPC(self.sensor, model)

    def project(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray, model: str,
                params: np.ndarray | None) -> np.ndarray:
        """(N, 2) pixels of the model (``params`` None) or of the corrected model (compiled path)."""
        row, col = self.sensor.projection(lon, lat, h)
        if params is not None:
            row, col = apply_correction(model, params, row, col)
        return np.stack([row, col], axis=1)

    def adjust(self, model: str, params: np.ndarray) -> dict[str, Any]:
        """Fold the correction in; returns the report entry (file name, folding residual)."""
        from explorer.refine.fold import fold_correction

        self.fold = fold_correction(self.sensor, model, params)
        return {"fold_max_residual_px": self.fold.max_residual_px, "fold_rms_residual_px": self.fold.rms_residual_px}

    def write(self, path: Path) -> Path:
        from explorer.rpc.writers import write_rpc00b_text

        return write_rpc00b_text(self.fold.rpc, path)

    suffix = ".txt"
    stem = "adjusted_rpc"


class _SensorBackedImage:
    """What an image refined through a sensor with a local frame (an MPC scene, a rigorous model, a CSM camera)
    shares: the body's axes, the image size, and localisation on the sensor's own terrain."""

    sensor: Any

    def project(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray, model: str,
                params: np.ndarray | None) -> np.ndarray:
        raise NotImplementedError

    @property
    def axes(self) -> tuple[float, float]:
        body = self.sensor.frame.body
        return float(body.a_m), float(body.b_m)

    @property
    def size(self) -> tuple[int, int]:
        return int(self.sensor.n_rows), int(self.sensor.n_columns)

    def ground_ok(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> np.ndarray:
        return np.isfinite(self.project(lon, lat, h, "attitude", None)).all(axis=1)

    def localise(self, row: np.ndarray, col: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(lon, lat, h, ok) of image points on the sensor's own terrain."""
        ground = self.sensor.image_to_ground(row, col)
        ok = np.isfinite(ground).all(axis=1)
        lon, lat, h = self.sensor.frame.enu_to_geodetic(np.where(ok[:, None], ground, 0.0))
        return lon, lat, h, ok


class SceneImage(_SensorBackedImage):
    """An MPC scene (:class:`~explorer.scene.Scene`) being refined by its exterior orientation."""

    kind = "scene"
    what = "scene"
    suffix = ".json"
    stem = "adjusted_scene"

    def __init__(self, scene: Scene) -> None:
        from explorer.refine.torch_scene import SCENE_MODELS

        self.sensor = scene
        self.models = tuple(SCENE_MODELS)
        self.adjusted: Scene | None = None

    def projector(self, model: str) -> Any:
        from explorer.refine.torch_scene import TorchScene

        return TorchScene(self.sensor, model)

    def project(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray, model: str,
                params: np.ndarray | None) -> np.ndarray:
        from explorer.refine.torch_scene import adjusted_scene

        scene = self.sensor if params is None else adjusted_scene(self.sensor, model, params)
        row, col = scene.geodetic_to_image(lon, lat, h)  # the Sensor's geodetic entry (same frame)
        return np.stack([row, col], axis=1)

    def adjusted_sensor(self, model: str, params: np.ndarray) -> Scene:
        """The scene with corrected coefficients (its trajectory: :mod:`explorer.refine.trajectory`)."""
        from explorer.refine.torch_scene import adjusted_scene

        return adjusted_scene(self.sensor, model, params)

    def adjust(self, model: str, params: np.ndarray) -> dict[str, Any]:
        self.adjusted = self.adjusted_sensor(model, params)
        return {}

    def write(self, path: Path) -> Path:
        assert self.adjusted is not None
        self.adjusted.save(path)
        return path


class LineScanImage(_SensorBackedImage):
    """A rigorous DIMAP/DG model or a USGS CSM camera refined by corrections of its position and attitude tables
    (:mod:`explorer.refine.line_corrections`); the adjusted model is written as a JSON sidecar
    (:func:`explorer.refine.line_adjust.sidecar_dict`: parameters, sigmas, the base file's name and SHA-256)."""

    kind = "linescan"
    suffix = ".json"
    stem = "adjusted_model"

    def __init__(self, sensor: Any, *, base_file: str | None = None, source_kind: str | None = None,
                 jitter_hz: tuple[float, ...] | None = None) -> None:
        from explorer.refine.line_corrections import LINE_MODELS

        self.sensor = sensor
        self.models = tuple(LINE_MODELS)
        self.what = "CSM camera" if _is_csm(sensor) else "rigorous line-scan model"
        self.base_file = base_file
        self.source_kind = source_kind or ("isd" if _is_csm(sensor) else "dimap")
        self.jitter_hz = tuple(jitter_hz) if jitter_hz else None
        self._corrections: dict[str, Any] = {}
        self.sidecar: dict[str, Any] | None = None
        self.adjusted: Any = None

    def correction(self, model: str) -> Any:
        from explorer.refine.line_adjust import correction_for

        if model not in self._corrections:
            self._corrections[model] = correction_for(self.sensor, model, self.jitter_hz)
        return self._corrections[model]

    def projector(self, model: str) -> Any:
        from explorer.refine.torch_linescan import line_projector

        return line_projector(self.sensor, self.correction(model))

    def project(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray, model: str,
                params: np.ndarray | None) -> np.ndarray:
        """(N, 2) pixels of the sensor (``params`` None) or of the adjusted sensor (its compiled path)."""
        from explorer.refine.line_adjust import adjusted_sensor

        sensor = self.sensor if params is None else adjusted_sensor(self.sensor, self.correction(model), params)
        row, col = sensor.geodetic_to_image(lon, lat, h)  # the Sensor's geodetic entry (same class and frame)
        return np.stack([row, col], axis=1)

    def adjust(self, model: str, params: np.ndarray, sigmas: np.ndarray | None = None) -> dict[str, Any]:
        from explorer.refine.line_adjust import adjusted_sensor, sidecar_dict

        corr = self.correction(model)
        self.adjusted = adjusted_sensor(self.sensor, corr, params)
        self.sidecar = sidecar_dict(corr, params, sigmas, base_file=self.base_file, source_kind=self.source_kind)
        out: dict[str, Any] = {"correction": corr.to_dict()}
        if corr.frequencies_hz:
            out["harmonics"] = corr.harmonics(np.asarray(params, dtype=np.float64))
        return out

    def write(self, path: Path) -> Path:
        from explorer.refine.line_adjust import write_sidecar

        assert self.sidecar is not None
        return write_sidecar(path, self.sidecar)


def _is_csm(sensor: Any) -> bool:
    from explorer.real.csm_sensor import CsmScene

    return isinstance(sensor, CsmScene)


def image_adapter(sensor: Any, **options: Any) -> RPCImage | SceneImage | LineScanImage:
    """The adapter of an RPC model, an MPC scene, a rigorous DIMAP/DG model or a CSM camera (``options``: the
    :class:`LineScanImage` keywords); InputError for anything else."""
    if isinstance(sensor, RationalFunctionModel):
        return RPCImage(sensor)
    if isinstance(sensor, Scene):
        from explorer.refine.line_adjust import is_line_scanner
        from explorer.sensor import has_polynomial_exterior

        if is_line_scanner(sensor):
            return LineScanImage(sensor, **options)
        if not has_polynomial_exterior(sensor):
            raise InputError(f"cannot refine a {type(sensor).__name__}: its exterior is neither MPC polynomials nor "
                             "the tables of a rigorous DIMAP/DG model or a CSM camera")
        return SceneImage(sensor)
    raise InputError(f"cannot refine a {type(sensor).__name__}: an RPC model, an MPC scene, a rigorous DIMAP/DG "
                     "model or a CSM camera is needed")
