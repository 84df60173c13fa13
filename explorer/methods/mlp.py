"""Best scanline by a multilayer perceptron trained on simulated control points: ``mlp``.

Ahooei Nezhad, Valadan Zoej, Khoshelham, Ghorbanian, Farnaghi, Jamali, Youssefi,
Gheisari (2024), "Best Scanline Determination of Pushbroom Images for a Direct
Object to Image Space Transformation Using Multilayer Perceptron", Remote Sensing
16:2787, sections 2.4-3: the scanline is ``r = f(X, Y)`` (eq. 3) with ``f`` an MLP
of sigmoid hidden units trained by Levenberg-Marquardt on SCOPs split 70 % /
30 % into training and validation sets; a grid search over 1-5 hidden layers of
10-50 neurons picks the structure; one hidden layer of 5-10 neurons and 100 SCOPs
gave sub-pixel accuracy on all ten images (Table 3, Figures 3-8).

Inputs (X, Y[, Z]) are scaled to [-1, 1] by the SCOPs' extent.  The network learns the row
*minus its least-squares affine function of the scaled inputs* (the trend, fitted on the training
SCOPs), scaled to [-1, 1]; the row is trend + network.  This departs from the paper, which scales
the raw row (MATLAB's ``mapminmax``): on a real image of 50,000 rows the non-linear part of the
row is a few pixels to a few hundred, so a sub-pixel fit of the raw row needs a relative error
near 1e-5, which Levenberg-Marquardt from a random start rarely reaches with tens of SCOPs.
Measured on the Pleiades DIMAP scene with its DEM (49,826 rows, SCPs at 20,000 points): 100 SCOPs
gave 2.3 px RMSE with the raw row (stopped by validation after 16 epochs) and 0.0025 px with the
trend removed; 30 SCOPs 49 px and 0.75 px (also on the CTX ISD and a Pleiades RPC:
``docs/explorer.md``).  The network itself (sigmoid hidden layers, linear output, Nguyen-Widrow
initial weights, Levenberg-Marquardt with early stopping on 30 % validation SCOPs) is the
paper's.  The Levenberg-Marquardt trainer and the network are in :mod:`explorer.methods._lm`
(float64; one hidden layer on the CPU compiled without torch, several layers by torch).

A training that ends above ``max_val_rmse_px`` on the validation SCOPs is reported
(``fit_info["converged"]`` False, one log line with the validation RMSE and the stop reason), but
its best model (the weights of the lowest validation error) still answers: the residuals then
show what it reached instead of a map of missing values.  The column comes from the collinearity at the predicted row
(one collinearity evaluation per point).  Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from explorer import _log
from explorer.geometry.kernels import NUMBA_AVAILABLE
from explorer.methods._compiled import mlp_predict
from explorer.methods._lm import GroundFeatures, fit_network, split_train_validation, take_params
from explorer.methods.base import BestScanlineMethod, ScanlineResult, register
from explorer.points import PointSet
from explorer.scene import Scene


def network_verdict(name: str, info: dict, max_val_rmse_px: float,
                    consequence: str = "its points are marked not converged") -> bool:
    """Decide whether a trained model is usable, record it in ``info`` and warn if not.

    Usable ("converged") means: the optimiser ended with a finite error (an exhausted
    epoch budget is allowed, see ``stop_reason`` / ``optimizer_converged``) and the
    validation RMSE is at most ``max_val_rmse_px`` -- the papers' feasibility criterion
    (sub-pixel).  The log line names what was reached and why training stopped.
    """
    ok = info["stop_reason"] != "non_finite" and np.isfinite(info["val_rmse_px"])
    ok = bool(ok and info["val_rmse_px"] <= max_val_rmse_px)
    info["converged"] = ok
    if not ok:  # one line on the package logger (explorer/_log.py), not a warning record with a file path
        _log.warn(
            f"{name}: training did not reach its accuracy goal (validation RMSE {info['val_rmse_px']:.3g} px, "
            f"limit {max_val_rmse_px} px; stop: {info['stop_reason']} after {info['epochs']} epochs); "
            f"{consequence}"
        )
    return ok


@register
class MLPMethod(BestScanlineMethod):
    """``mlp``: scanline = MLP(X, Y[, Z]) trained on SCOPs (Remote Sens. 16:2787).

    Parameters
    ----------
    scene : Scene
    hidden_layers : int
        Number of hidden layers (default 1).
    neurons : int or sequence of int
        Neurons per hidden layer (default 10; a sequence gives each layer its own).
    seed : int
        Seeds the 70/30 split and the initial weights (default 0).
    max_epochs : int
        Levenberg-Marquardt epoch budget (default 1000, MATLAB's ``trainlm``).
    max_fail : int
        Early stopping: validation error above its best this many epochs in a row (6).
    train_fraction : float
        Share of SCOPs used for training, the rest validates (0.7).
    use_height : bool or None
        Include Z; default only when the SCOPs' heights span more than 1 m.
    device : str
        Device for training and inference (default "cpu": one hidden layer trains and predicts without torch;
        another value is a torch device).
    max_val_rmse_px : float
        A network whose validation RMSE exceeds this is reported as not reaching its goal (1.0):
        ``fit_info["converged"]`` False and a log line; its best model still answers.
    detrend : bool
        Learn the row minus its least-squares affine function of the inputs (default True; False:
        the paper's raw scaled row).
    goal_px : float
        Stop training once the training RMSE is at most this (default 0.01 px, 1 % of the paper's
        sub-pixel criterion; MATLAB's ``trainlm`` goal).  On the DIMAP scene at 100 SCOPs it ends
        training after 122 instead of 1,000 epochs (0.3 s instead of 5 s here) for an SCP RMSE of
        0.019 px instead of 0.005 px; 0 trains until the validation, gradient or epoch limit.
    domain_margin, height_tolerance_m : float
        Training-domain check as in :class:`explorer.methods.regression.LinearRegressionMethod`
        (0.05, 1.0 m): points outside are not located (``converged``/``inside`` False).
    """

    name = "mlp"
    label = "MLP-BSD"
    reference = (
        "Ahooei Nezhad, Valadan Zoej, Khoshelham, Ghorbanian, Farnaghi, Jamali, Youssefi, Gheisari "
        "(2024) Remote Sensing 16:2787"
    )
    family = "learned"
    needs_line_geometry = False  # ground / image pairs only: runs on any sensor, an RPC included
    needs_fit = True
    long_fit = True
    exactness = "approximate"

    DEFAULTS = {
        "hidden_layers": 1, "neurons": 10, "seed": 0, "max_epochs": 1000, "max_fail": 6,
        "train_fraction": 0.7, "use_height": None, "device": "cpu", "max_val_rmse_px": 1.0,
        "domain_margin": 0.05, "height_tolerance_m": 1.0, "detrend": True, "goal_px": 0.01,
    }

    def __init__(self, scene: Scene, **params) -> None:
        p = take_params(self.name, params, self.DEFAULTS)
        super().__init__(scene, **p)
        neurons = p["neurons"]
        if isinstance(neurons, Iterable):
            self.hidden = tuple(int(v) for v in neurons)
        else:
            self.hidden = (int(neurons),) * int(p["hidden_layers"])
        if not self.hidden or min(self.hidden) < 1:
            raise ValueError(f"{self.name}: need at least one hidden layer of >= 1 neuron, got {self.hidden}")

    def _fit(self, control: PointSet) -> None:
        p = self.params
        self.features = GroundFeatures(control, p["use_height"], p["domain_margin"], p["height_tolerance_m"])
        x, _ = self.features(control.ground)
        t0 = time.perf_counter()
        self.trend = np.zeros(x.shape[1] + 1)
        if p["detrend"]:
            # the affine trend from the training SCOPs only (the same seeded split as the network's)
            train, _ = split_train_validation(x.shape[0], p["train_fraction"], p["seed"])
            design = np.c_[x[train], np.ones(train.size)]
            self.trend = np.linalg.lstsq(design, control.row[train], rcond=None)[0]
        target = control.row - (x @ self.trend[:-1] + self.trend[-1])
        self.network, info = fit_network(
            x, target, self.hidden, name=self.name, seed=p["seed"],
            train_fraction=p["train_fraction"], max_epochs=p["max_epochs"], max_fail=p["max_fail"],
            device=p["device"], goal_rmse=float(p["goal_px"]),
        )
        info["train_rmse_px"] = info.pop("train_rmse")
        info["val_rmse_px"] = info.pop("val_rmse")
        info["train_s"] = time.perf_counter() - t0
        info["n_control"] = len(control)
        info["detrend"] = bool(p["detrend"])
        info["max_val_rmse_px"] = float(p["max_val_rmse_px"])
        info.update(self.features.info())
        self.fit_info = info
        network_verdict(self.name, info, p["max_val_rmse_px"], "its best model is used")

    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        net = self.network
        f, ok_f = self.features(ground)
        if NUMBA_AVAILABLE and net.on_cpu:  # one compiled pass (same network, float64)
            row, ok = mlp_predict(self.features, ground, net.theta_numpy, net.layer_sizes, net.target_scale,
                                  net.target_offset)
        else:  # torch on the network's device
            row, ok = net.predict(f), ok_f
        row = row + (f @ self.trend[:-1] + self.trend[-1])
        # a training above its accuracy goal still answers with its best model (fit_info says so)
        converged = ok.copy()
        ce = np.zeros(row.shape, dtype=np.int64)
        return self._result(ground, row, converged, ce, trace=[row.copy()] if trace else None,
                            info={"in_domain": ok}, mask=ok)


@dataclass
class GridSearchResult:
    """Outcome of :func:`grid_search`.

    Attributes
    ----------
    table : list of dict
        One row per structure: ``layers``, ``neurons``, ``n_params``, ``val_rmse_px``,
        ``train_rmse_px``, ``epochs``, ``stop_reason``, ``converged``, ``fit_s``.
    best : dict
        The chosen row (lowest validation RMSE among converged networks; ties go to
        fewer parameters).
    method : MLPMethod
        The fitted network of ``best``.
    """

    table: list[dict] = field(default_factory=list)
    best: dict = field(default_factory=dict)
    method: MLPMethod | None = None


def grid_search(
    scene: Scene,
    scops: PointSet,
    layers: Iterable[int] = range(1, 6),
    neurons: Iterable[int] = range(10, 51, 10),
    seed: int = 0,
    **params,
) -> GridSearchResult:
    """The paper's structure search: train every (layers, neurons) network on the same
    70/30 split and rank them by validation RMSE (Remote Sens. 16:2787, section 3).

    Parameters
    ----------
    scene : Scene
    scops : PointSet
    layers, neurons : iterables of int
        Hidden layers 1-5 and neurons per layer 10-50 by 10 in the paper (41 to
        10,401 parameters).
    seed : int
    **params
        Other :class:`MLPMethod` parameters (``max_epochs``, ``use_height``, ...).

    Returns
    -------
    GridSearchResult
    """
    table, fitted = [], []
    for n_layers in layers:
        for n_neurons in neurons:
            m = MLPMethod(scene, hidden_layers=int(n_layers), neurons=int(n_neurons), seed=seed, **params)
            t0 = time.perf_counter()
            with warnings.catch_warnings(), _log.quiet():  # failing candidates are expected and tabulated
                warnings.simplefilter("ignore", RuntimeWarning)
                m.fit(scops)
            fi = m.fit_info
            table.append({
                "layers": int(n_layers), "neurons": int(n_neurons), "n_params": fi["n_params"],
                "val_rmse_px": fi["val_rmse_px"], "train_rmse_px": fi["train_rmse_px"],
                "epochs": fi["epochs"], "stop_reason": fi["stop_reason"], "converged": fi["converged"],
                "fit_s": time.perf_counter() - t0,
            })
            fitted.append(m)
    if not table:
        raise ValueError("grid_search: empty layers/neurons ranges")
    def rank(k: int) -> tuple:
        v = table[k]["val_rmse_px"]
        return (not table[k]["converged"], v if np.isfinite(v) else np.inf, table[k]["n_params"])

    order = sorted(range(len(table)), key=rank)
    k = order[0]
    return GridSearchResult(table, dict(table[k]), fitted[k])
