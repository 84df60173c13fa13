"""Refine image models to control, check and tie points: the adjustment, its report and its files.

:func:`refine_images` adjusts a correction of one or several images' models (an image-space correction
of RPCs, :mod:`explorer.refine.corrections`; the exterior orientation of MPC scenes,
:mod:`explorer.refine.torch_scene`) to control points (ground known to ``sigma_ground_m``, or fixed)
and tie points (ground unknown) by :func:`explorer.refine.bundle.bundle_adjust`, and returns a :class:`Refinement`:

- residuals ``measured - model`` of every observation before and after, its role (``control``,
  ``check``, ``tie``) and outlier flag;
- the parameters with their a posteriori sigmas and correlations, ``sigma0``;
- RMSEs per image coordinate, ``sqrt(mean((d_row^2 + d_col^2) / 2))`` over the points that are not
  outliers, in pixels (the noise of one coordinate when the model fits);
- the adjusted models (:mod:`explorer.refine.images`): RPCs with the correction folded in
  (:func:`explorer.refine.fold.fold_correction`), scenes with corrected coefficients (a JSON sidecar).

Check points are kept apart from control: with one image they take no part in the adjustment and are
projected by the adjusted model; with several images, a check point measured in two images or more
enters as a tie point (its pixels help, its ground coordinates do not), and its triangulated ground
position is compared with the surveyed one against the propagated sigma of the adjustment
(``report["check_ground"]``).  The check RMSE in pixels is always that of the surveyed ground projected
by the adjusted model (a tie point's own residuals would hide a ground error).

:meth:`Refinement.write` writes ``report.json``, ``points.csv``, ``parameters.csv`` and the adjusted RPC
files (RPC00B text) into a folder.
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from explorer.errors import InputError
from explorer.refine.bundle import BundleProblem, BundleResult, bundle_adjust, metres_per_degree
from explorer.refine.images import LineScanImage, RPCImage, SceneImage, image_adapter
from explorer.refine.line_adjust import is_line_scanner
from explorer.refine.points_io import PointTable

__all__ = ["DEFAULT_MODELS", "Refinement", "image_size", "refine_images"]

#: RMSE definition written into every report.
RMSE_DEFINITION = "per image coordinate: sqrt(mean((d_row^2 + d_col^2) / 2)) over non-outlier points, pixels"


def image_size(sensor: Any) -> tuple[int, int]:
    """(rows, columns) of an RPC's image (the file's size, else ``2 * offset + 1``) or of a scene."""
    return image_adapter(sensor).size


def _rmse(d: np.ndarray) -> float | None:
    return float(np.sqrt(np.mean(d * d))) if d.size else None


@dataclass
class Refinement:
    """Result of :func:`refine_images`; :meth:`report` and :meth:`write` give it to other tools."""

    model: str
    models: list[str]
    image_names: list[str]
    images: list[RPCImage | SceneImage | LineScanImage]
    parameter_names: list[str]
    result: BundleResult
    observations: dict[str, Any]
    adjusted: list[dict[str, Any]]
    settings: dict[str, Any]
    check_residuals_before: np.ndarray
    check_residuals_after: np.ndarray
    check_ground: dict[str, Any] | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def parameters(self) -> np.ndarray:
        """Stacked adjusted parameters (P,)."""
        return np.concatenate(self.result.parameters)

    def _role_mask(self, role: str) -> np.ndarray:
        return np.asarray(self.observations["role"]) == role

    @property
    def control_rmse_px(self) -> float | None:
        m = self._role_mask("control") & ~self.result.outlier
        return _rmse(self.result.residuals_after[m])

    @property
    def check_rmse_px(self) -> float | None:
        """Check points' RMSE after the adjustment (see the module docstring), pixels; None without them."""
        return _rmse(self.check_residuals_after) if self.check_residuals_after.size else None

    def parameter_table(self) -> list[dict[str, Any]]:
        sigma = self.result.parameter_sigma
        owner = np.repeat(np.arange(len(self.images)), [p.size for p in self.result.parameters])
        return [{"name": name, "value": float(v), "sigma": float(s), "image": self.image_names[int(owner[k])]}
                for k, (name, v, s) in enumerate(zip(self.parameter_names, self.parameters, sigma, strict=True))]

    def report(self) -> dict[str, Any]:
        """The report (``report.json``): the issue's keys ``model``, ``sigma0``, ``control_rmse_px``,
        ``check_rmse_px``, ``parameters`` [{name, value, sigma}] and the details."""
        res = self.result
        control = self._role_mask("control")
        out = {
            "model": self.model,
            "sigma0": res.sigma0,
            "control_rmse_px": self.control_rmse_px,
            "check_rmse_px": self.check_rmse_px,
            "parameters": self.parameter_table(),
            "control_rmse_px_before": _rmse(res.residuals_before[control & ~res.outlier]),
            "check_rmse_px_before": _rmse(self.check_residuals_before) if self.check_residuals_before.size else None,
            "tie_rmse_px": _rmse(res.residuals_after[self._role_mask("tie") & ~res.outlier]),
            "rmse_definition": RMSE_DEFINITION,
            "correlation": np.round(res.parameter_correlation, 6).tolist(),
            "redundancy": res.redundancy,
            "iterations": res.iterations,
            "n_observations": int(res.outlier.size),
            "n_outliers": int(res.outlier.sum()),
            "images": [{"name": n, "kind": im.kind, "model": m, "rows": im.size[0], "columns": im.size[1],
                        "adjusted_model": im.stem + (f"_{k}" if len(self.images) > 1 else "") + im.suffix, **f}
                       for k, (n, im, m, f) in enumerate(zip(self.image_names, self.images, self.models, self.adjusted,
                                                             strict=True))],
            "settings": self.settings,
        }
        if self.check_ground is not None:
            out["check_ground"] = self.check_ground
        return out

    def points_rows(self) -> list[dict[str, Any]]:
        """One row per measured point: id, role, image, row, col, residuals before/after, outlier."""
        rows = []
        obs = self.observations
        res = self.result
        for i in range(res.outlier.size):
            if obs["role"][i] == "check":
                continue  # listed below, with residuals from the surveyed ground
            before, after = res.residuals_before[i], res.residuals_after[i]
            rows.append({"id": obs["id"][i], "role": obs["role"][i], "image": self.image_names[obs["image"][i]],
                         "row": obs["row"][i], "col": obs["col"][i],
                         "residual_row_before": before[0], "residual_col_before": before[1],
                         "residual_row_after": after[0], "residual_col_after": after[1],
                         "outlier": int(res.outlier[i])})
        ck = self.extra.get("check_only")
        if ck is not None:
            before, after = self.extra["check_residuals"]
            for i in range(len(ck["id"])):
                rows.append({"id": ck["id"][i], "role": "check", "image": self.image_names[ck["image"][i]],
                             "row": ck["row"][i], "col": ck["col"][i],
                             "residual_row_before": before[i, 0], "residual_col_before": before[i, 1],
                             "residual_row_after": after[i, 0], "residual_col_after": after[i, 1],
                             "outlier": ck["outlier"][i]})
        return rows

    def write(self, out_dir: str | os.PathLike[str]) -> list[Path]:
        """Write ``report.json``, ``points.csv``, ``parameters.csv`` and the adjusted models into ``out_dir``
        (RPC00B text ``adjusted_rpc[_K].txt`` for RPCs, scene JSON ``adjusted_scene[_K].json`` for scenes)."""
        from explorer.io_atomic import write_text_atomic

        folder = Path(out_dir)
        if folder.exists() and not folder.is_dir():
            raise InputError(f"{folder}: exists and is not a folder")
        folder.mkdir(parents=True, exist_ok=True)
        written = [write_text_atomic(folder / "report.json", json.dumps(self.report(), indent=2) + "\n")]
        for name, rows in (("points.csv", self.points_rows()), ("parameters.csv", self.parameter_table())):
            text = io.StringIO()
            writer = csv.DictWriter(text, fieldnames=list(rows[0]), lineterminator="\n")
            writer.writeheader()
            writer.writerows({k: (f"{v:.10g}" if isinstance(v, float) else v) for k, v in r.items()} for r in rows)
            written.append(write_text_atomic(folder / name, text.getvalue()))
        for entry, image in zip(self.report()["images"], self.images, strict=True):
            written.append(image.write(folder / entry["adjusted_model"]))
        return written


def _image_of(table: PointTable, names: list[str]) -> np.ndarray:
    """Image index (N,) of each row of ``table``: its ``image`` column (index or name), else image 0."""
    if table.image is None:
        if len(names) > 1:
            raise InputError(f"{table.path}: an 'image' column is needed with several images")
        return np.zeros(len(table), dtype=np.int64)
    stems = [Path(n).name for n in names]
    # one look-up per distinct value of the column (a few), then an index per row
    values, inverse = np.unique(np.asarray(table.image, dtype=str), return_inverse=True)
    index = np.empty(values.size, dtype=np.int64)
    for u, value in enumerate(values.tolist()):
        if value.isdigit() and int(value) < len(names):
            index[u] = int(value)
        elif value in names or value in stems:
            index[u] = names.index(value) if value in names else stems.index(value)
        else:
            i = int(np.flatnonzero(inverse == u)[0])
            raise InputError(f"{table.path}: line {i + 2}: image {value!r} is not one of the images "
                             f"(0..{len(names) - 1} or {', '.join(stems)})")
    return index[inverse.ravel()]


def _check_inside(table: PointTable, image: np.ndarray, images: list[RPCImage | SceneImage | LineScanImage],
                  role: str) -> None:
    """InputError for a measurement outside its image or a ground point outside the model's domain."""
    for k, adapter in enumerate(images):
        sel = np.flatnonzero(image == k)
        rows, cols = adapter.size
        bad = sel[~((table.row[sel] >= -0.5) & (table.row[sel] <= rows - 0.5)
                    & (table.col[sel] >= -0.5) & (table.col[sel] <= cols - 0.5))]
        if bad.size:
            i = int(bad[0])
            raise InputError(f"{table.path}: {role} point {table.ids[i]!r} (line {i + 2}) at row {table.row[i]:g}, "
                             f"col {table.col[i]:g} is outside the image ({rows} x {cols} pixels)")
        if table.has_ground:
            assert table.lon is not None and table.lat is not None and table.h is not None
            ok = adapter.ground_ok(table.lon[sel], table.lat[sel], table.h[sel])
            if not ok.all():
                i = int(sel[~ok][0])
                raise InputError(f"{table.path}: {role} point {table.ids[i]!r} (line {i + 2}) at lon {table.lon[i]:g}, "
                                 f"lat {table.lat[i]:g}, h {table.h[i]:g} is outside the {adapter.what}'s validity "
                                 "domain")


def _initial_ground(images: list[RPCImage | SceneImage | LineScanImage], image: np.ndarray, row: np.ndarray,
                    col: np.ndarray) -> np.ndarray:
    """Start (lon, lat, h) (N, 3) of tie points: each localised in its first image (``image``, (N,)) at the
    RPC's height offset or on the scene's terrain (vectorised per image)."""
    out = np.empty((image.size, 3))
    for k, adapter in enumerate(images):
        sel = np.flatnonzero(image == k)
        if not sel.size:
            continue
        lon, lat, h, ok = adapter.localise(row[sel], col[sel])
        if not ok.all():
            i = int(sel[~ok][0])
            raise InputError(f"a tie point at row {row[i]:g}, col {col[i]:g} does not localise in its image")
        out[sel] = np.stack([lon, lat, h], axis=1)
    return out


#: The correction model of each kind of image when none is given.
DEFAULT_MODELS = {"rpc": "affine", "scene": "attitude", "linescan": "attitude"}


def _check_one_body(images: list[RPCImage | SceneImage | LineScanImage], labels: list[str]) -> None:
    """InputError for images on different bodies (ellipsoid axes differing by more than 1 mm)."""
    a0, b0 = images[0].axes
    for k, im in enumerate(images[1:], start=1):
        a, b = im.axes
        if abs(a - a0) > 1e-3 or abs(b - b0) > 1e-3:
            raise InputError(f"images on different bodies: {labels[0]} has ellipsoid axes {a0:.3f} / {b0:.3f} m, "
                             f"{labels[k]} {a:.3f} / {b:.3f} m (tie and control points need one body)")


def _image_models(model: str | Sequence[str] | None, images: list[RPCImage | SceneImage | LineScanImage],
                  labels: list[str]) -> list[str]:
    """The correction model of each image: one for all, one per image, or each kind's default."""
    if model is None:
        return [DEFAULT_MODELS[im.kind] for im in images]
    given = [model] if isinstance(model, str) else list(model)
    if len(given) == 1:
        given = given * len(images)
    if len(given) != len(images):
        raise InputError(f"{len(given)} correction models for {len(images)} images (give one for all or one per "
                         "image)")
    for k, (m, im) in enumerate(zip(given, images, strict=True)):
        if m not in im.models:
            other = (" (attitude models need a rigorous sensor: an MPC scene, a DIMAP/DG model or a CSM camera)"
                     if im.kind == "rpc" else "")
            where = f"image {labels[k]}: " if len(images) > 1 else ""
            raise InputError(f"{where}unknown {im.what} correction model {m!r} (one of {', '.join(im.models)}){other}")
    return given


def refine_images(
    sensors: list[Any],
    *,
    model: str | Sequence[str] | None = None,
    control: PointTable | None = None,
    ties: PointTable | None = None,
    check: PointTable | None = None,
    names: list[str] | None = None,
    sigma_px: float = 0.5,
    sigma_ground_m: float = 0.0,
    loss: str = "huber",
    loss_scale: float = 1.5,
    outlier_probability: float = 0.999,
    max_iterations: int = 50,
    image_files: list[str] | None = None,
    source_kinds: list[str] | None = None,
    jitter_hz: tuple[float, ...] | None = None,
) -> Refinement:
    """Adjust a correction of each image's model to control and tie points.

    Parameters
    ----------
    sensors : list of RationalFunctionModel, Scene, RigorousLineScanScene or CsmScene
        The images (one for a resection to control points, several for a bundle adjustment), of any kinds
        mixed (RPCs, MPC scenes, rigorous DIMAP/DG models, CSM cameras), on one body.
    model : str or sequence of str, optional
        One correction model for every image, or one per image: for RPCs ``shift``, ``affine`` or ``poly2``
        (image space, :mod:`explorer.refine.corrections`); for MPC scenes ``attitude`` or ``attitude-drift``
        (exterior orientation, :mod:`explorer.refine.torch_scene`); for rigorous and CSM line scanners
        ``attitude``, ``attitude-drift``, ``position-attitude``, ``position-attitude-drift`` or ``jitter`` (their
        tables, :mod:`explorer.refine.line_corrections`).  None: :data:`DEFAULT_MODELS` of each image's kind
        (``affine`` for an RPC, ``attitude`` for a scene or a line scanner).
    control, ties, check : PointTable, optional
        Control points (``id,lon,lat,h,row,col`` [+ ``image``]), tie points (``id,image,row,col``) and
        check points (as control; never used as control).
    names : list of str, optional
        Image names (default ``image0``, ...); the ``image`` columns may use them.
    sigma_px : float
        Stated sigma of each measured image coordinate, pixels.
    sigma_ground_m : float
        Stated sigma of each control point's ground coordinates (east, north, up), metres; 0 fixes them.
    loss, loss_scale, outlier_probability, max_iterations
        As :func:`explorer.refine.bundle.bundle_adjust` (``loss_scale`` in sigmas).
    image_files, source_kinds : list of str, optional
        Line scanners: the file each image was read from and its kind (``dimap``, ``dg``, ``isd``), named
        with its SHA-256 in the adjusted model's sidecar.
    jitter_hz : tuple of float, optional
        Line scanners, ``jitter`` model: the harmonics' frequencies (default ``1/T, 2/T`` of the exposure).

    Returns
    -------
    Refinement

    Raises
    ------
    InputError
        Too few points, a point outside its image or the model's domain, an unknown image name, a
        degenerate configuration, bad sigmas, a model the sensor has not (one line naming the problem).
    """
    if not sensors:
        raise InputError("no image to refine")
    files: list[str | None] = list(image_files) if image_files else [None] * len(sensors)
    kinds: list[str | None] = list(source_kinds) if source_kinds else [None] * len(sensors)
    labels: list[str] = list(names) if names else [f"image{k}" for k in range(len(sensors))]
    if len(labels) != len(sensors):
        raise InputError(f"{len(labels)} image name(s) for {len(sensors)} image(s)")
    images: list[RPCImage | SceneImage | LineScanImage] = []
    for k, s in enumerate(sensors):
        try:
            images.append(image_adapter(s, base_file=files[k], source_kind=kinds[k], jitter_hz=jitter_hz)
                          if is_line_scanner(s) else image_adapter(s))
        except InputError as exc:
            raise InputError(f"image {labels[k]}: {exc}") from exc
    _check_one_body(images, labels)
    models = _image_models(model, images, labels)
    if not (np.isfinite(sigma_px) and sigma_px > 0):
        raise InputError(f"pixel sigma must be a finite number > 0, got {sigma_px}")
    if not (np.isfinite(sigma_ground_m) and sigma_ground_m >= 0):
        raise InputError(f"ground sigma must be a finite number >= 0, got {sigma_ground_m}")
    if control is None and ties is None:
        raise InputError("no control points and no tie points: nothing to adjust to")
    if control is not None and not control.has_ground:
        raise InputError(f"{control.path}: control points need lon, lat, h")
    if check is not None and not check.has_ground:
        raise InputError(f"{check.path}: check points need lon, lat, h")
    projectors = [im.projector(m) for im, m in zip(images, models, strict=True)]
    n_pars = [len(p.parameter_names) for p in projectors]
    multi = len(images) > 1

    # observations, ground points and their priors, built per table with array operations (no loop over points)
    ground: list[np.ndarray] = []  # (M_t, 3) per table: lon, lat, h (NaN for tie points: localised below)
    sigma_g: list[np.ndarray] = []  # (M_t,)
    parts: list[dict[str, np.ndarray]] = []
    pending: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []  # ties: (point, first image, row, col)
    check_only: dict[str, Any] = {"id": [], "image": [], "row": [], "col": [], "ground": []}
    n_points = 0

    def add(table: PointTable, role: str, as_tie: bool) -> None:
        nonlocal n_points
        image = _image_of(table, labels)
        _check_inside(table, image, images, role)
        ids = np.asarray(table.ids, dtype=str)
        uniq, first, inverse, counts = np.unique(ids, return_index=True, return_inverse=True, return_counts=True)
        inverse = inverse.ravel()
        if as_tie and (counts < 2).any():
            single = np.flatnonzero(counts < 2)
            if role == "tie":
                pid = str(uniq[single[np.argmin(first[single])]])
                raise InputError(f"{table.path}: tie point {pid!r} is measured in one image only")
            # a check point seen in one image: projected only (below)
        kept = counts >= 2 if as_tie else np.ones(uniq.size, dtype=bool)
        # ground points in the order of their first row; rows grouped by point (file order within a point)
        order = np.argsort(np.where(kept, first, np.iinfo(np.int64).max), kind="stable")[:int(kept.sum())]
        point = np.full(uniq.size, -1, dtype=np.int64)
        point[order] = n_points + np.arange(order.size)
        rows = np.flatnonzero(kept[inverse])
        rows = rows[np.argsort(point[inverse[rows]], kind="stable")]
        head = first[order]  # the first row of each point
        if as_tie:
            ground.append(np.full((order.size, 3), np.nan))
            sigma_g.append(np.full(order.size, np.inf))
            pending.append((point[order], image[head], table.row[head], table.col[head]))
        else:
            assert table.lon is not None and table.lat is not None and table.h is not None
            ground.append(np.stack([table.lon[head], table.lat[head], table.h[head]], axis=1))
            sigma_g.append(np.full(order.size, sigma_ground_m))
        parts.append({"id": ids[rows], "role": np.full(rows.size, role), "image": image[rows],
                      "row": table.row[rows], "col": table.col[rows], "point": point[inverse[rows]]})
        n_points += order.size

    if control is not None:
        add(control, "control", False)
    if ties is not None:
        add(ties, "tie", True)
    if check is not None:
        # every check measurement is projected from its surveyed ground by the adjusted model; with several
        # images, those seen in two images or more also enter the adjustment as tie points
        assert check.lon is not None and check.lat is not None and check.h is not None
        image = _image_of(check, labels)
        if multi:
            add(check, "check", True)
        else:
            _check_inside(check, image, images, "check")
        check_only.update(id=np.asarray(check.ids, dtype=str), image=image, row=check.row, col=check.col,
                          ground=np.stack([check.lon, check.lat, check.h], axis=1))
    obs: dict[str, np.ndarray] = {k: np.concatenate([p[k] for p in parts]) for k in
                                  ("id", "role", "image", "row", "col", "point")}
    all_ground = np.concatenate(ground) if ground else np.zeros((0, 3))
    if pending:
        idx, first_image, t_row, t_col = (np.concatenate(v) for v in zip(*pending, strict=True))
        all_ground[idx] = _initial_ground(images, first_image.astype(np.int64), t_row.astype(float),
                                          t_col.astype(float))
    if not obs["id"].size:
        raise InputError("no usable observation (every check point is measured in one image only)")
    n_control = int(np.sum(obs["role"] == "control"))
    if not multi and n_control * 2 <= n_pars[0]:
        raise InputError(f"too few control points: the {models[0]} model has {n_pars[0]} parameters and needs at "
                         f"least {n_pars[0] // 2 + 1} points, got {n_control}")
    problem = BundleProblem(
        projectors=projectors,
        initial_parameters=[np.zeros(n) for n in n_pars],
        ground=all_ground,
        ground_sigma_m=np.concatenate(sigma_g)[:, None],
        image_index=obs["image"],
        point_index=obs["point"],
        measured=np.stack([obs["row"], obs["col"]], axis=1),
        sigma_px=np.asarray(sigma_px, dtype=np.float64),
        axes=images[0].axes,
    )
    stacked = [n if not multi else f"{labels[k]}:{n}" for k, p in enumerate(projectors) for n in p.parameter_names]
    result = bundle_adjust(problem, loss=loss, loss_scale=loss_scale, outlier_probability=outlier_probability,
                           max_iterations=max_iterations, parameter_names=stacked)
    offs = np.concatenate([[0], np.cumsum([p.size for p in result.parameters])])
    sigma_all = result.parameter_sigma
    adjusted = [im.adjust(models[k], p, sigma_all[offs[k]:offs[k + 1]]) if isinstance(im, LineScanImage)
                else im.adjust(models[k], p) for k, (im, p) in enumerate(zip(images, result.parameters, strict=True))]

    # check points: their surveyed ground projected by the model before and after (compiled paths)
    ck_before = np.zeros((0, 2))
    ck_after = np.zeros((0, 2))
    extra: dict[str, Any] = {}
    if len(check_only["id"]):
        g = np.asarray(check_only["ground"])
        img = np.asarray(check_only["image"])
        measured = np.stack([check_only["row"], check_only["col"]], axis=1)
        before = np.empty_like(measured)
        after = np.empty_like(measured)
        for k, adapter in enumerate(images):
            sel = img == k
            before[sel] = adapter.project(g[sel, 0], g[sel, 1], g[sel, 2], models[k], None)
            after[sel] = adapter.project(g[sel, 0], g[sel, 1], g[sel, 2], models[k], result.parameters[k])
        # a check measurement that entered as a tie observation and was flagged there is flagged here too
        flagged = (obs["role"] == "check") & result.outlier
        check_only["outlier"] = np.isin(_keys(check_only["id"], check_only["image"]),
                                        _keys(obs["id"][flagged], obs["image"][flagged])).astype(int)
        keep = ~np.asarray(check_only["outlier"], dtype=bool)
        ck_before, ck_after = (measured - before)[keep], (measured - after)[keep]
        extra["check_only"] = check_only
        extra["check_residuals"] = (measured - before, measured - after)
    check_ground = _check_ground(check, obs, result, images[0].axes) if multi and check is not None else None
    settings = {"sigma_px": sigma_px, "sigma_ground_m": sigma_ground_m, "loss": loss, "loss_scale_sigma": loss_scale,
                "outlier_probability": outlier_probability,
                "outlier_threshold_sigma": float(np.sqrt(-2.0 * np.log(1.0 - outlier_probability)))}
    summary = models[0] if len(set(models)) == 1 else ",".join(models)
    return Refinement(model=summary, models=models, image_names=labels, images=images, parameter_names=stacked,
                      result=result, observations=obs, adjusted=adjusted, settings=settings,
                      check_residuals_before=ck_before, check_residuals_after=ck_after, check_ground=check_ground,
                      extra=extra)


def _keys(ids: np.ndarray, image: np.ndarray) -> np.ndarray:
    """One string per (id, image) pair, for set operations on arrays."""
    return np.char.add(np.char.add(np.asarray(ids, dtype=str), "\x00"), np.asarray(image).astype(str))


def _check_ground(check: PointTable, obs: dict[str, np.ndarray], result: BundleResult,
                  axes: tuple[float, float]) -> dict[str, Any]:
    """Triangulated check points against their surveyed ground: errors (E, N, U metres) and predicted sigmas."""
    assert check.lon is not None and check.lat is not None and check.h is not None
    is_check = obs["role"] == "check"
    points, first = np.unique(obs["point"][is_check], return_index=True)
    if not points.size:
        return {"n": 0}
    point_ids = obs["id"][is_check][first]
    table_ids, table_first = np.unique(np.asarray(check.ids, dtype=str), return_index=True)
    row = table_first[np.searchsorted(table_ids, point_ids)]  # each point's surveyed ground: its first row
    est = result.ground[points]
    tru = np.stack([check.lon[row], check.lat[row], check.h[row]], axis=1)
    m_lon, m_lat = metres_per_degree(tru[:, 1], tru[:, 2], axes)
    err = np.stack([(est[:, 0] - tru[:, 0]) * m_lon, (est[:, 1] - tru[:, 1]) * m_lat, est[:, 2] - tru[:, 2]], axis=1)
    cov = result.ground_covariance_m[points]
    predicted = np.sqrt(np.einsum("jii->j", cov))
    return {
        "n": int(points.size),
        "rmse_3d_m": float(np.sqrt(np.mean(np.sum(err**2, axis=1)))),
        "predicted_rmse_3d_m": float(np.sqrt(np.mean(predicted**2))),
        "rmse_enu_m": np.sqrt(np.mean(err**2, axis=0)).tolist(),
        "predicted_rmse_enu_m": np.sqrt(np.mean(np.diagonal(cov, axis1=1, axis2=2), axis=0)).tolist(),
        "ids": point_ids.tolist(),
        "errors_enu_m": err.tolist(),
    }
