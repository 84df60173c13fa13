"""Three-stage best scanline determination with a GA-optimised global polynomial: ``ogp``.

Ahooei Nezhad, Valadan Zoej, Ghorbanian (2021), Adv. Space Res. 68:3584-3593, as
summarised in Remote Sensing 16:2787 (2024): after the affine approximation and the
approximate exposure time (stages 1-2, :class:`explorer.methods.ann.ThreeStageMethod`),
the scanline error is modelled by a global polynomial of up to fifth degree in the
approximate image coordinates whose terms a genetic algorithm selects ("the OGP model
utilized a fifth-degree polynomial and Genetic algorithm to compress the model").

Here a chromosome is a binary mask over the ``(d + 1)(d + 2) / 2`` monomials
``u_r^i u_c^j`` (``i + j <= max_degree``) of the normalised approximate (row, column);
its fitness is the validation RMSE (pixels) of the least-squares polynomial on those
terms -- trained on 70 % of the SCOPs, validated on the other 30 % (seeded split) --
plus ``complexity_penalty_px`` per term.  The GA (seeded numpy generator) uses
tournament selection, uniform crossover, bit-flip mutation and elitism; the chosen
terms are finally fitted by least squares on all SCOPs.  The column comes from the
collinearity at the final row.  Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from explorer._threads import blas_threads
from explorer.methods._lm import check_split_sizes, split_train_validation
from explorer.methods.ann import REFERENCE_2021, ThreeStageMethod
from explorer.methods.base import register
from explorer.methods.mlp import network_verdict
from explorer.methods.regression import design_matrix, monomial_exponents, qr_least_squares


def genetic_term_selection(
    design_train: np.ndarray,
    target_train: np.ndarray,
    design_val: np.ndarray,
    target_val: np.ndarray,
    *,
    seed: int,
    population: int = 40,
    generations: int = 40,
    crossover_rate: float = 0.9,
    mutation_rate: float | None = None,
    tournament: int = 3,
    elite: int = 2,
    complexity_penalty: float = 1e-4,
    initial: list[np.ndarray] | None = None,
) -> tuple[np.ndarray, float, dict]:
    """Select columns of a design matrix by a binary genetic algorithm.

    Parameters
    ----------
    design_train, target_train : ndarray (N, K), (N,)
        Candidate terms and target of the training points.
    design_val, target_val : ndarray (M, K), (M,)
        The same for the validation points.
    seed : int
        Seeds the numpy generator: the same inputs and seed select the same terms.
    population, generations : int
    crossover_rate : float
        Probability that a child mixes two parents (uniform crossover).
    mutation_rate : float, optional
        Per-bit flip probability (default ``1 / K``).
    tournament : int
        Tournament size of the selection.
    elite : int
        Best chromosomes copied unchanged into the next generation.
    complexity_penalty : float
        Added to the validation RMSE per selected term (target units).
    initial : list of bool ndarray (K,), optional
        Chromosomes placed in the first population (the rest is random).

    Returns
    -------
    mask : ndarray of bool, shape (K,)
        Best chromosome found.
    fitness : float
        Its fitness.
    info : dict
        ``val_rmse``, ``best_fitness_per_generation``, ``evaluations``.
    """
    k_all = design_train.shape[1]
    n_train = design_train.shape[0]
    rng = np.random.default_rng(seed)
    pm = 1.0 / k_all if mutation_rate is None else float(mutation_rate)
    cache: dict[bytes, tuple[float, float]] = {}

    def fitness(mask: np.ndarray) -> tuple[float, float]:
        key = np.packbits(mask).tobytes()
        if key in cache:
            return cache[key]
        k = int(mask.sum())
        if k == 0:
            rmse = float(np.sqrt(np.mean(target_val**2)))
        elif k > n_train:
            rmse = np.inf
        else:
            coef, *_ = np.linalg.lstsq(design_train[:, mask], target_train, rcond=None)
            rmse = float(np.sqrt(np.mean((design_val[:, mask] @ coef - target_val) ** 2)))
        out = (rmse + complexity_penalty * k, rmse)
        cache[key] = out
        return out

    with blas_threads(1):  # hundreds of small solves: OpenBLAS's threads cost 25x here on a busy machine
        return _evolve(fitness, rng, k_all, pm, population=population, generations=generations,
                       crossover_rate=crossover_rate, tournament=tournament, elite=elite, initial=initial,
                       cache=cache)


def _evolve(fitness: Callable[[np.ndarray], tuple[float, float]], rng: np.random.Generator, k_all: int, pm: float,
            *, population: int, generations: int, crossover_rate: float, tournament: int, elite: int,
            initial: list[np.ndarray] | None, cache: dict) -> tuple[np.ndarray, float, dict]:
    """The generations of :func:`genetic_term_selection` (its parameters; ``fitness`` cached in ``cache``)."""
    pop = rng.random((population, k_all)) < 0.5
    for j, chrom in enumerate(initial or []):
        if j < population:
            pop[j] = chrom
    history = []
    for _ in range(generations):
        fit = np.array([fitness(c)[0] for c in pop])
        order = np.argsort(fit, kind="stable")
        history.append(float(fit[order[0]]))
        new = [pop[i].copy() for i in order[:elite]]
        while len(new) < population:
            parents = []
            for _ in range(2):
                contenders = rng.integers(0, population, tournament)
                parents.append(pop[contenders[np.argmin(fit[contenders])]])
            if rng.random() < crossover_rate:
                pick = rng.random(k_all) < 0.5
                child = np.where(pick, parents[0], parents[1])
            else:
                child = parents[0].copy()
            child ^= rng.random(k_all) < pm
            new.append(child)
        pop = np.array(new)
    fit = np.array([fitness(c)[0] for c in pop])
    best = pop[int(np.argmin(fit))].copy()
    # the best ever seen (elitism keeps it in the population, the cache remembers it)
    best_fit, best_rmse = fitness(best)
    return best, best_fit, {
        "val_rmse": best_rmse, "best_fitness_per_generation": history, "evaluations": len(cache),
    }


@register
class OGPMethod(ThreeStageMethod):
    """``ogp``: affine approximation + GA-selected global polynomial error model (Adv. Space Res. 2021).

    Parameters
    ----------
    scene : Scene
    max_degree : int
        Highest total degree of the candidate monomials (default 5: 21 terms).
    population, generations : int
        GA size (default 40 x 40, well under a second).
    crossover_rate, tournament, elite
        GA operators (0.9, 3, 2); mutation flips each bit with probability 1/21.
    complexity_penalty_px : float
        Fitness penalty per selected term, pixels (1e-4: a term must lower the
        validation RMSE by 1e-4 px to be kept).
    max_val_rmse_px : float
        A model whose validation RMSE exceeds this missed its accuracy goal (1.0 px): ``fit_info["converged"]``
        False, one log line, the map's title; its best model still answers (as ``mlp``).
    use_height, seed, train_fraction, domain_margin, height_tolerance_m
        See :class:`explorer.methods.ann.ThreeStageMethod`.
    """

    name = "ogp"
    label = "OGP-BSD"
    reference = REFERENCE_2021
    EXTRA = {
        "max_degree": 5, "population": 40, "generations": 40, "crossover_rate": 0.9,
        "tournament": 3, "elite": 2, "complexity_penalty_px": 1e-4, "max_val_rmse_px": 1.0,
    }

    def _fit_error_model(self, u: np.ndarray, dr: np.ndarray) -> None:
        p = self.params
        deg = int(p["max_degree"])
        if not 1 <= deg <= 5:
            raise ValueError(f"ogp: max_degree must lie in 1..5, got {deg}")
        exps = monomial_exponents(2, deg)
        tr, va = split_train_validation(u.shape[0], float(p["train_fraction"]), int(p["seed"]))
        check_split_sizes(self.name, u.shape[0], tr.size, va.size, 2)
        a = design_matrix(u, exps)
        initial = [np.array([e.sum() <= d for e in exps]) for d in range(1, deg + 1)]
        initial = [m for m in initial if m.sum() <= tr.size]
        mask, fit, ga = genetic_term_selection(
            a[tr], dr[tr], a[va], dr[va], seed=int(p["seed"]), population=int(p["population"]),
            generations=int(p["generations"]), crossover_rate=float(p["crossover_rate"]),
            tournament=int(p["tournament"]), elite=int(p["elite"]),
            complexity_penalty=float(p["complexity_penalty_px"]), initial=initial,
        )
        self.exponents = exps[mask]
        if mask.any():
            self.coef, cond = qr_least_squares(a[:, mask], dr, self.name)
        else:
            self.coef, cond = np.zeros(0), 1.0
        res = (a[:, mask] @ self.coef if mask.any() else 0.0) - dr
        self.fit_info.update({
            "candidate_terms": exps.tolist(),
            "selected_terms": self.exponents.tolist(),
            "n_terms": int(mask.sum()),
            "coefficients": self.coef.tolist(),
            "condition_number": cond,
            "fitness": fit,
            "val_rmse_px": ga["val_rmse"],
            "train_rmse_px": float(np.sqrt(np.mean(np.square(res)))),
            "ga_best_fitness": ga["best_fitness_per_generation"],
            "ga_evaluations": ga["evaluations"],
            "n_train": int(tr.size),
            "n_val": int(va.size),
            "stop_reason": "generations" if np.isfinite(fit) else "non_finite",
            "epochs": int(p["generations"]),
        })
        network_verdict(self.name, self.fit_info, float(p["max_val_rmse_px"]), "its best model is used")

    def _predict_error(self, u: np.ndarray) -> np.ndarray:
        if self.exponents.shape[0] == 0:
            return np.zeros(u.shape[0])
        out = np.empty(u.shape[0])
        step = 1 << 17
        for s in range(0, u.shape[0], step):
            out[s:s + step] = design_matrix(u[s:s + step], self.exponents) @ self.coef
        return out
