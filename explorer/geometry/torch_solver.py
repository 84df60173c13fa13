"""The fast Newton passes of :func:`explorer.geometry.kernels.solve_exact` on a torch device.

:func:`solve_exact_torch` has the contract and the returns of ``solve_exact`` (without ``trace``):
the seed and the plain, branch-free Newton passes over all points -- the bulk of the work, one
collinearity evaluation (CE) per point on the paper presets -- run on a torch device ("cpu", or
"cuda" where available) in float64; the few points those passes do not accept come back to the
host and are finished by the numpy safeguarded iteration :func:`~explorer.geometry.kernels._solve_exact_np`
(per-point bracket, bisection, window probes), so every decision is the numpy path's.

The device evaluates *the same code* as the numpy fallback: :func:`~explorer.geometry.kernels._ce_fixed_py`
(the branch-free CE), :func:`~explorer.geometry.kernels._seed_row_py` and
:func:`~explorer.geometry.kernels._seed_full_py` are written with ``+ - * /`` and indexing only, so
they run unchanged on torch tensors; this module rebinds them to a torch-aware table lookup
(``floor``/``clamp`` instead of ``np.floor``/``np.clip``) and hands them the model's coefficients as
Python floats and its tables as device tensors.  Element-wise float64 ``+ - * /`` are correctly
rounded on the CPU and on CUDA alike and eager torch fuses nothing, so the device performs the
numpy path's floating-point operations in the same order: on the CPU the results agree bit for bit.
Only :func:`_newton_update_torch`, the ten-line acceptance rule of
:func:`~explorer.geometry.kernels._newton_update_np`, is restated for tensors.

torch is imported when a function here is called, never at import time (the model layer imports
the kernels without torch).  Conventions (rows, columns, time, frames): ``docs/conventions.md``.
"""

from __future__ import annotations

import math
import types
from functools import cache
from typing import TYPE_CHECKING, Any

import numpy as np

from explorer.geometry import kernels
from explorer.geometry.kernels import (
    _ACCEPTED,
    _NO_ROOT,
    _RUNNING,
    _TO_GENERAL,
    STATUS_NO_ROOT_IN_WINDOW,
    CollinearityParams,
    NewtonOptions,
    SeedModel,
    _solve_exact_np,
)

if TYPE_CHECKING:  # pragma: no cover - typing only
    import torch

# Points per device pass; peak device memory is about 0.6 kB per point (some 70 float64 temporaries of one
# CE).  On the CPU a chunk below torch's parallel grain (32,768 elements) runs every op on one thread, in
# cache and without OpenMP hand-offs, which on a loaded machine made 65,536-point chunks 10-100x slower.
DEFAULT_CHUNK = {"cpu": 1 << 14, "cuda": 1 << 21}
DEVICE_TYPES = ("cpu", "cuda")


class _DeviceArray:
    """A model array for the shared evaluators: integer items as Python floats, tensor-indexed items on the device.

    ``_ce_fixed_py`` and the seed read coefficients one at a time (``P[0, 3]``: a Python float mixes
    with a tensor of any device, where a numpy scalar on the left of ``*`` would try to convert the
    tensor) and look tables up at per-point indices (``js[j, k]``, ``H[k + 1, 0]`` with ``k`` a tensor:
    the device copy).
    """

    __slots__ = ("host", "device")

    def __init__(self, a: np.ndarray, dev: torch.device) -> None:
        import torch

        self.host = np.ascontiguousarray(a, dtype=np.float64)
        self.device = torch.as_tensor(self.host, device=dev)

    def __getitem__(self, idx: Any) -> float | torch.Tensor:
        parts = idx if isinstance(idx, tuple) else (idx,)
        if all(isinstance(i, int | np.integer) for i in parts) and len(parts) == self.host.ndim:
            return float(self.host[idx])
        return self.device[idx]

    @property
    def shape(self) -> tuple[int, ...]:
        return self.host.shape


def _device_args(args: tuple, dev: torch.device) -> tuple:
    """Kernel arguments (:meth:`FixedModel.args`, :meth:`SeedModel.args`) for tensors on ``dev``: arrays as
    :class:`_DeviceArray`, numpy scalars as Python floats, the count tuples unchanged."""
    out = []
    for a in args:
        if isinstance(a, np.ndarray):
            a = _DeviceArray(a, dev)
        elif isinstance(a, np.floating):
            a = float(a)
        out.append(a)
    return tuple(out)


@cache
def _torch_kernels() -> tuple[types.FunctionType, types.FunctionType]:
    """``_ce_fixed_py`` and ``_seed_full_py`` rebound to a torch table lookup (the same code objects)."""
    import torch

    def _table_index(x: torch.Tensor, last: int) -> torch.Tensor:
        # np.clip(np.floor(x), 0, last).astype(int64); NaN maps to 0 (numpy's cast would be undefined)
        return torch.clamp(torch.nan_to_num(torch.floor(x), nan=0.0), 0, last).to(torch.int64)

    # the globals the evaluator and seed functions were defined with, with the table lookup swapped
    names = {**kernels._ce_fixed_py.__globals__, **kernels._seed_full_py.__globals__}
    names["_table_index"] = _table_index
    seed_row = types.FunctionType(kernels._seed_row_py.__code__, names, "_seed_row_py")
    names["_seed_row_py"] = seed_row
    ce = types.FunctionType(kernels._ce_fixed_py.__code__, names, "_ce_fixed_py")
    seed = types.FunctionType(kernels._seed_full_py.__code__, names, "_seed_full_py")
    return ce, seed


def _newton_update_torch(
    rr: torch.Tensor,
    g: torch.Tensor,
    gt: torch.Tensor,
    yd: torch.Tensor,
    ydt: torch.Tensor,
    vz: torch.Tensor,
    line_period: float,
    pitch: float,
    pc: float,
    w_lo: float,
    w_hi: float,
    orient: float,
    accept_step: float,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Torch twin of :func:`~explorer.geometry.kernels._newton_update_np` (same operations, same order).

    Parameters
    ----------
    rr : Tensor, shape (M,)
        Rows evaluated (clipped to the window).
    g, gt : Tensor, shape (M,)
        Residual (m) and its time derivative (m/s) at ``rr``.
    yd, ydt : Tensor, shape (M,)
        Across-track focal coordinate (m) and its rate (m/s).
    vz : Tensor, shape (M,)
        Sensor-frame ``v_z`` (m; negative in front of the camera).
    line_period, pitch, pc : float
        Seconds per row, metres per detector, principal column (px).
    w_lo, w_hi, orient, accept_step : float
        Search window (rows), sign of ``dg/drow``, largest accepted Newton step (rows).

    Returns
    -------
    row, col : Tensor, shape (M,)
        ``rr`` plus the Newton step, and the column moved to it (px).
    r : Tensor, shape (M,)
        Next iterate (``rr`` where the evaluation was unusable).
    state : Tensor of int8, shape (M,)
        ``_ACCEPTED``, ``_NO_ROOT``, ``_RUNNING`` or ``_TO_GENERAL``.
    """
    import torch

    gr = gt * line_period
    delta = -g / gr
    rn = rr + delta
    good = (vz < 0.0) & (orient * gr > 0.0) & (torch.abs(delta) < math.inf)
    outward = ((rr >= w_hi) & (delta > 0.0)) | ((rr <= w_lo) & (delta < 0.0))
    acc = good & (torch.abs(delta) <= accept_step)
    state = torch.full(rr.shape, _TO_GENERAL, dtype=torch.int8, device=rr.device)
    state = state.masked_fill(good, _RUNNING).masked_fill(good & outward, _NO_ROOT).masked_fill(acc, _ACCEPTED)
    return rn, (yd + ydt * line_period * delta) / pitch + pc, torch.where(good, rn, rr), state


def _resolve_device(device: str | torch.device) -> torch.device:
    """A usable float64 torch device ("cpu" or an available "cuda[:k]"), or a ValueError saying why not."""
    import torch

    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError, ValueError) as exc:
        raise ValueError(f"solve_exact_torch: {device!r} is not a torch device (use 'cpu' or 'cuda')") from exc
    if dev.type not in DEVICE_TYPES:
        raise ValueError(f"solve_exact_torch runs in float64 on 'cpu' or 'cuda' devices only, got {device!r}")
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            raise ValueError(
                f"device {device!r} requested but CUDA is not available (torch.cuda.is_available() is False)"
            )
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise ValueError(f"device {device!r} requested but only {torch.cuda.device_count()} CUDA device(s) exist")
    return dev


def solve_exact_torch(
    params: CollinearityParams,
    ground: np.ndarray,
    seed: SeedModel,
    *,
    device: str | torch.device = "cpu",
    chunk: int | None = None,
    **options: Any,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`~explorer.geometry.kernels.solve_exact` with its seed and fast Newton passes on a torch device.

    Per chunk of points the device computes the window-clipped seed, ``first_evaluations`` Newton
    evaluations of every point and up to ``max_fast_passes`` evaluations in all of the points still
    running (the branch-free evaluator, the acceptance rule of ``solve_exact``); the rows, columns,
    states and CE counts come back to the host, where the points neither accepted nor rootless (an
    unusable evaluation, or still running) are finished by the numpy safeguarded iteration from their
    last iterate.  Same decisions as ``solve_exact(..., backend="numpy")``; on the CPU the same bits.

    Parameters
    ----------
    params : CollinearityParams
        The scene; it must fit the branch-free evaluator (:meth:`CollinearityParams.fixed_model`).
    ground : ndarray, shape (N, 3)
        Ground points, local ENU metres (``docs/conventions.md#frames``); float64 on the device.
    seed : SeedModel
        Polynomial row seed (plus optional row correction table).
    device : str or torch.device
        "cpu" (default) or "cuda" / "cuda:k" where available.
    chunk : int, optional
        Points per device pass (bounds device memory, about 0.6 kB per point at the peak); default
        16,384 on the CPU (one thread per op, see ``DEFAULT_CHUNK``) and 2,097,152 on CUDA.  Results
        do not depend on it.
    **options
        ``window, orient, tol, accept_step, max_iter`` and optionally ``max_fast_passes,
        first_evaluations`` (:class:`~explorer.geometry.kernels.NewtonOptions`, as ``solve_exact``); with
        ``max_fast_passes`` below ``first_evaluations`` every point goes to the (host) safeguarded
        iteration from its seed.

    Returns
    -------
    row, col : ndarray of float64, shape (N,)
        Fractional row and column (px, ``docs/conventions.md#pixels``); NaN where not converged.
    status : ndarray of int8, shape (N,)
        ``STATUS_*`` codes of :mod:`explorer.geometry.kernels`.
    ce : ndarray of int64, shape (N,)
        Collinearity evaluations per point.

    Raises
    ------
    ValueError
        For a device that is not "cpu" or an available CUDA device, a scene the branch-free
        evaluator does not cover, a bad ``chunk`` or ``first_evaluations``.
    """
    import torch

    dev = _resolve_device(device)
    o = NewtonOptions(**options)
    (w_lo, w_hi), orient, tol, accept_step = o.window, o.orient, o.tol, o.accept_step
    max_iter, max_fast_passes, first = o.max_iter, o.max_fast_passes, o.first_evaluations
    if chunk is None:
        chunk = DEFAULT_CHUNK[dev.type]
    if int(chunk) < 1:
        raise ValueError(f"chunk must be a positive number of points, got {chunk}")
    chunk = int(chunk)
    p = params
    fm = p.fixed_model(o.window)
    if fm is None:
        raise ValueError(
            "solve_exact_torch needs the branch-free collinearity evaluator, which does not cover this scene "
            "(CollinearityParams.fixed_model(window) is None: polynomials above degree 3, more than "
            f"{kernels.FIXED_MAX_TERMS} jitter / distortion / curvature terms, or angle increments too large over "
            "the window); use solve_exact on the CPU"
        )
    ground = np.ascontiguousarray(ground, dtype=np.float64)
    n = ground.shape[0]
    dt, ref, pitch, pc = p.line_period, p.reference_row, p.pitch, p.principal_column
    row = np.empty(n)
    col = np.empty(n)
    status = np.zeros(n, np.int8)  # STATUS_CONVERGED
    if max_fast_passes < first:  # no fast pass at all: the safeguarded iteration from the seed, as solve_exact
        ce = np.zeros(n, np.int64)
        rest = np.arange(n)
        start = seed.rows(ground)
    else:
        ce = np.empty(n, np.int64)
        ce_fixed, seed_full = _torch_kernels()
        fx = _device_args(fm.args(), dev)
        sx = _device_args(seed.args(), dev)
        rests, starts = [], []
        for lo in range(0, n, chunk):
            hi = min(lo + chunk, n)
            pts = torch.as_tensor(ground[lo:hi].T.copy(), dtype=torch.float64, device=dev)  # (3, m) rows X, Y, Z
            X, Y, Z = pts[0], pts[1], pts[2]
            rr = torch.clamp(seed_full(X, Y, Z, *sx), w_lo, w_hi)
            for step in range(first):
                g, gt, yd, ydt, vz = ce_fixed(X, Y, Z, (rr - ref) * dt, *fx, p.focal, p.offset)
                row_d, col_d, r, state = _newton_update_torch(
                    rr, g, gt, yd, ydt, vz, dt, pitch, pc, w_lo, w_hi, orient, accept_step
                )
                if step + 1 < first:
                    rr = torch.clamp(r, w_lo, w_hi)
            ce_d = torch.full((hi - lo,), first, dtype=torch.int32, device=dev)
            idx = torch.nonzero(state == _RUNNING).squeeze(1)
            k = first
            while idx.numel() and k < max_fast_passes:
                rr = torch.clamp(r[idx], w_lo, w_hi)
                g, gt, yd, ydt, vz = ce_fixed(X[idx], Y[idx], Z[idx], (rr - ref) * dt, *fx, p.focal, p.offset)
                row_d[idx], col_d[idx], r[idx], state[idx] = _newton_update_torch(
                    rr, g, gt, yd, ydt, vz, dt, pitch, pc, w_lo, w_hi, orient, accept_step
                )
                ce_d[idx] = k + 1
                k += 1
                idx = idx[state[idx] == _RUNNING]
            row[lo:hi] = row_d.cpu().numpy()
            col[lo:hi] = col_d.cpu().numpy()
            ce[lo:hi] = ce_d.cpu().numpy()
            state_h = state.cpu().numpy()
            pending = np.flatnonzero(state_h != _ACCEPTED)
            final = state_h[pending]
            no_root = lo + pending[final == _NO_ROOT]
            status[no_root] = STATUS_NO_ROOT_IN_WINDOW
            row[no_root] = np.nan
            col[no_root] = np.nan
            rest_local = pending[(final == _RUNNING) | (final == _TO_GENERAL)]
            if rest_local.size:
                rests.append(lo + rest_local)
                starts.append(r[torch.as_tensor(rest_local, device=dev)].cpu().numpy())
        rest = np.concatenate(rests) if rests else np.zeros(0, np.int64)
        start = np.concatenate(starts) if starts else np.zeros(0)
    if rest.size:
        r2, c2, s2, ce2 = _solve_exact_np(
            ground[rest], start, p, fm, True, w_lo, w_hi, orient, tol, accept_step, int(max_iter), np.zeros((0, 0))
        )
        row[rest] = r2
        col[rest] = c2
        status[rest] = s2
        ce[rest] += ce2
    return row, p.to_columns(col), status, ce
