"""Shared machinery of the learned best-scanline methods (``lrm``, ``prm``, ``mlp``,
``ann``, ``ogp``): feature scaling with a training-domain check, the seeded 70/30
SCOP split, a sigmoid multilayer perceptron with flat parameters, and a
Levenberg-Marquardt trainer with early stopping (torch, float64).

The trainer follows MATLAB's ``trainlm`` as used by Ahooei Nezhad et al. (2024,
Remote Sensing 16:2787, section 2.4: "the Levenberg-Marquardt algorithm and the
sigmoid function") and (2021, Adv. Space Res. 68:3584, the ANN error model):
damped Gauss-Newton steps ``(J^T J + mu I) d = J^T e`` with ``mu`` divided by 10
after a successful step and multiplied by 10 until the error decreases, stopping when
the validation error has stayed above its best for ``max_fail`` epochs in a row (the
weights with the best validation error are kept), on a vanishing gradient, on
``mu > mu_max``, on the error goal or after ``max_epochs``.  MATLAB's defaults
(``mu`` 1e-3, factors 0.1/10, ``mu_max`` 1e10, 6 validation failures, 1000 epochs)
are kept except the gradient bound: 1e-12 instead of 1e-7, because a sub-pixel
scanline over thousands of rows needs a relative target error near 1e-6.
The Jacobian of the outputs with respect to all parameters is back-propagated by
:meth:`SigmoidMLP.per_sample_jacobian` (``torch.func.jacrev`` of one sample's output, vmapped
over the samples, for other networks).

Two implementations of that one training.  :func:`fit_network` (``mlp``, ``ann``) trains a network
of ONE hidden layer on the CPU without torch when numba is present
(:func:`explorer.methods._lm_compiled.train_one_hidden`, the whole training one compiled call;
:func:`levenberg_marquardt_compiled`): the first weights come from
:class:`explorer.methods._torch_uniform.TorchUniform` with the arithmetic of
:meth:`SigmoidMLP.init_params` (the same bits as torch's generator), the trained weights equal the
torch trainer's to round-off over short trainings (tests/methods/test_lm_without_torch.py), and the
:class:`TrainedNetwork` holds a numpy ``theta`` and predicts in numpy -- importing torch costs some
1.3 s of CPU per process for networks of a few dozen weights.  The torch trainer
(:func:`levenberg_marquardt`, :func:`lm_minimise`) serves the rest: several hidden layers
(``mlp``'s ``grid_search``), a device other than the CPU, no numba.
Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from explorer._lazy import LazyModule
from explorer._numba import NUMBA_AVAILABLE
from explorer._threads import blas_threads
from explorer.methods._torch_uniform import TorchUniform
from explorer.points import PointSet

if TYPE_CHECKING:  # the real module for annotations
    import torch
else:
    torch = LazyModule("torch")  # imported on first use (about 2 s)

# ------------------------------------------------------------------- parameters


def take_params(name: str, params: dict, defaults: dict) -> dict:
    """``defaults`` updated by ``params``; raises ``TypeError`` naming any unknown parameter."""
    unknown = sorted(set(params) - set(defaults))
    if unknown:
        raise TypeError(f"{name}: unknown parameter(s) {unknown}; accepted: {sorted(defaults)}")
    return {**defaults, **params}


# ----------------------------------------------------------------- feature scaling


@dataclass
class FeatureScaler:
    """Affine map of features to [-1, 1] from the training SCOPs (min/max per column).

    Attributes
    ----------
    offset, scale : ndarray, shape (D,)
        ``normalised = (value - offset) / scale``.
    """

    offset: np.ndarray
    scale: np.ndarray

    @classmethod
    def fit(cls, values: np.ndarray, names: Sequence[str] | None = None) -> FeatureScaler:
        """Scaler of ``values`` (N, D); raises ``ValueError`` for a constant column."""
        values = np.asarray(values, dtype=np.float64)
        lo, hi = values.min(axis=0), values.max(axis=0)
        scale = (hi - lo) / 2.0
        bad = ~(scale > 0)
        if bad.any():
            which = [names[int(k)] if names else str(k) for k in np.flatnonzero(bad)]
            raise ValueError(f"feature(s) {', '.join(which)} constant over the control points: cannot scale")
        return cls((hi + lo) / 2.0, scale)

    def transform(self, values: np.ndarray) -> np.ndarray:
        """Normalised values (N, D)."""
        return (values - self.offset) / self.scale

    def inverse(self, values: np.ndarray) -> np.ndarray:
        """Undo :meth:`transform`."""
        return values * self.scale + self.offset

    def in_domain(self, normalised: np.ndarray, margin: float) -> np.ndarray:
        """True (N,) where every normalised feature lies in ``[-1 - margin, 1 + margin]``."""
        return np.all(np.abs(normalised) <= 1.0 + margin, axis=1)


def default_use_height(control: PointSet, threshold_m: float = 1.0) -> bool:
    """The papers' rule: use Z as a feature only when the SCOPs' heights span more than ``threshold_m``.

    With SCOPs on the mean-height plane (the papers' protocol) the model is a function
    of (X, Y) only.
    """
    z = control.ground[:, 2]
    return bool(np.ptp(z) > threshold_m)


class GroundFeatures:
    """Normalised (X, Y[, Z]) features of ground points and the training-domain check.

    Parameters
    ----------
    control : PointSet
        SCOPs the scaling is fitted on.
    use_height : bool or None
        Include Z; ``None`` applies :func:`default_use_height`.
    domain_margin : float
        Points whose normalised features leave ``[-1 - margin, 1 + margin]`` are outside
        the training domain (the models are not trusted there).
    height_tolerance_m : float
        Without Z, points farther than this from the SCOPs' mean height are outside the
        domain (the model only knows that plane).
    """

    def __init__(
        self,
        control: PointSet,
        use_height: bool | None,
        domain_margin: float,
        height_tolerance_m: float,
    ) -> None:
        self.use_height = default_use_height(control) if use_height is None else bool(use_height)
        self.columns = [0, 1, 2] if self.use_height else [0, 1]
        names = ["X", "Y", "Z"] if self.use_height else ["X", "Y"]
        self.scaler = FeatureScaler.fit(control.ground[:, self.columns], names)
        self.domain_margin = float(domain_margin)
        self.height_tolerance_m = float(height_tolerance_m)
        self.mean_height = float(control.ground[:, 2].mean())

    @property
    def n_features(self) -> int:
        return len(self.columns)

    def __call__(self, ground: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalised features (N, D) and the in-domain mask (N,) of ground points (N, 3)."""
        f = self.scaler.transform(ground[:, self.columns])
        ok = self.scaler.in_domain(f, self.domain_margin)
        if not self.use_height:
            ok &= np.abs(ground[:, 2] - self.mean_height) <= self.height_tolerance_m
        return f, ok

    def info(self) -> dict:
        return {
            "use_height": self.use_height,
            "feature_offset": self.scaler.offset.tolist(),
            "feature_scale": self.scaler.scale.tolist(),
            "domain_margin": self.domain_margin,
            "mean_height_m": self.mean_height,
        }


def split_train_validation(n: int, fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Seeded random split of ``range(n)`` into sorted (train, validation) index arrays.

    ``round(fraction * n)`` points go to training (the papers' 70/30 split).
    """
    rng = np.random.default_rng(seed)
    perm = rng.permutation(n)
    k = int(round(fraction * n))
    return np.sort(perm[:k]), np.sort(perm[k:])


def check_split_sizes(name: str, n: int, n_train: int, n_val: int, n_features: int) -> None:
    """Raise a clear ``ValueError`` when a split cannot train a model on ``n_features`` inputs.

    The training part must at least fix an affine function of the inputs
    (``n_features + 1`` points) and the validation part needs one point.
    """
    if n_train < n_features + 1 or n_val < 1:
        raise ValueError(
            f"{name}: {n} control points give {n_train} training / {n_val} validation points; "
            f"need at least {n_features + 1} training and 1 validation point"
        )


# ----------------------------------------------------------------------- network


def dense_layers(theta: torch.Tensor, shapes: Sequence[tuple[int, int]]) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """Weights ``W (out, in)`` and biases ``b (out,)`` of consecutive dense layers, viewed from one flat
    parameter vector laid out layer by layer as ``W`` row-major then ``b`` (the layout of every network
    trained by :func:`lm_minimise`)."""
    layers, pos = [], 0
    for o, i in shapes:
        layers.append((theta[pos:pos + o * i].reshape(o, i), theta[pos + o * i:pos + o * i + o]))
        pos += o * i + o
    return layers


def layer_shapes(sizes: Sequence[int]) -> list[tuple[int, int]]:
    """``(out, in)`` of each dense layer of a network of layer widths ``sizes`` (inputs, hidden..., outputs)."""
    return [(sizes[k + 1], sizes[k]) for k in range(len(sizes) - 1)]


def n_parameters(shapes: Sequence[tuple[int, int]]) -> int:
    """Weights and biases of the dense layers ``shapes``: the length of their flat parameter vector."""
    return sum(o * i + o for o, i in shapes)


def dense_forward(
    theta: torch.Tensor,
    shapes: Sequence[tuple[int, int]],
    x: torch.Tensor,
    activation: Callable[[torch.Tensor], torch.Tensor],
    *,
    linear_output: bool = True,
) -> torch.Tensor:
    """Outputs (N, out) of the dense layers ``shapes`` (parameters ``theta``, :func:`dense_layers`) on
    inputs ``x`` (N, in): ``activation`` after every layer, except the last when ``linear_output``."""
    h = x
    last = len(shapes) - 1
    for k, (w, b) in enumerate(dense_layers(theta, shapes)):
        h = h @ w.T + b
        if k < last or not linear_output:
            h = activation(h)
    return h


def _row_norms_like_torch(w: np.ndarray) -> np.ndarray:
    """``torch.linalg.vector_norm(w, dim=1, keepdim=True)`` of a float64 CPU matrix (H, I), bit for bit where it
    matters here (I of 2 or 3: the inputs of ``mlp`` and ``ann``).

    torch's vectorised CPU kernel accumulates a short row's squares by fused multiply-adds,
    ``fma(w2, w2, fma(w1, w1, w0 * w0))``, which numpy cannot do: here each fused step is computed exactly in
    rational arithmetic and rounded once (a handful of rows).  Measured against torch 2.13 on this machine (its
    AVX-512 kernels; a CPU without FMA would run others): equal for every row of 2 and 3 columns (3,000 random
    rows each); rows of 4 or more columns are summed by another pattern, for which numpy's sum is the closest
    match found (every row of 4 columns equal; 67-95 % of rows of 5-30 columns, the rest within 2 ulp).  A first
    weight an ulp off changes no rule of the training, only its round-off.  Returns (H, 1).
    """
    if w.shape[1] > 3:
        return np.sqrt(np.sum(w * w, axis=1, keepdims=True))
    from fractions import Fraction

    out = np.empty((w.shape[0], 1))
    for r, row in enumerate(w.tolist()):
        acc = row[0] * row[0]
        for v in row[1:]:
            acc = float(Fraction(v) * Fraction(v) + Fraction(acc))  # one rounding: a fused multiply-add
        out[r, 0] = np.sqrt(acc)
    return out


class SigmoidMLP:
    """Fully connected network: logistic-sigmoid hidden layers, one linear output.

    The parameters live in one flat float64 vector (the Levenberg-Marquardt unknowns),
    laid out layer by layer as ``W (out, in)`` row-major then ``b (out,)``.

    Parameters
    ----------
    n_inputs : int
    hidden : sequence of int
        Neurons per hidden layer (the papers: one layer of 5-50).
    """

    def __init__(self, n_inputs: int, hidden: Sequence[int]) -> None:
        if n_inputs < 1 or not hidden or any(int(h) < 1 for h in hidden):
            raise ValueError(f"invalid network shape: {n_inputs} inputs, hidden {list(hidden)}")
        self.n_inputs = int(n_inputs)
        self.hidden = tuple(int(h) for h in hidden)
        self.shapes = layer_shapes((self.n_inputs, *self.hidden, 1))
        self.n_params = n_parameters(self.shapes)

    def init_params(self, generator: torch.Generator) -> torch.Tensor:
        """Nguyen-Widrow initial weights (seeded), flat float64 vector (P,).

        Hidden rows get norm ``0.7 h^(1/n_in)`` and biases uniform in +- that, so the
        sigmoids' transitions spread over the normalised input box without being steep
        (steep initial sigmoids can leave steps between the grid nodes of the SCOPs that
        neither the training nor the validation points see); the output layer starts small.
        """
        parts = []
        for k, (o, i) in enumerate(self.shapes):
            if k < len(self.shapes) - 1:
                beta = 0.7 * o ** (1.0 / i)
                w = torch.rand(o, i, generator=generator, dtype=torch.float64) * 2 - 1
                w = beta * w / w.norm(dim=1, keepdim=True)
                b = beta * (torch.rand(o, generator=generator, dtype=torch.float64) * 2 - 1)
            else:
                w = (torch.rand(o, i, generator=generator, dtype=torch.float64) * 2 - 1) / np.sqrt(i)
                b = torch.zeros(o, dtype=torch.float64)
            parts += [w.reshape(-1), b]
        return torch.cat(parts)

    def init_params_numpy(self, uniform: TorchUniform) -> np.ndarray:
        """:meth:`init_params` without torch: the same draws (``uniform``, :class:`TorchUniform` of the seed of
        torch's generator) and the same arithmetic, hence the same bits (tests/methods/test_lm_without_torch.py);
        flat float64 vector (P,)."""
        parts = []
        for k, (o, i) in enumerate(self.shapes):
            if k < len(self.shapes) - 1:
                beta = 0.7 * o ** (1.0 / i)
                w = uniform.rand((o, i)) * 2 - 1
                w = beta * w / _row_norms_like_torch(w)
                b = beta * (uniform.rand(o) * 2 - 1)
            else:
                w = (uniform.rand((o, i)) * 2 - 1) / np.sqrt(i)
                b = np.zeros(o)
            parts += [w.reshape(-1), b]
        return np.concatenate(parts)

    def forward_numpy(self, theta: np.ndarray, x: np.ndarray) -> np.ndarray:
        """:meth:`forward` in numpy: output (N,) for inputs ``x`` (N, n_inputs) and parameters ``theta`` (P,)
        (float64 host arrays)."""
        h = x
        last = len(self.shapes) - 1
        pos = 0
        for k, (o, i) in enumerate(self.shapes):
            w, b = theta[pos:pos + o * i].reshape(o, i), theta[pos + o * i:pos + o * i + o]
            pos += o * i + o
            h = h @ w.T + b
            if k < last:
                with np.errstate(over="ignore"):  # exp(-z) = inf far below the transition: sigmoid 0, as torch
                    h = 1.0 / (1.0 + np.exp(-h))
        return h[:, 0]

    def forward(self, theta: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """Network output (N,) for inputs ``x`` (N, n_inputs) and parameters ``theta`` (P,)."""
        return dense_forward(theta, self.shapes, x, torch.sigmoid)[:, 0]

    def per_sample_jacobian(self, theta: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """d output_n / d theta, shape (N, P), by back-propagation written out for these layers (every sample at
        once, no autograd): the Jacobian :func:`levenberg_marquardt` otherwise gets from ``torch.func`` (vmap of
        jacrev), whose first call imports torch's compiler stack (seconds) and whose per-call overhead dominated
        the training of these small networks; equal to it within round-off (tests/methods/test_lm_jacobian.py)."""
        layers = dense_layers(theta, self.shapes)
        last = len(layers) - 1
        acts = [x]  # acts[k]: the input of layer k
        h = x
        for k, (w, b) in enumerate(layers):
            h = h @ w.T + b
            if k < last:
                h = torch.sigmoid(h)
            acts.append(h)
        n = x.shape[0]
        delta = torch.ones((n, 1), dtype=theta.dtype, device=theta.device)  # d output / d z of the linear output
        blocks: list[torch.Tensor] = []
        for k in range(last, -1, -1):
            w, _ = layers[k]
            a = acts[k]
            blocks.append(delta)  # d / d b
            blocks.append((delta[:, :, None] * a[:, None, :]).reshape(n, -1))  # d / d W, row-major
            if k:
                delta = (delta @ w) * a * (1.0 - a)  # through the sigmoid of layer k - 1 (a = its output)
        return torch.cat(blocks[::-1], dim=1)


# ----------------------------------------------------------- Levenberg-Marquardt


@contextmanager
def torch_threads(n: int = 1) -> Iterator[None]:
    """Run torch CPU ops on ``n`` threads inside the block, then restore the setting.

    The networks here are tiny (tens of points, tens to thousands of parameters): with
    several threads torch spends its time synchronising, and on a shared machine a
    multi-threaded Jacobian is 10x slower than a single-threaded one.
    """
    old = torch.get_num_threads()
    torch.set_num_threads(max(1, int(n)))
    try:
        yield
    finally:
        torch.set_num_threads(old)


@dataclass
class LMResult:
    """Outcome of :func:`lm_minimise` (errors in the caller's normalised units).

    Attributes
    ----------
    theta : Tensor (P,)
        Parameters with the lowest validation error met during training (the last ones without a
        validation set); a float64 numpy array from :func:`levenberg_marquardt_compiled`.
    epochs : int
        Levenberg-Marquardt steps taken (accepted epochs).
    best_epoch : int
        Epoch of ``theta``.
    stop_reason : str
        "goal", "min_grad", "mu_max", "validation", "plateau", "max_epochs" or "non_finite".
    converged : bool
        Stopped for a reason other than ``max_epochs`` / ``non_finite``.
    train_mse, val_mse : float
        Training objective and validation error of ``theta`` (mean squared errors for the MLP).
    history : dict
        "objective", "validation", "mu" at the start and after each epoch (``epochs + 1`` values).
    iterations : int
        Epochs started (``epochs`` plus one where the damping could not find a step).
    final_objective : float
        Training objective of the last accepted step (not necessarily ``theta``'s).
    """

    theta: Any
    epochs: int
    best_epoch: int
    stop_reason: str
    converged: bool
    train_mse: float
    val_mse: float
    history: dict = field(default_factory=dict)
    iterations: int = 0
    final_objective: float = float("nan")


@dataclass
class _NormalEquations:
    """The parts of a Levenberg-Marquardt step that do not depend on ``mu``, built once per epoch
    (:func:`_normal_equations`): the product ``J^T J`` (or ``J J^T`` when the parameters outnumber the errors)
    and the right-hand side.  Before, each damping tried in an epoch (two on average: one rejected, one taken)
    recomputed them -- half the training's time at 1,000 SCOPs -- with the same inputs, so the same bits."""

    jac: torch.Tensor
    product: torch.Tensor
    rhs: torch.Tensor
    weight_decay: float
    dual: bool
    """True: the ``N x N`` form ``d = J^T (J J^T + mu I)^-1 e``."""


def _normal_equations(jac: torch.Tensor, err: torch.Tensor, theta: torch.Tensor,
                      weight_decay: float = 0.0) -> _NormalEquations:
    """``J^T J`` and ``J^T e - lambda theta`` of one epoch (``J J^T`` and ``e`` when there are more parameters than
    errors and no weight decay)."""
    n, p = jac.shape
    if weight_decay:
        return _NormalEquations(jac, jac.T @ jac, jac.T @ err - weight_decay * theta, weight_decay, False)
    if p <= n:
        return _NormalEquations(jac, jac.T @ jac, jac.T @ err, 0.0, False)
    return _NormalEquations(jac, jac @ jac.T, err, 0.0, True)


def _damped_step(normal: _NormalEquations, mu: float) -> torch.Tensor:
    """The step of damping ``mu`` from an epoch's normal equations: ``(J^T J + (mu + lambda) I) d = J^T e -
    lambda theta`` (Cholesky, least squares if singular); without weight decay and with more parameters than
    errors the equivalent ``d = J^T (J J^T + mu I)^-1 e`` (an N x N system)."""
    a = normal.product.clone()
    a.diagonal().add_(mu + normal.weight_decay if normal.weight_decay else mu)
    rhs = normal.rhs
    chol, info = torch.linalg.cholesky_ex(a)
    if int(info) != 0:
        sol = torch.linalg.lstsq(a, rhs[:, None]).solution[:, 0]
    else:
        sol = torch.cholesky_solve(rhs[:, None], chol)[:, 0]
    return normal.jac.T @ sol if normal.dual else sol


def lm_minimise(
    errors: Callable[[torch.Tensor], torch.Tensor],
    jacobian: Callable[[torch.Tensor], torch.Tensor],
    theta0: torch.Tensor,
    *,
    validation_error: Callable[[torch.Tensor], float] | None = None,
    mean: bool = True,
    weight_decay: float = 0.0,
    max_epochs: int = 1000,
    mu: float = 1e-3,
    mu_dec: float = 0.1,
    mu_inc: float = 10.0,
    mu_max: float = 1e10,
    min_grad: float = 0.0,
    goal: float = 0.0,
    max_fail: int = 6,
    fail_on_tie: bool = False,
    count_initial_validation: bool = True,
    plateau: tuple[int, float] | None = None,
) -> LMResult:
    """The one Levenberg-Marquardt trainer of the package (networks of ``mlp``, ``ann``, ``bpnn``, ``nn-rfm``).

    Damped Gauss-Newton steps ``(J^T J + (mu + lambda) I) d = J^T e - lambda theta`` on the errors
    ``e = target - model`` (flattened, N) with ``J = d model / d theta`` (N, P); ``mu`` is multiplied by
    ``mu_dec`` after a step that lowers the objective ``mean(e^2)`` (or ``e.e`` with ``mean=False``) plus
    ``lambda |theta|^2``, and by ``mu_inc`` until one does (MATLAB's ``trainlm``).

    Stops on a non-finite objective, on the objective ``<= goal``, on a gradient norm ``|2 J^T e| / N``
    below ``min_grad``, when ``mu`` exceeds ``mu_max``, after ``max_fail`` epochs in a row whose
    validation error did not improve on the best (``> best``; ``>= best`` with ``fail_on_tie``), on a
    plateau (``plateau=(window, tol)``: the objective fell by less than the fraction ``tol`` over the
    last ``window`` epochs) or after ``max_epochs``.  The parameters with the best validation error are
    returned; ``count_initial_validation=False`` starts the best validation error at infinity instead
    of the initial parameters' error.

    Parameters
    ----------
    errors : callable
        ``theta (P,) -> e (N,)``, target minus model.
    jacobian : callable
        ``theta (P,) -> J (N, P)``, derivative of the model (not of ``e``).
    theta0 : Tensor (P,)
        Initial parameters (float64).
    validation_error : callable, optional
        ``theta -> float``; without it there is no early stopping.

    Returns
    -------
    LMResult
    """
    lam = float(weight_decay)

    def objective(e: torch.Tensor, th: torch.Tensor) -> float:
        base = torch.mean(e**2) if mean else e @ e
        return float(base + lam * (th @ th)) if lam else float(base)

    def val_error(th: torch.Tensor) -> float:
        if validation_error is None:
            return float("nan")
        with torch.no_grad():
            return float(validation_error(th))

    theta = theta0.detach().clone()
    with torch.no_grad():
        err = errors(theta)
    n = err.shape[0]
    perf = objective(err, theta)
    best_theta, best_epoch = theta.clone(), 0
    best_val = val_error(theta) if count_initial_validation else float("inf")
    fails = 0
    hist: dict[str, list[float]] = {"objective": [perf], "validation": [val_error(theta)], "mu": [mu]}
    stop, done, started = "max_epochs", 0, 0
    for epoch in range(1, max_epochs + 1):
        if not np.isfinite(perf):
            stop = "non_finite"
            break
        if perf <= goal:
            stop = "goal"
            break
        started = epoch
        jf = jacobian(theta).detach()
        if min_grad > 0.0 and float(torch.linalg.vector_norm(2.0 * (jf.T @ err)) / n) < min_grad:
            stop, started = "min_grad", epoch - 1
            break
        improved = False
        normal = _normal_equations(jf, err, theta, lam)  # the same for every damping tried in this epoch
        while mu <= mu_max:
            cand = theta + _damped_step(normal, mu)
            with torch.no_grad():
                cerr = errors(cand)
            cperf = objective(cerr, cand)
            if np.isfinite(cperf) and cperf < perf:
                theta, err, perf = cand, cerr, cperf
                mu = max(mu * mu_dec, 1e-20)
                improved = True
                break
            mu *= mu_inc
        if not improved:
            stop = "mu_max"
            break
        done = epoch
        v = val_error(theta)
        hist["mu"].append(mu)
        hist["objective"].append(perf)
        hist["validation"].append(v)
        if validation_error is None:
            best_theta, best_epoch = theta.clone(), epoch
        elif v < best_val:
            best_theta, best_val, best_epoch = theta.clone(), v, epoch
            fails = 0
        elif v > best_val or fail_on_tie:
            fails += 1
            if fails >= max_fail:
                stop = "validation"
                break
        if plateau is not None:
            window, tol = plateau
            past = hist["objective"]
            if len(past) > window and past[-1 - window] - perf <= tol * past[-1 - window]:
                stop = "plateau"
                break
    with torch.no_grad():
        train_best = objective(errors(best_theta), best_theta)
    ok = stop not in ("max_epochs", "non_finite") and np.isfinite(train_best)
    return LMResult(best_theta, done, best_epoch, stop, bool(ok), train_best, val_error(best_theta), hist,
                    max(started, done), perf)


@torch_threads(1)
def levenberg_marquardt(
    net: SigmoidMLP,
    theta0: torch.Tensor,
    x_train: np.ndarray,
    y_train: np.ndarray,
    x_val: np.ndarray,
    y_val: np.ndarray,
    *,
    min_grad: float = 1e-12,
    device: str | torch.device = "cpu",
    **options: Any,
) -> LMResult:
    """Train a :class:`SigmoidMLP` by :func:`lm_minimise` (mean squared error) with early stopping on
    the validation set.

    Runs on one CPU thread (:func:`torch_threads`), restoring torch's setting after.  The Jacobian of
    the outputs (N, P) is built row by row: ``jacrev`` of one sample's output, vmapped over the samples
    (cost O(N P); ``jacrev`` of the whole batch costs O(N^2 P)).

    Parameters
    ----------
    net : SigmoidMLP
    theta0 : Tensor (P,)
        Initial parameters (float64).
    x_train, y_train : ndarray (N, D), (N,)
        Normalised training inputs and targets.
    x_val, y_val : ndarray (M, D), (M,)
        Normalised validation inputs and targets (M may be 0: no early stopping).
    min_grad : float
        As :func:`lm_minimise`, whose default (0: no gradient test) this replaces by 1e-12.
    device : str or torch.device
        Where the tensors live ("cpu" is enough for these small problems).
    **options
        Other options of :func:`lm_minimise` (``max_epochs``, ``mu``, ``mu_dec``, ``mu_inc``, ``mu_max``,
        ``goal``, ``max_fail``), with its defaults (MATLAB's ``trainlm``).

    Returns
    -------
    LMResult
        ``train_mse`` / ``val_mse`` are mean squared errors in normalised target units.
    """
    dev = torch.device(device)

    def tensor(a: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float64)).to(dev)

    xt, yt, xv, yv = tensor(x_train), tensor(y_train), tensor(x_val), tensor(y_val)
    own = getattr(net, "per_sample_jacobian", None)  # a network that back-propagates itself (SigmoidMLP)
    if own is not None:
        def jacobian(theta: torch.Tensor) -> torch.Tensor:
            return own(theta, xt)
    else:
        per_sample = torch.func.vmap(
            torch.func.jacrev(lambda theta, xi: net.forward(theta, xi[None, :])[0]), in_dims=(None, 0)
        )

        def jacobian(theta: torch.Tensor) -> torch.Tensor:
            return per_sample(theta, xt)
    return lm_minimise(
        lambda theta: yt - net.forward(theta, xt),
        jacobian,
        theta0.detach().clone().to(device=dev, dtype=torch.float64),
        validation_error=(lambda theta: float(torch.mean((yv - net.forward(theta, xv)) ** 2))) if xv.shape[0] else None,
        min_grad=min_grad, **options,
    )


def compiled_training_applies(net: SigmoidMLP, device: Any = "cpu") -> bool:
    """True where :func:`levenberg_marquardt_compiled` trains ``net`` instead of the torch trainer: numba present,
    one hidden layer, on the CPU."""
    return NUMBA_AVAILABLE and len(net.hidden) == 1 and str(device).split(":")[0] == "cpu"


def levenberg_marquardt_compiled(
    net: SigmoidMLP,
    theta0: np.ndarray,
    x_train: np.ndarray,
    y_train: np.ndarray,
    x_val: np.ndarray,
    y_val: np.ndarray,
    *,
    min_grad: float = 1e-12,
    max_epochs: int = 1000,
    mu: float = 1e-3,
    mu_dec: float = 0.1,
    mu_inc: float = 10.0,
    mu_max: float = 1e10,
    goal: float = 0.0,
    max_fail: int = 6,
) -> LMResult:
    """:func:`levenberg_marquardt` of a one-hidden-layer :class:`SigmoidMLP` without torch: one compiled call
    (:func:`explorer.methods._lm_compiled.train_one_hidden`) with the same objective (mean squared error), options
    and stopping rules (``min_grad``, validation failures only when worse, the initial validation error counted, no
    plateau, no weight decay; the dual ``J J^T`` form with more weights than errors), on one OpenBLAS thread.

    Parameters
    ----------
    net : SigmoidMLP
        One hidden layer (:func:`compiled_training_applies`).
    theta0 : ndarray (P,)
        Initial parameters.
    x_train, y_train, x_val, y_val
        As :func:`levenberg_marquardt`.

    Returns
    -------
    LMResult
        As :func:`levenberg_marquardt`'s, its ``theta`` a float64 numpy array.
    """
    from explorer.methods._lm_compiled import STOP_REASONS, train_one_hidden

    if len(net.hidden) != 1:
        raise ValueError(f"the compiled trainer serves one hidden layer, not {len(net.hidden)}")

    def inputs(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(a, dtype=np.float64).reshape(-1, net.n_inputs)

    def targets(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(a, dtype=np.float64).reshape(-1, 1)

    xt, xv, yt, yv = inputs(x_train), inputs(x_val), targets(y_train), targets(y_val)
    no_feats = np.empty((xt.shape[0], 0))
    no_feats_val = np.empty((xv.shape[0], 0))
    with blas_threads(1):  # its small products on OpenBLAS's threads cost 25x on a busy machine (bpnn's measure)
        (theta, done, best_epoch, stop, iterations, train_best, val_best, final, hist, hist_val,
         hist_mu) = train_one_hidden(
            np.ascontiguousarray(theta0, dtype=np.float64), xt, no_feats, yt, xv, no_feats_val, yv, net.hidden[0],
            False, 0.0, int(max_epochs), float(mu), float(mu_dec), float(mu_inc), float(mu_max), float(goal),
            int(max_fail), 0, 0.0, True, float(min_grad), False, True)
    reason = STOP_REASONS[int(stop)]
    ok = reason not in ("max_epochs", "non_finite") and bool(np.isfinite(train_best))
    history = {"objective": hist.tolist(), "validation": hist_val.tolist(), "mu": hist_mu.tolist()}
    return LMResult(theta, int(done), int(best_epoch), reason, ok, float(train_best),
                    float(val_best) if xv.shape[0] else float("nan"), history, int(iterations), float(final))


# ------------------------------------------------------------- network training


@dataclass
class TrainedNetwork:
    """A trained :class:`SigmoidMLP` with its target scaling.

    Attributes
    ----------
    net : SigmoidMLP
    theta : ndarray or Tensor (P,)
        Parameters: a float64 numpy array when trained without torch (:func:`fit_network`'s compiled path), else a
        torch tensor on ``device``.
    target_offset, target_scale : float
        ``target = network output * target_scale + target_offset``.
    device : str or torch.device
        Where ``theta`` lives ("cpu" for a numpy ``theta``).
    """

    net: SigmoidMLP
    theta: np.ndarray | torch.Tensor
    target_offset: float
    target_scale: float
    device: str | torch.device

    @property
    def on_cpu(self) -> bool:
        """True when the parameters live on the CPU (numpy, or a CPU torch tensor)."""
        return str(self.device).split(":")[0] == "cpu"

    @property
    def theta_numpy(self) -> np.ndarray:
        """The parameters as a float64 host array (P,) (cached)."""
        cached = self.__dict__.get("_theta_numpy")
        if cached is None:
            if isinstance(self.theta, np.ndarray):
                cached = self.theta.astype(np.float64, copy=True)
            else:
                cached = self.theta.detach().cpu().numpy().astype(np.float64, copy=True)
            self.__dict__["_theta_numpy"] = cached
        return cached

    @property
    def layer_sizes(self) -> tuple[int, ...]:
        """``(n_inputs, hidden..., 1)``."""
        return (self.net.n_inputs, *self.net.hidden, 1)

    def predict(self, x: np.ndarray, chunk: int = 1 << 16) -> np.ndarray:
        """Target values (N,) of normalised inputs ``x`` (N, D): chunked, float64; in numpy on the CPU
        (:meth:`SigmoidMLP.forward_numpy`: no torch needed), by torch on another device."""
        x = np.asarray(x, dtype=np.float64)
        out = np.empty(x.shape[0])
        if self.on_cpu:
            theta = self.theta_numpy
            for s in range(0, x.shape[0], chunk):
                out[s:s + chunk] = self.net.forward_numpy(theta, x[s:s + chunk])
        else:
            theta_t = cast("torch.Tensor", self.theta)  # on another device: a torch tensor (the torch trainer's)
            with torch.no_grad():
                for s in range(0, x.shape[0], chunk):
                    xs = torch.from_numpy(np.ascontiguousarray(x[s:s + chunk])).to(self.device)
                    out[s:s + chunk] = self.net.forward(theta_t, xs).cpu().numpy()
        return out * self.target_scale + self.target_offset


def fit_network(
    x: np.ndarray,
    y: np.ndarray,
    hidden: Sequence[int],
    *,
    name: str,
    seed: int,
    train_fraction: float = 0.7,
    max_epochs: int = 1000,
    max_fail: int = 6,
    device: str | torch.device = "cpu",
    min_inputs: int | None = None,
    goal_rmse: float = 0.0,
) -> tuple[TrainedNetwork, dict]:
    """Train a sigmoid MLP on normalised inputs ``x`` (N, D) for targets ``y`` (N,).

    The targets are scaled to [-1, 1] (min/max); the points are split 70/30 (seeded)
    into training and validation sets; the initial weights are those of a torch generator
    seeded with ``seed``; training is :func:`levenberg_marquardt` in float64, stopping when the
    training RMSE reaches ``goal_rmse`` (target units; 0: no goal, MATLAB's default).  One hidden
    layer on the CPU with numba (:func:`compiled_training_applies`) trains without torch
    (:class:`TorchUniform` draws, :func:`levenberg_marquardt_compiled`; the returned network's
    ``theta`` is a numpy array); the rest by torch.

    Returns
    -------
    TrainedNetwork
    dict
        ``n_params``, ``n_train``, ``n_val``, ``epochs``, ``best_epoch``, ``stop_reason``,
        ``optimizer_converged``, ``train_rmse`` and ``val_rmse`` (target units).

    Raises
    ------
    ValueError
        If the split leaves too few points (:func:`check_split_sizes`).
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if not (0.0 < train_fraction < 1.0):
        raise ValueError(f"{name}: train_fraction must lie in (0, 1), got {train_fraction}")
    tr, va = split_train_validation(x.shape[0], train_fraction, seed)
    check_split_sizes(name, x.shape[0], tr.size, va.size, min_inputs if min_inputs is not None else x.shape[1])
    lo, hi = float(y.min()), float(y.max())
    offset = (hi + lo) / 2.0
    scale = (hi - lo) / 2.0
    if not scale > 1e-300:
        scale = 1.0  # constant target: nothing to scale
    yn = (y - offset) / scale
    net = SigmoidMLP(x.shape[1], hidden)
    goal = (float(goal_rmse) / scale) ** 2
    dev: str | torch.device
    if compiled_training_applies(net, device):
        dev = "cpu"
        res = levenberg_marquardt_compiled(
            net, net.init_params_numpy(TorchUniform(int(seed))), x[tr], yn[tr], x[va], yn[va],
            max_epochs=max_epochs, max_fail=max_fail, goal=goal,
        )
    else:
        dev = torch.device(device)
        gen = torch.Generator(device="cpu").manual_seed(int(seed))
        theta0 = net.init_params(gen)
        res = levenberg_marquardt(
            net, theta0.to(dev), x[tr], yn[tr], x[va], yn[va], max_epochs=max_epochs,
            max_fail=max_fail, device=dev, goal=goal,
        )
    info = {
        "hidden": list(net.hidden),
        "n_params": net.n_params,
        "n_train": int(tr.size),
        "n_val": int(va.size),
        "epochs": res.epochs,
        "best_epoch": res.best_epoch,
        "stop_reason": res.stop_reason,
        "optimizer_converged": res.converged,
        "train_rmse": float(np.sqrt(res.train_mse) * scale),
        "val_rmse": float(np.sqrt(res.val_mse) * scale),
        "seed": int(seed),
    }
    return TrainedNetwork(net, res.theta, offset, scale, dev), info
