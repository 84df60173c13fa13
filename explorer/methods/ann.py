"""Three-stage best scanline determination with a neural error model: ``ann``.

Ahooei Nezhad, Valadan Zoej, Ghorbanian (2021), "A fast non-iterative method for
the object to image space best scanline determination of spaceborne linear array
pushbroom images", Adv. Space Res. 68:3584-3593, as summarised by the same authors
in Remote Sensing 16:2787 (2024, sections 1 and 4) and Sensors 24:5594 (2024,
section 1): (1) an affine transformation ground -> image (row, column) fitted on
SCOPs gives approximate image coordinates, (2) the approximate row gives an
approximate exposure time, (3) a one-hidden-layer network models the difference
between the exact and the approximate scanline as a function of the approximate
(row, column); the best scanline is the approximate one plus the modelled error.
The papers report 200-700 SCOPs (500 for most images) for sub-pixel accuracy.

Here the error model works in rows (pixels; a row difference is a time difference
times the line period), its inputs are the approximate (row, column) scaled to
[-1, 1] by the SCOPs, and it is trained by the Levenberg-Marquardt trainer of
:mod:`explorer.methods._lm` on a seeded 70/30 split.  The column comes from the
collinearity at the final row (one collinearity evaluation).  :class:`ThreeStageMethod`
is shared with ``ogp`` (:mod:`explorer.methods.ogp`).  Conventions:
``docs/conventions.md``.
"""

from __future__ import annotations

import time

import numpy as np

from explorer.methods._lm import FeatureScaler, GroundFeatures, fit_network, take_params
from explorer.methods.base import BestScanlineMethod, ScanlineResult, register
from explorer.methods.mlp import network_verdict
from explorer.methods.regression import qr_least_squares
from explorer.points import PointSet, scanline_times
from explorer.scene import Scene

REFERENCE_2021 = "Ahooei Nezhad, Valadan Zoej, Ghorbanian (2021) Adv. Space Res. 68:3584-3593"


class ThreeStageMethod(BestScanlineMethod):
    """Affine approximation + approximate exposure time + a learned scanline error model.

    Subclasses implement :meth:`_fit_error_model` and :meth:`_predict_error` on the
    normalised approximate image coordinates ``u`` (N, 2).

    Parameters (common)
    -------------------
    use_height : bool or None
        Include Z in the affine stage (default: only when the SCOPs' heights span > 1 m).
    seed : int
        Seeds the 70/30 split (and the subclass's own randomness).
    train_fraction : float
        Share of SCOPs that trains the error model; the rest validates it (0.7).
    domain_margin, height_tolerance_m : float
        Training-domain check (0.05, 1 m): ground points outside the SCOPs' extent (in
        ground coordinates and in approximate image coordinates) are not located
        (``converged`` and ``inside`` False).
    """

    family = "learned"
    needs_line_geometry = False  # ground / image pairs only: runs on any sensor, an RPC included
    needs_fit = True
    long_fit = True
    exactness = "approximate"
    COMMON = {
        "use_height": None, "seed": 0, "train_fraction": 0.7, "domain_margin": 0.05,
        "height_tolerance_m": 1.0,
    }
    EXTRA: dict = {}

    def __init__(self, scene: Scene, **params) -> None:
        p = take_params(self.name, params, {**self.COMMON, **self.EXTRA})
        if not (0.0 < float(p["train_fraction"]) < 1.0):
            raise ValueError(f"{self.name}: train_fraction must lie in (0, 1), got {p['train_fraction']}")
        super().__init__(scene, **p)

    # ------------------------------------------------------------ stages 1-2
    def _approximate(self, ground: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Stage 1 (affine) and the domain mask: approximate row, column (N,), ``u`` (N, 2), mask."""
        f, ok = self.features(ground)
        a = np.column_stack([np.ones(f.shape[0]), f])
        r_a = a @ self.affine_row
        c_a = a @ self.affine_col
        u = self.uv_scaler.transform(np.column_stack([r_a, c_a]))
        ok &= self.uv_scaler.in_domain(u, self.params["domain_margin"])
        return r_a, c_a, u, ok

    def _fit(self, control: PointSet) -> None:
        p = self.params
        self.features = GroundFeatures(control, p["use_height"], p["domain_margin"], p["height_tolerance_m"])
        d = self.features.n_features
        if len(control) < d + 2:
            raise ValueError(
                f"{self.name}: {len(control)} control points are too few for the affine stage "
                f"({d + 1} coefficients) plus a validated error model"
            )
        f, _ = self.features(control.ground)
        a = np.column_stack([np.ones(f.shape[0]), f])
        self.affine_row, cond = qr_least_squares(a, control.row, self.name)
        self.affine_col, _ = qr_least_squares(a, control.col, self.name)
        r_a, c_a = a @ self.affine_row, a @ self.affine_col
        self.uv_scaler = FeatureScaler.fit(np.column_stack([r_a, c_a]), ["row", "column"])
        u = self.uv_scaler.transform(np.column_stack([r_a, c_a]))
        t_a = scanline_times(self.scene, r_a)  # stage 2: approximate exposure time (NaN without scanlines)
        dr = control.row - r_a
        self.fit_info = {
            "n_control": len(control),
            "affine_row": self.affine_row.tolist(),
            "affine_col": self.affine_col.tolist(),
            "affine_condition_number": cond,
            "affine_rmse_px": float(np.sqrt(np.mean(dr**2))),
            "affine_max_px": float(np.max(np.abs(dr))),
            "approx_time_span_s": [float(np.min(t_a)), float(np.max(t_a))] if np.isfinite(t_a).all() else None,
            **self.features.info(),
        }
        t0 = time.perf_counter()
        self._fit_error_model(u, dr)
        self.fit_info["error_model_s"] = time.perf_counter() - t0

    def _fit_error_model(self, u: np.ndarray, dr: np.ndarray) -> None:  # pragma: no cover
        raise NotImplementedError

    def _predict_error(self, u: np.ndarray) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        r_a, _, u, ok = self._approximate(ground)
        row = r_a + self._predict_error(u)
        # a model that missed its accuracy goal still answers with its best model, like mlp (fit_info,
        # the log line and the map's title say so); only a training that broke down flags every answer
        converged = ok & bool(self.fit_info.get("stop_reason") != "non_finite"
                              and np.isfinite(self.fit_info.get("val_rmse_px", 0.0)))
        ce = np.zeros(row.shape, dtype=np.int64)
        res = self._result(ground, row, converged, ce, trace=[r_a, row.copy()] if trace else None,
                           info={"in_domain": ok, "approx_row": r_a})
        res.inside &= ok
        return res


@register
class ANNMethod(ThreeStageMethod):
    """``ann``: affine approximation + one-hidden-layer network error model (Adv. Space Res. 2021).

    Parameters
    ----------
    scene : Scene
    neurons : int
        Hidden neurons of the error model (default 10).
    max_epochs, max_fail : int
        Levenberg-Marquardt budget and early-stopping patience (200, 6).  The error model
        is small and smooth: on the paper presets it is below 1e-3 px after 30 epochs, and
        each epoch with ~350 training points costs about ten times an ``mlp`` epoch.
    device : str
        Device (default "cpu": trained and evaluated without torch where numba is present,
        :func:`explorer.methods._lm.fit_network`; another value is a torch device).
    max_val_rmse_px : float
        Validation RMSE above which the training missed its accuracy goal (1.0 px): ``fit_info["converged"]``
        False, one log line, the map's title; its best model still answers (as ``mlp``).
    goal_px : float
        Training RMSE at which the training stops (1e-6 px).  With few SCOPs the network has more weights
        than training points and fits them exactly: without a goal it went on to the targets' float64
        rounding (~1e-14 px), where each step is decided by the last bits of the arithmetic, and two
        trainings on the same SCOPs in one process ended at different epochs with maps that differed in
        the 9th digit (usgscsm's orbital ISD at 30 SCOPs).  1e-6 px is far below anything a map shows
        and far above that rounding (~1e-12 px at 10,000 rows).
    use_height, seed, train_fraction, domain_margin, height_tolerance_m
        See :class:`ThreeStageMethod`.
    """

    name = "ann"
    label = "ANN-BSD"
    reference = REFERENCE_2021
    EXTRA = {"neurons": 10, "max_epochs": 200, "max_fail": 6, "device": "cpu", "max_val_rmse_px": 1.0,
             "goal_px": 1e-6}

    def _fit_error_model(self, u: np.ndarray, dr: np.ndarray) -> None:
        p = self.params
        self.network, info = fit_network(
            u, dr, (int(p["neurons"]),), name=self.name, seed=p["seed"],
            train_fraction=p["train_fraction"], max_epochs=p["max_epochs"], max_fail=p["max_fail"],
            device=p["device"], goal_rmse=float(p["goal_px"]),
        )
        info["train_rmse_px"] = info.pop("train_rmse")
        info["val_rmse_px"] = info.pop("val_rmse")
        self.fit_info.update(info)
        network_verdict(self.name, self.fit_info, p["max_val_rmse_px"], "its best model is used")

    def _predict_error(self, u: np.ndarray) -> np.ndarray:
        return self.network.predict(u)
