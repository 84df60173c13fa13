"""``nn-rfm``: the hybrid neural network + RFM model of Habib et al. (2018).

Paper: A. Habib, Z. Weshahy, M. El-Ghazaly, A. El-Shehaby, "Geometric Correction of High
Resolution Satellite Imagery Using Hybrid Non-parametric Model" (2018).
Irregularly distributed control points (572 points matched automatically against an orthophoto,
heights from a DTM) train a "downward" multilayer perceptron image -> ground (4 hidden layers,
32 neurons, tanh or logistic sigmoid, MATLAB toolbox); the network then predicts the ground
coordinates of a *regular* grid of image points (756 gridded GCPs), on which an RFM is fitted.
Their Table 2: conventional RFM on the irregular points 1.223 / 0.949 m RMS (x / y) on 9 check
points, hybrid ANN + RFM 0.851 / 0.685 m (QuickBird, 0.62 m GSD).

Here:

1. irregular GCPs: seeded uniform random image points mapped to the ground on the scene terrain
   (exact), then perturbed by Gaussian measurement noise (``noise_px`` on row/col, ``noise_m`` on
   X, Y, Z);
2. the network is ``(row, col, Z) -> (X, Y)`` (Yue et al.'s inputs and outputs) shaped as a line of
   sight, :class:`LineOfSightNetwork`: X and Y affine in Z at an image point, as a straight line of sight
   in the local ENU frame is -- Yue's free-Z network (``network="free"``) was seed-fragile between the
   heights of layered SCOPs (2.05 / 111 / 2,381 px for seeds 0-2 on the contract scene); it is
   trained by Levenberg-Marquardt with MATLAB-style validation early stopping (15 % held out)
   against over-training.  Default: one hidden layer of 7 sigmoid nodes (Yue et al.'s choice).
   Habib's own network, 32 neurons on 4 layers (``hidden=(8, 8, 8, 8), activation="tanh"``), is
   available; measured on QII (300 m relief, 572 GCPs with 0.5 px / 0.3 m noise, 500 checks,
   seeds 0-4) it extrapolates less tamely off the terrain (synthetic-grid RFM residual 0.4 px
   against 0.2 px), beat the direct RFM in 3 of 5 seeds instead of 5 of 5, and trains several
   times slower (266 parameters instead of 44);
3. synthetic GCPs: a regular image grid at 5 heights spanning the GCPs' height range (12 x 12 x 5
   = 720 points, about the paper's 756; one layer when the terrain is flat).  Habib predicted
   (X, Y, Z) from (u, v), i.e. generated points on the learned terrain surface; that variant is
   ``synthetic="surface"`` (it needs the network to learn the terrain, see :func:`fit_nn_rfm`);
4. a cubic RPC00B RFM (local ENU coordinates, reusing :mod:`explorer.rpc.fit`) fitted on them,
   with a mild Tikhonov term (``rfm_regularization=1e-5``, the same for the direct RFM; Habib
   et al. mention Tikhonov for large GCP sets).  Without it, free-denominator cubic RFMs fitted
   to noisy points grow poles inside the image (check points whose inversion fails and image
   errors of tens of pixels), in both models.

:func:`compare_nn_rfm` runs the experiment against an RFM fitted directly on the irregular
points, both judged on independent exact check points; the registered method ``nn-rfm`` uses the
SCOPs as the irregular GCPs and answers ground -> image through the final RFM (no collinearity
evaluation: CE = 0).  Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

import inspect
import warnings
from typing import Any, ClassVar

import numpy as np

from explorer import _log
from explorer.methods._lm import take_params
from explorer.methods.base import BestScanlineMethod, ScanlineResult, register
from explorer.methods.bpnn import BPNetworkGeometryModel, LineOfSightNetwork, MLPRegressor
from explorer.methods.rfm import rfm_domain_mask, rfm_ground_errors
from explorer.points import PointSet, scanline_times
from explorer.rpc.fit import fit_rfm_from_gcps
from explorer.rpc.model import RationalFunctionModel
from explorer.scene import Scene

__all__ = ["LineOfSightNetwork", "NNRFMMethod", "compare_nn_rfm", "fit_nn_rfm", "irregular_gcps"]


def irregular_gcps(
    scene: Scene, n: int, *, noise_px: float = 0.0, noise_m: float = 0.0, seed: int = 0
) -> tuple[PointSet, PointSet]:
    """Irregularly distributed control points on the scene terrain, exact and noisy.

    Parameters
    ----------
    scene : Scene
    n : int
        Number of seeded uniform random image points (points whose ray misses a DEM are dropped).
    noise_px : float
        Gaussian noise, 1 sigma, on row and column (image measurement), pixels.
    noise_m : float
        Gaussian noise, 1 sigma, on X, Y and Z (ground survey / orthophoto + DTM), metres.
    seed : int

    Returns
    -------
    exact, noisy : PointSet
        The same points without and with noise (``time`` is the exact scanline time).
    """
    rng = np.random.default_rng(seed)
    row = rng.uniform(0.0, scene.n_rows - 1.0, n)
    col = rng.uniform(0.0, scene.n_columns - 1.0, n)
    ground = scene.image_to_ground(row, col)
    ok = np.isfinite(ground[:, 0])
    row, col, ground = row[ok], col[ok], ground[ok]
    exact = PointSet(row, col, ground, scanline_times(scene, row), (0, 0, 1))
    noisy = PointSet(row + rng.normal(0.0, noise_px, row.shape) if noise_px else row.copy(),
                     col + rng.normal(0.0, noise_px, col.shape) if noise_px else col.copy(),
                     ground + rng.normal(0.0, noise_m, ground.shape) if noise_m else ground.copy(),
                     exact.time, (0, 0, 1))
    return exact, noisy


def _default_grid(synthetic: str) -> tuple[int, int, int]:
    """About the paper's 756 synthetic GCPs: 28 x 27 on the surface, or 12 x 12 x 5 layers (720).

    A cubic RFM needs at least 4 distinct heights: on 3 layers at normalised H = -1, 0, 1 the
    ``H^3`` column equals ``H`` and the fit is rank deficient (measured: 2.2 m check RMS on QII
    with 3 layers, 0.12 m with 5).
    """
    return (28, 27, 1) if synthetic == "surface" else (12, 12, 5)


def fit_nn_rfm(
    gcps: PointSet,
    image_shape: tuple[int, int],
    *,
    synthetic: str = "layers",
    network: str = "line-of-sight",
    hidden: tuple[int, ...] = (7,),
    activation: str = "sigmoid",
    grid: tuple[int, int, int] | None = None,
    validation_fraction: float = 0.15,
    max_iter: int = 1000,
    n_restarts: int = 1,
    rfm_regularization: float = 1e-5,
    seed: int = 0,
) -> tuple[RationalFunctionModel, MLPRegressor, dict]:
    """Habib et al.'s chain: network on irregular GCPs -> regular synthetic GCPs -> cubic RFM.

    Parameters
    ----------
    gcps : PointSet
        Irregular control points (row, col, ENU ground), possibly noisy.
    image_shape : (rows, columns)
        The synthetic grid spans the image from its first to its last pixel centre.
    synthetic : {"layers", "surface"}
        ``"layers"`` (default): the network is Yue et al.'s (row, col, Z) -> (X, Y) and the
        synthetic GCPs are a regular image grid at ``grid[2]`` heights spanning the GCPs' height
        range (>= 4 layers for a cubic RFM, see :func:`_default_grid`).  ``"surface"`` (Habib et
        al. literally): the network maps (row, col) -> (X, Y, Z) and the synthetic GCPs are a
        regular image grid on the *learned* terrain surface; the network must then learn the
        terrain itself, which a 32-neuron network does on flat or gentle terrain but not on the
        synthetic hilly relief of the presets (measured on QII with 300 m relief: 74 m RMS).
    network : {"line-of-sight", "free"}
        With ``synthetic="layers"``: ``"line-of-sight"`` (default) is :class:`LineOfSightNetwork` (X, Y affine
        in Z at a fixed image point, as a line of sight is); ``"free"`` is Yue et al.'s network with Z as a free
        input (:class:`~explorer.methods.bpnn.BPNetworkGeometryModel`), seed-fragile between the training
        heights (see :class:`LineOfSightNetwork`).
    hidden, activation, validation_fraction, max_iter, n_restarts, seed :
        Network options (:class:`~explorer.methods.bpnn.MLPRegressor`).
    grid : (n_rows, n_cols, n_layers), optional
        Synthetic GCP grid; default about the paper's 756 points (28 x 27 x 1 on the surface,
        12 x 12 x 5 for layers; the layers collapse to one when the GCP heights span < 1 m).
    rfm_regularization : float
        Tikhonov weight of the RFM fit (:mod:`explorer.rpc.fit`); default 1e-5.

    Returns
    -------
    model : RationalFunctionModel
        Cubic RFM, ENU metres in the roles of lon/lat/h.
    network : MLPRegressor
        ``(row, col) -> (X, Y, Z)`` (surface) or a :class:`BPNetworkGeometryModel` (layers).
    info : dict
        Network ``fit_info``, synthetic grid size and heights, RFM residuals on the synthetic grid.
    """
    if synthetic not in ("surface", "layers"):
        raise ValueError(f"synthetic must be 'surface' or 'layers', got {synthetic!r}")
    if network not in ("line-of-sight", "free"):
        raise ValueError(f"network must be 'line-of-sight' or 'free', got {network!r}")
    nr, nc, nz = (int(v) for v in (grid or _default_grid(synthetic)))
    if synthetic == "surface" and nz != 1:
        raise ValueError(f"synthetic='surface' puts the grid on the learned terrain: n_layers must be 1, got {nz}")
    g = gcps.ground
    options: dict[str, Any] = dict(activation=activation, max_iter=max_iter, n_restarts=n_restarts,
                   validation_fraction=validation_fraction, seed=seed, name="nn-rfm")
    rows = np.linspace(0.0, image_shape[0] - 1.0, nr)
    cols = np.linspace(0.0, image_shape[1] - 1.0, nc)
    if synthetic == "surface":
        net: MLPRegressor = MLPRegressor(hidden, **options)
        net.fit_arrays(np.column_stack([gcps.row, gcps.col]), g, min_input_scale=0.5,
                       min_target_scale=(1e-3, 1e-3, 1.0))
        rr, cc = np.repeat(rows, nc), np.tile(cols, nr)
        xyz = net.predict(np.column_stack([rr, cc]))
        xx, yy, zz = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        if float(np.ptp(g[:, 2])) < 1.0:
            zz = np.full_like(zz, float(np.mean(g[:, 2])))  # flat: keep the one height exactly
        heights = [float(zz.min()), float(zz.max())]
    else:
        net = (LineOfSightNetwork if network == "line-of-sight" else BPNetworkGeometryModel)(hidden, **options)
        net.fit(gcps.row, gcps.col, g[:, 2], g[:, 0], g[:, 1])
        z_lo, z_hi = float(g[:, 2].min()), float(g[:, 2].max())
        layers = np.linspace(z_lo, z_hi, nz) if (nz > 1 and z_hi - z_lo >= 1.0) else np.array([0.5 * (z_lo + z_hi)])
        rr = np.tile(np.repeat(rows, nc), layers.size)
        cc = np.tile(np.tile(cols, nr), layers.size)
        zz = np.repeat(layers, nr * nc)
        xx, yy = net.image_to_ground(rr, cc, zz)
        heights = layers.tolist()
    fit = fit_rfm_from_gcps(xx, yy, zz, rr, cc, order=3, rational=True, regularization=rfm_regularization)
    info = {"network": dict(net.fit_info), "synthetic": synthetic, "n_synthetic": int(rr.size),
            "synthetic_heights_m": heights, "rfm_grid_rms_px": fit.rms_px, "rfm_grid_max_px": fit.max_px}
    return fit.model, net, info


#: The options of :func:`fit_nn_rfm` (its keyword-only parameters) and their defaults; :func:`compare_nn_rfm`
#: and the ``nn-rfm`` method take the same.
FIT_OPTIONS: dict[str, Any] = {name: p.default for name, p in inspect.signature(fit_nn_rfm).parameters.items()
                               if p.kind is p.KEYWORD_ONLY}


def _xy_stats(dx: np.ndarray, dy: np.ndarray) -> dict:
    """Habib et al. Table 2 statistics in metres: per-point errors, mean and RMS of x and y.

    Points where the model gave no answer (NaN: its image -> ground inversion did not converge,
    e.g. near a pole of a rational function) are excluded from the statistics and counted in
    ``n_failed``.
    """
    ok = np.isfinite(dx) & np.isfinite(dy)
    a, b = dx[ok], dy[ok]
    nan = float("nan")
    return {"err_x": dx.tolist(), "err_y": dy.tolist(), "n_failed": int((~ok).sum()),
            "mean_x": float(np.mean(a)) if a.size else nan, "mean_y": float(np.mean(b)) if b.size else nan,
            "rms_x": float(np.sqrt(np.mean(a**2))) if a.size else nan,
            "rms_y": float(np.sqrt(np.mean(b**2))) if b.size else nan,
            "rms_total": float(np.sqrt(np.mean(a**2 + b**2))) if a.size else nan}


def compare_nn_rfm(
    scene: Scene,
    n_gcps: int = 572,
    n_checks: int = 9,
    noise_px: float = 0.5,
    noise_m: float = 0.3,
    seed: int = 0,
    **options: Any,
) -> dict:
    """Habib et al.'s Table 2 on a simulated scene: direct RFM vs NN + RFM on irregular noisy GCPs.

    Parameters
    ----------
    scene : Scene
        Use a scene with relief for a 3-D problem (e.g. ``build_scene("QII", relief_m=300)``,
        QuickBird as in the paper); on a flat scene every point has the same height.
    n_gcps : int
        Irregular control points (the paper: 572).
    n_checks : int
        Independent exact check points on the terrain (the paper: 9; more give a stabler RMS).
    noise_px, noise_m : float
        Gaussian measurement noise (1 sigma) of the control points: image (pixels) and ground
        (metres, X, Y and Z).  Check points are exact (the paper's GPS points).
    seed : int
        Seeds the control points, the noise, the check points and the network.
    **options
        The other options of :func:`fit_nn_rfm` (:data:`FIT_OPTIONS`: ``synthetic``, ``hidden``,
        ``activation``, ``grid``, ``validation_fraction``, ``max_iter``, ``n_restarts``,
        ``rfm_regularization``, the last also for the direct RFM), with its defaults.

    Returns
    -------
    dict
        ``rfm`` and ``nn_rfm`` (and ``nn``, the network alone): per-check-point object-space
        errors ``err_x``/``err_y`` (metres: each model's image -> ground at the true height minus
        the true X, Y), their mean and RMS (Table 2 layout), ``rms_total``, and the image-space
        RMS ``image_rms_px`` (ground -> image through the RFM vs the exact row/col); plus the
        setup (``gsd_m``, counts, noise, seeds) and the paper's numbers under ``paper``.

    Notes
    -----
    Measured on ``build_scene("QII", relief_m=300, relief_seed=1)``, 572 GCPs with 0.5 px and
    0.3 m noise, 500 check points, seeds 0-4, defaults: total RMS (m) direct RFM 0.143, 0.392,
    0.145, 0.246, 0.394 (2 seeds with 2 failed check points each: poles) against NN + RFM 0.099,
    0.079, 0.083, 0.101, 0.114 with the line-of-sight network (the network alone 0.087-0.121; with
    ``network="free"`` 0.132, 0.177, 0.102, 0.170, 0.136; no failure either way): the hybrid wins every
    seed, as Habib et al. claim (their 1.55 -> 1.09 m).  Measured with the free network (not re-measured
    with the line-of-sight one): the gain comes from stability, not from a better model: with
    ``rfm_regularization=1e-3`` the direct RFM has no failure and 0.124-0.178 m, as good as the
    hybrid (which wins 2 of 5 seeds then); the network alone is 0.12-0.18 m.  With the paper's
    9 check points the direct RFM is as good or better in all five seeds (0.07-0.11 m against
    0.10-0.13 m): its failures are local (poles), which 9 random points rarely hit, so the
    hybrid's advantage is robustness, visible over many check points, not typical-point accuracy.
    """
    options = take_params("compare_nn_rfm", {**options, "seed": seed}, FIT_OPTIONS)
    exact_gcps, gcps = irregular_gcps(scene, n_gcps, noise_px=noise_px, noise_m=noise_m, seed=seed)
    rng = np.random.default_rng(seed + 7919)
    cr = rng.uniform(0.0, scene.n_rows - 1.0, n_checks)
    cc = rng.uniform(0.0, scene.n_columns - 1.0, n_checks)
    cg = scene.image_to_ground(cr, cc)
    ok = np.isfinite(cg[:, 0])
    cr, cc, cg = cr[ok], cc[ok], cg[ok]

    g = gcps.ground
    direct = fit_rfm_from_gcps(g[:, 0], g[:, 1], g[:, 2], gcps.row, gcps.col, order=3, rational=True,
                               regularization=options["rfm_regularization"]).model
    with warnings.catch_warnings(record=True) as caught, _log.collect_warnings() as logged:
        warnings.simplefilter("always")
        hybrid, net, info = fit_nn_rfm(gcps, scene.shape, **options)

    def rfm_block(model: RationalFunctionModel) -> dict:
        dx, dy, conv = rfm_ground_errors(model, cr, cc, cg)
        pr, pc = model.projection(cg[:, 0], cg[:, 1], cg[:, 2])
        out = _xy_stats(dx, dy)
        out["localization_converged"] = float(np.mean(conv))
        out["image_rms_px"] = {"row": float(np.sqrt(np.mean((pr - cr) ** 2))),
                               "col": float(np.sqrt(np.mean((pc - cc) ** 2)))}
        out["image_max_px"] = float(np.max(np.hypot(pr - cr, pc - cc)))
        return out

    if isinstance(net, BPNetworkGeometryModel):
        xn, yn = net.image_to_ground(cr, cc, cg[:, 2])
    else:
        xyz = net.predict(np.column_stack([cr, cc]))
        xn, yn = xyz[:, 0], xyz[:, 1]
    return {
        "scene": scene.name, "gsd_m": float(np.mean(scene.ground_sample_distance())), "seed": seed,
        "n_gcps": len(gcps), "n_checks": int(cr.size), "noise_px": noise_px, "noise_m": noise_m,
        "gcp_height_range_m": [float(exact_gcps.ground[:, 2].min()), float(exact_gcps.ground[:, 2].max())],
        "rfm": rfm_block(direct), "nn_rfm": rfm_block(hybrid), "nn": _xy_stats(xn - cg[:, 0], yn - cg[:, 1]),
        "network": info["network"], "n_synthetic": info["n_synthetic"], "synthetic": info["synthetic"],
        "synthetic_heights_m": info["synthetic_heights_m"], "rfm_synthetic_grid_rms_px": info["rfm_grid_rms_px"],
        "warnings": [str(w.message) for w in caught] + list(logged),
        "paper": {"rfm": {"rms_x": 1.223, "rms_y": 0.949}, "nn_rfm": {"rms_x": 0.851, "rms_y": 0.685},
                  "note": "Habib et al. 2018 Table 2, QuickBird 0.62 m, 572 AGE points, 9 GPS check points"},
    }


@register
class NNRFMMethod(BestScanlineMethod):
    """Habib et al.'s hybrid model: SCOPs -> network -> regular synthetic GCPs -> RFM (ground -> image).

    Parameters
    ----------
    scene : Scene
    synthetic : {"layers", "surface"}
        How the synthetic GCPs are made (:func:`fit_nn_rfm`); default ``"layers"``.
    hidden : tuple of int
        Network hidden layers (default (7,); Habib's 32 neurons on 4 layers: (8, 8, 8, 8), tanh).
    activation : {"sigmoid", "tanh"}
    grid : (int, int, int), optional
        Synthetic GCP grid rows x columns x layers (default 12 x 12 x 5, about the paper's 756).
    validation_fraction : float
        Held-out fraction for early stopping (default 0: SCOPs are exact, see :attr:`DEFAULTS`).
    max_iter, n_restarts : int
        Network training options.
    rfm_regularization : float
        Tikhonov weight of the final RFM fit (default 1e-5).
    domain_margin : float
        Points beyond ``1 + domain_margin`` of the RFM's normalised X, Y, Z box come back
        ``converged = False`` (default 0.05).  On flat terrain the box is 1 m thick in Z: the RFM
        only knows that height.
    seed : int
    """

    name = "nn-rfm"
    label = "Hybrid NN + RFM"
    reference = ("Habib, Weshahy, El-Ghazaly, El-Shehaby 2018, Geometric correction of high resolution "
                 "satellite imagery using hybrid non-parametric model")
    family = "generalized"
    needs_line_geometry = False  # ground / image pairs only: runs on any sensor, an RPC included
    needs_fit = True
    long_fit = True
    exactness = "approximate"
    column_source = "model"  # the network predicts the column too
    #: SCOPs are exact (simulated by the sensor): no validation split.  Held-out points guard against fitting the
    #: noise of measured GCPs (Habib's case, :func:`compare_nn_rfm` keeps 15 %); on exact SCOPs the 15 points held
    #: out of 100 stopped the training after 17-47 of 1000 steps in 3 of 6 seeds on the Pleiades DIMAP (row RMSE
    #: 0.27-1.73 px, against 0.02-0.05 px for all 6 seeds without the split; the network's error at the check
    #: points equals its error at the SCOPs, so nothing was over-trained).
    DEFAULTS: ClassVar[dict[str, Any]] = {**FIT_OPTIONS, "validation_fraction": 0.0, "domain_margin": 0.05}

    def __init__(self, scene: Scene, **params: Any) -> None:
        p = take_params(self.name, params, self.DEFAULTS)
        super().__init__(scene, **p)
        self.domain_margin = float(p.pop("domain_margin"))
        grid = p["grid"]
        self._options: dict[str, Any] = {**p, "hidden": tuple(p["hidden"]),
                                         "grid": None if grid is None else tuple(grid)}
        self.model: RationalFunctionModel | None = None
        self.network: MLPRegressor | None = None

    def _fit(self, control: PointSet) -> None:
        self.model, self.network, info = fit_nn_rfm(control, self.scene.shape, **self._options)
        self.fit_info = {**info, "converged": info["network"]["converged"]}

    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        assert self.model is not None
        row, col = self.model.projection(ground[:, 0], ground[:, 1], ground[:, 2])
        in_domain = rfm_domain_mask(self.model, ground, self.domain_margin)
        converged = in_domain & np.isfinite(row) & np.isfinite(col)
        if self.fit_info["network"].get("too_few_points"):  # the network cannot generalise: trust nothing
            converged[:] = False
        return self._result(ground, row, converged, np.zeros(row.size, dtype=np.int64), col=col,
                            trace=[row.copy()] if trace else None, info={"in_domain": in_domain})
