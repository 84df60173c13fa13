"""The Levenberg-Marquardt training of a network with ONE hidden layer, compiled whole (numba): the trainer of
``bpnn`` and ``nn-rfm`` (:class:`explorer.methods.bpnn.MLPRegressor` and its subclasses).

The same algorithm, stopping rules and results as :func:`explorer.methods._lm.lm_minimise` called the way
:meth:`~explorer.methods.bpnn.MLPRegressor._levenberg_marquardt` calls it (sum of squared errors plus
``lambda |theta|^2``, MATLAB's ``trainlm`` damping, validation failures counted on ties, the plateau rule), but
one compiled call for the whole training instead of some thirty torch operations per epoch: at 42 weights and 200
errors an epoch cost 0.27 ms of per-operation overhead in torch for some 0.04 ms of arithmetic.  The normal
equations come from ONE product of the columns every output shares (:func:`_normal_equations`): an output's errors
depend only on the hidden layer's weights (shared, through that output's weights ``W2[o, :]``) and on that output's
own weights (its row of the output layer, its bias and its linear terms, whose columns are the same for every
output), so ``J^T J`` is a product ``M^T M`` of N x (S + H + 1 + F) columns scaled by the output weights -- half the
products of one ``J_o^T J_o`` per output with two outputs (bpnn, nn-rfm: 29-32 % less CPU per epoch at 300-1000
points), and exactly that product with one output (mlp, ann).  The hidden layer and the errors are one pass over the
points, the product's scratch is allocated once per training.
The damped system is solved by Cholesky (least squares if it is not positive definite), as in
:func:`explorer.methods._lm._damped_step`.  The sums are in another order than torch's: the trained weights
agree with the torch trainer's to round-off over a few epochs and then drift as any two LM trainings started
from round-off-different points do (tests/methods/test_lm_compiled.py); same inputs, same bits, run to run.

The network: ``y_o = sum_j W2[o, j] h_j + b2[o] + sum_f L[o, f] F_f`` with ``h_j =
act(sum_i W1[j, i] X_i + b1[j])`` (``act`` the logistic sigmoid or tanh), parameters laid out as ``W1`` (H, I)
row-major, ``b1`` (H), ``W2`` (O, H) row-major, ``b2`` (O), ``L`` (O, F) row-major -- the flat layout of
:func:`explorer.methods._lm.dense_layers` followed by the line-of-sight network's linear terms (F = 0: none).
Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

import numpy as np

from explorer._numba import NUMBA_AVAILABLE, njit

__all__ = ["NUMBA_AVAILABLE", "STOP_REASONS", "lm_one_hidden", "train_one_hidden"]

#: The stop reasons of :func:`lm_one_hidden` by code (those of :func:`explorer.methods._lm.lm_minimise`).
STOP_REASONS = ("max_epochs", "non_finite", "goal", "mu_max", "validation", "plateau", "min_grad")


@njit(cache=True)
def _sse(theta, x, feats, target, n_hidden, tanh, lam):  # pragma: no cover - compiled
    """Sum of squared errors ``target - outputs`` plus ``lam |theta|^2``, the errors (N, O) and the hidden
    activations (N, H) of the network (module docstring), computed in one pass over the points."""
    n, n_in = x.shape
    n_out, n_feat = target.shape[1], feats.shape[1]
    b0 = n_hidden * n_in
    s0 = b0 + n_hidden  # where the output layer starts
    w2, b2, lin = s0, s0 + n_out * n_hidden, s0 + n_out * n_hidden + n_out
    h = np.empty((n, n_hidden))
    e = np.empty((n, n_out))
    s = 0.0
    for k in range(n):
        for j in range(n_hidden):
            z = theta[b0 + j]
            for i in range(n_in):
                z += theta[j * n_in + i] * x[k, i]
            h[k, j] = np.tanh(z) if tanh else 1.0 / (1.0 + np.exp(-z))
        for o in range(n_out):
            v = theta[b2 + o]
            for j in range(n_hidden):
                v += theta[w2 + o * n_hidden + j] * h[k, j]
            for f in range(n_feat):
                v += theta[lin + o * n_feat + f] * feats[k, f]
            d = target[k, o] - v
            e[k, o] = d
            s += d * d
    if lam != 0.0:
        s += lam * np.dot(theta, theta)
    return s, e, h


@njit(cache=True)
def _normal_work(x, feats, n_hidden, n_out):  # pragma: no cover - compiled
    """The scratch (S + H + 1 + F, N) :func:`_normal_equations` builds ``M`` transposed in, allocated once per
    training."""
    n, n_in = x.shape
    return np.empty((n_hidden * n_in + 2 * n_hidden + 1 + feats.shape[1], n))


@njit(cache=True)
def _normal_equations(theta, x, feats, err, h, tanh, lam, work):  # pragma: no cover - compiled
    """``J^T J`` (P, P) and ``J^T e - lam theta`` (P,) of the errors ``err`` (N, O) and hidden activations ``h``
    (N, H) at ``theta``, from ONE product of the columns every output shares.

    Output ``o``'s derivative by a hidden-layer weight of node ``j`` is ``W2[o, j]`` times a column ``a_j x_i``
    (``a_j`` the activation's derivative, ``x_i`` an input or 1 for the bias) that does not depend on ``o``, and its
    derivatives by its own weights are the columns ``h_j``, 1 and ``F_f``, the same for every output.  So with
    ``M`` the N x (S + H + 1 + F) matrix of those columns (S hidden-layer weights) and ``G = M^T M``, ``J^T J`` is
    ``sum_o W2[o, j] W2[o, j'] G`` on the hidden layer's block, ``W2[o, j] G`` between it and output ``o``'s own
    weights and ``G`` on each output's own block (zero between two outputs' own weights); ``J^T e`` likewise from
    ``M^T e``.  The products are those of the per-output Jacobians ``J_o`` up to the order of the factors
    (round-off), at one product of M's columns instead of one per output.  With one output its weights are kept in
    M's columns (M's block is ``J`` itself, the per-output products exactly).  ``work``: (S + H + 1 + F, N) scratch
    for ``M`` transposed (:func:`_normal_work`), overwritten."""
    n, n_in = x.shape
    n_hidden = h.shape[1]
    n_out, n_feat = err.shape[1], feats.shape[1]
    p = theta.size
    s = n_hidden * n_in + n_hidden
    w2, b2, lin = s, s + n_out * n_hidden, s + n_out * n_hidden + n_out
    own = n_hidden + 1 + n_feat  # an output's own columns
    mt = work  # M transposed: one row per column, contiguous over points
    deriv = n_hidden * n_in  # the rows of a_j (the hidden biases' columns)
    for j in range(n_hidden):
        w = theta[w2 + j] if n_out == 1 else 1.0  # one output: its weight in the column, M's block is J's
        for k in range(n):
            hj = h[k, j]
            mt[deriv + j, k] = w * ((1.0 - hj * hj) if tanh else hj * (1.0 - hj))
            mt[s + j, k] = hj
        for i in range(n_in):
            for k in range(n):
                mt[j * n_in + i, k] = mt[deriv + j, k] * x[k, i]
    for k in range(n):
        mt[s + n_hidden, k] = 1.0
    for f in range(n_feat):
        for k in range(n):
            mt[s + n_hidden + 1 + f, k] = feats[k, f]
    g = np.dot(mt, mt.T)
    r = np.empty((mt.shape[0], n_out))  # M^T e
    for o in range(n_out):
        r[:, o] = np.dot(mt, np.ascontiguousarray(err[:, o]))
    node = np.empty(s, np.int64)  # the hidden node of each hidden-layer column
    for c in range(s):
        node[c] = c // n_in if c < deriv else c - deriv
    wt = np.ones((n_out, n_hidden))  # the output weights still to apply (one output: already in M)
    if n_out > 1:
        for o in range(n_out):
            for j in range(n_hidden):
                wt[o, j] = theta[w2 + o * n_hidden + j]
    product = np.zeros((p, p))
    rhs = np.empty(p)
    for a in range(s):
        ja = node[a]
        for b in range(a + 1):  # G's lower triangle, as the Cholesky factorisation reads the product's
            jb = node[b]
            w = 0.0
            for o in range(n_out):
                w += wt[o, ja] * wt[o, jb]
            v = w * g[a, b]
            product[a, b] = v
            product[b, a] = v
        t = 0.0
        for o in range(n_out):
            t += wt[o, ja] * r[a, o]
        rhs[a] = t
    for o in range(n_out):
        for q in range(own):
            cq = (w2 + o * n_hidden + q if q < n_hidden
                  else (b2 + o if q == n_hidden else lin + o * n_feat + q - n_hidden - 1))
            for a in range(s):
                v = wt[o, node[a]] * g[s + q, a]
                product[a, cq] = v
                product[cq, a] = v
            for q2 in range(q, own):
                cq2 = (w2 + o * n_hidden + q2 if q2 < n_hidden
                       else (b2 + o if q2 == n_hidden else lin + o * n_feat + q2 - n_hidden - 1))
                product[cq, cq2] = g[s + q2, s + q]
                product[cq2, cq] = g[s + q2, s + q]
            rhs[cq] = r[s + q, o]
    if lam != 0.0:
        for c in range(p):
            rhs[c] -= lam * theta[c]
    return product, rhs


@njit(cache=True)
def _damped_step(product, rhs, damping):  # pragma: no cover - compiled
    """Solution of ``(product + damping I) d = rhs``: Cholesky, least squares if not positive definite."""
    p = rhs.size
    a = product.copy()
    for c in range(p):
        a[c, c] += damping
    low = np.zeros((p, p))
    ok = True
    for j in range(p):
        s = a[j, j]
        for k in range(j):
            s -= low[j, k] * low[j, k]
        if not s > 0.0:  # also NaN
            ok = False
            break
        d = np.sqrt(s)
        low[j, j] = d
        for i in range(j + 1, p):
            t = a[i, j]
            for k in range(j):
                t -= low[i, k] * low[j, k]
            low[i, j] = t / d
    if not ok:
        return np.linalg.lstsq(a, rhs)[0]
    y = np.empty(p)
    for i in range(p):
        t = rhs[i]
        for k in range(i):
            t -= low[i, k] * y[k]
        y[i] = t / low[i, i]
    sol = np.empty(p)
    for i in range(p - 1, -1, -1):
        t = y[i]
        for k in range(i + 1, p):
            t -= low[k, i] * sol[k]
        sol[i] = t / low[i, i]
    return sol


@njit(cache=True)
def _objective(theta, x, feats, target, n_hidden, tanh, lam, mean):  # pragma: no cover - compiled
    """The training objective (:func:`_sse`'s sum, or with ``mean`` the mean squared error, plus ``lam |theta|^2``),
    the errors (N, O) and the hidden activations (N, H)."""
    if not mean:
        return _sse(theta, x, feats, target, n_hidden, tanh, lam)
    s, e, h = _sse(theta, x, feats, target, n_hidden, tanh, 0.0)
    s = s / e.size if e.size else np.nan  # torch.mean of no element is NaN
    if lam != 0.0:
        s += lam * np.dot(theta, theta)
    return s, e, h


@njit(cache=True)
def _jacobian(theta, x, feats, h, tanh, n_out):  # pragma: no cover - compiled
    """The full Jacobian ``d outputs / d theta`` (N O, P) at ``theta``, row ``k O + o`` for output ``o`` of point
    ``k`` (the order of the errors flattened row-major, as the torch trainer flattens them)."""
    n, n_in = x.shape
    n_hidden = h.shape[1]
    n_feat = feats.shape[1]
    s = n_hidden * n_in + n_hidden
    w2, b2, lin = s, s + n_out * n_hidden, s + n_out * n_hidden + n_out
    jac = np.zeros((n * n_out, theta.size))
    for k in range(n):
        for o in range(n_out):
            r = k * n_out + o
            for j in range(n_hidden):
                hj = h[k, j]
                d = theta[w2 + o * n_hidden + j] * ((1.0 - hj * hj) if tanh else hj * (1.0 - hj))
                for i in range(n_in):
                    jac[r, j * n_in + i] = d * x[k, i]
                jac[r, n_hidden * n_in + j] = d
                jac[r, w2 + o * n_hidden + j] = hj
            jac[r, b2 + o] = 1.0
            for f in range(n_feat):
                jac[r, lin + o * n_feat + f] = feats[k, f]
    return jac


@njit(cache=True)
def _train(theta0, x, feats, target, x_val, feats_val, target_val, n_hidden, tanh, lam, max_epochs, mu, mu_dec,
           mu_inc, mu_max, goal, max_fail, window, tol, mean, min_grad, fail_on_tie, count_initial,
           allow_dual):  # pragma: no cover - compiled
    """:func:`train_one_hidden` (its documentation), also returning the histories."""
    validate = x_val.shape[0] > 0
    theta = theta0.copy()
    perf, err, hid = _objective(theta, x, feats, target, n_hidden, tanh, lam, mean)
    n_err = err.size
    dual = allow_dual and lam == 0.0 and theta.size > n_err  # the N x N form, as the torch trainer
    best_theta = theta.copy()
    best_epoch = 0
    work = _normal_work(x, feats, n_hidden, err.shape[1])
    v0 = _objective(theta, x_val, feats_val, target_val, n_hidden, tanh, 0.0, mean)[0] if validate else np.nan
    best_val = v0 if count_initial else np.inf
    fails = 0
    hist = np.empty(max_epochs + 1)
    hist_val = np.empty(max_epochs + 1)
    hist_mu = np.empty(max_epochs + 1)
    hist[0], hist_val[0], hist_mu[0] = perf, v0, mu
    stop, done, started = 0, 0, 0
    for epoch in range(1, max_epochs + 1):
        if not np.isfinite(perf):
            stop = 1
            break
        if perf <= goal:
            stop = 2
            break
        started = epoch
        if dual:
            jac = _jacobian(theta, x, feats, hid, tanh, err.shape[1])
            e_flat = np.ascontiguousarray(err).reshape(-1)
            grad = np.dot(jac.T, e_flat)
            product, rhs = np.dot(jac, jac.T), e_flat
        else:
            product, rhs = _normal_equations(theta, x, feats, err, hid, tanh, lam, work)
            grad = rhs + lam * theta if lam != 0.0 else rhs
        if min_grad > 0.0 and np.sqrt(np.dot(2.0 * grad, 2.0 * grad)) / n_err < min_grad:
            stop, started = 6, epoch - 1
            break
        improved = False
        while mu <= mu_max:
            if dual:
                cand = theta + np.dot(jac.T, _damped_step(product, rhs, mu))
            else:
                cand = theta + _damped_step(product, rhs, mu + lam)
            cperf, cerr, chid = _objective(cand, x, feats, target, n_hidden, tanh, lam, mean)
            if np.isfinite(cperf) and cperf < perf:
                theta, err, perf, hid = cand, cerr, cperf, chid
                mu = max(mu * mu_dec, 1e-20)
                improved = True
                break
            mu *= mu_inc
        if not improved:
            stop = 3
            break
        done = epoch
        hist[epoch] = perf
        hist_mu[epoch] = mu
        if not validate:
            hist_val[epoch] = np.nan
            best_theta, best_epoch = theta.copy(), epoch
        else:
            v = _objective(theta, x_val, feats_val, target_val, n_hidden, tanh, 0.0, mean)[0]
            hist_val[epoch] = v
            if v < best_val:
                best_theta, best_val, best_epoch = theta.copy(), v, epoch
                fails = 0
            elif v > best_val or fail_on_tie:
                fails += 1
                if fails >= max_fail:
                    stop = 4
                    break
        if window >= 1 and done >= window:  # the objective fell by less than tol over the last window epochs
            ref = hist[done - window]
            if ref - perf <= tol * ref:
                stop = 5
                break
    train_best = _objective(best_theta, x, feats, target, n_hidden, tanh, lam, mean)[0]
    val_best = np.nan
    if validate:
        val_best = _objective(best_theta, x_val, feats_val, target_val, n_hidden, tanh, 0.0, mean)[0]
    return (best_theta, done, best_epoch, stop, max(started, done), train_best, val_best, perf,
            hist[:done + 1].copy(), hist_val[:done + 1].copy(), hist_mu[:done + 1].copy())


@njit(cache=True)
def lm_one_hidden(theta0, x, feats, target, x_val, feats_val, target_val, n_hidden, tanh, lam, max_epochs, mu,
                  mu_dec, mu_inc, mu_max, goal, max_fail, window, tol):  # pragma: no cover - compiled
    """Train the network (module docstring) by Levenberg-Marquardt the way ``bpnn`` / ``nn-rfm`` do:
    :func:`explorer.methods._lm.lm_minimise` with ``mean=False``, ``weight_decay=lam``, ``min_grad=0``,
    ``fail_on_tie=True``, ``count_initial_validation=False`` and ``plateau=(window, tol)`` (``window < 1``: no
    plateau rule), always the ``J^T J`` form (the caller only calls it with at least as many errors as weights); no
    validation when ``x_val`` has no row (:func:`train_one_hidden` with those options).

    Returns
    -------
    tuple
        The first nine results of :func:`train_one_hidden` (``theta`` ... ``history``: not the validation and
        damping histories), its errors sums of squares.
    """
    r = _train(theta0, x, feats, target, x_val, feats_val, target_val, n_hidden, tanh, lam, max_epochs, mu, mu_dec,
               mu_inc, mu_max, goal, max_fail, window, tol, False, 0.0, True, False, False)
    return r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8]


@njit(cache=True)
def train_one_hidden(theta0, x, feats, target, x_val, feats_val, target_val, n_hidden, tanh, lam, max_epochs, mu,
                     mu_dec, mu_inc, mu_max, goal, max_fail, window, tol, mean, min_grad, fail_on_tie,
                     count_initial):  # pragma: no cover - compiled
    """Train the network (module docstring) by Levenberg-Marquardt: :func:`explorer.methods._lm.lm_minimise` with
    every option it has for these networks.

    ``mean``: the objective (and the validation error, the goal, the gradient test) is the mean of the squared
    errors, else their sum (the step does not depend on it); ``lam``: weight decay (``lam |theta|^2`` added to the
    objective and to the normal equations); ``min_grad``: stop when ``|2 J^T e| / n < min_grad`` (``n`` errors; 0:
    no test); ``fail_on_tie``: a validation error equal to the best counts as a failure; ``count_initial``: the
    initial parameters' validation error is the first best (else infinity); ``window < 1``: no plateau rule.  With
    more weights than errors and no weight decay the step is the torch trainer's dual form
    ``d = J^T (J J^T + mu I)^-1 e`` (an n x n system; :func:`explorer.methods._lm._damped_step`), else
    ``(J^T J + (mu + lam) I) d = J^T e - lam theta``.  No validation when ``x_val`` has no row.

    Returns
    -------
    theta : ndarray (P,)
        The parameters with the best validation error (the last accepted ones without validation).
    done, best_epoch, stop, iterations : int
        Accepted epochs, the epoch of ``theta``, the stop code (:data:`STOP_REASONS`), epochs started.
    train_best, val_best, final_objective : float
        Objective and validation error of ``theta``, objective of the last accepted step.
    history, validation, mu : ndarray (done + 1,)
        The objective, the validation error (NaN without validation) and the damping at the start and after each
        epoch.
    """
    return _train(theta0, x, feats, target, x_val, feats_val, target_val, n_hidden, tanh, lam, max_epochs, mu,
                  mu_dec, mu_inc, mu_max, goal, max_fail, window, tol, mean, min_grad, fail_on_tie, count_initial,
                  True)
