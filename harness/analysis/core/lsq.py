"""Batched Levenberg-Marquardt: several independent box-bounded least-squares problems in lock-step.

Each problem i minimizes the cost ``r_i(x) @ r_i(x)`` (a chi-square when the residuals are divided by
their noise) over a box ``lo <= x <= hi``. The residual vectors come from one *batch evaluator*
``residuals(points) -> vectors`` called with a list of ``(problem index, x)`` points, so that every
point of an iteration (trial steps and forward-difference Jacobian columns of every problem) is
evaluated in one call: one simulation batch serves all problems (``harness.analysis.diagnosis``).

Numerics: forward-difference Jacobians (step ``fd[j]``, backward where a forward step would leave the
box), bounds by projection (a solution on a bound is close to, not exactly at, the constrained optimum).
Each iteration evaluates, in one batch, three damped steps (damping
x0.1, x1, x10 of the current lambda, Marquardt scaling by diag(J^T J)) and the Jacobian at the
middle one (used at once if that step is taken). A problem stops when its cost falls by less than
``ftol`` relative or ``atol`` absolute in an accepted step, or when its damping exceeds 1e8.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from threadpoolctl import ThreadpoolController

from harness.analysis.core import cpu_clock


@dataclass(frozen=True)
class SharedParam:
    """A parameter shared by the runs of a fit (a catalogue effect's, a discovered term's), as the fit sees it.

    ``key`` (name in the fit), ``effect`` (catalogue effect or term name), ``unit`` (of the natural value),
    ``log`` (fitted as its natural logarithm), box bounds ``lo``/``hi`` and finite-difference step ``fd`` (in the
    fitted scale), start value ``init`` (fitted scale) and a ``description``.
    """
    key: str
    effect: str
    unit: str
    log: bool
    lo: float
    hi: float
    fd: float
    init: float
    description: str
    #: standard uncertainty (fitted scale) of a Gaussian prior about ``init`` (what the data told before the fit,
    #: e.g. a loop radius derived from T7), added to the fit's residuals as (value - init) / prior_sd; None: none
    prior_sd: float | None = None

    def natural(self, v: float) -> float:
        """The natural value (unit ``self.unit``) of the fitted value ``v``."""
        return math.exp(v) if self.log else float(v)

#: batch evaluator: [(problem index, x)] -> [residual vector of each point] (same order)
BatchResiduals = Callable[[Sequence[tuple]], list]


class LsqError(ValueError):
    """A least-squares problem is malformed (shapes or bounds)."""


class ResidualLayoutError(AssertionError):
    """A defect of the code, not of the data: a problem's residual vector changed its length (or layout)
    between two parameter points. A residual lives on the measured grid, in windows chosen from the data
    alone, so its length is fixed per dataset whatever the parameters; every least-squares step relies on it."""


def check_length(label: str, expected: int, got: int) -> None:
    """Raise :class:`ResidualLayoutError` naming ``label`` when a residual vector has ``got`` entries where
    the problem's first one had ``expected``."""
    if got != expected:
        raise ResidualLayoutError(f"{label}: residual vector of {got} entries where the problem's first had "
                                  f"{expected} (a residual's length must not depend on the parameters)")


@dataclass(frozen=True)
class BoxProblem:
    """A box-bounded least-squares problem: start ``x0``, bounds ``lo``/``hi``, finite-difference steps ``fd``
    (all 1-D arrays of the same length, in the units of x); ``label`` names it in error messages (e.g. the
    sample and the parameters fitted)."""
    x0: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    fd: np.ndarray
    label: str = ""

    def __post_init__(self):
        arrs = [np.asarray(getattr(self, k), dtype=float) for k in ("x0", "lo", "hi", "fd")]
        if any(a.ndim != 1 or a.size != arrs[0].size for a in arrs):
            raise LsqError("x0, lo, hi and fd must be 1-D arrays of the same length")
        if np.any(arrs[1] > arrs[2]):
            raise LsqError("lower bound above upper bound")
        if np.any(arrs[3] <= 0):
            raise LsqError("finite-difference steps fd must be > 0")
        for k, a in zip(("x0", "lo", "hi", "fd"), arrs):
            object.__setattr__(self, k, a)


@dataclass(frozen=True)
class LMSettings:
    """Stopping rules of :func:`levenberg_marquardt`: at most ``max_iter`` iterations; a problem stops
    when an accepted step lowers its cost by less than ``ftol`` x cost or ``atol`` (cost units); no new
    iteration starts after ``deadline_s`` (an instant [s] of the CPU clock :func:`harness.analysis.core.cpu_clock.now`,
    so that the budget does not depend on the machine's load; None: no time limit)."""
    max_iter: int = 25
    ftol: float = 1e-4
    atol: float = 2.0
    deadline_s: float | None = None

    def __post_init__(self):
        if self.max_iter < 0 or self.ftol < 0 or self.atol < 0:
            raise LsqError("max_iter, ftol and atol must be >= 0")


#: why a problem stopped (``LMResult.stop``): converged (ftol/atol), damping above 1e8 (no step lowers the cost:
#: a minimum or a flat direction), the iteration limit, the time limit
STOPS = ("converged", "damping", "max_iter", "time_budget")


@dataclass(frozen=True)
class LMResult:
    """Solution of one problem: ``x``, ``cost`` = r @ r at x, ``jacobian`` (at the last linearization
    point; None when the last accepted step had none), the residual vector ``residual`` at x, the
    ``iterations`` it took and why it stopped (``stop``, one of :data:`STOPS`)."""
    x: np.ndarray
    cost: float
    jacobian: np.ndarray | None
    residual: np.ndarray
    iterations: int = 0
    stop: str = "converged"

    @property
    def cut_short(self) -> bool:
        """True when the problem stopped on a limit (iterations or time), not at a minimum."""
        return self.stop in ("max_iter", "time_budget")


def _columns(p: BoxProblem, x: np.ndarray) -> list:
    """Forward-difference points [(column, step, x + step e_j)] (backward where forward leaves the box)."""
    out = []
    for j in range(x.size):
        hstep = p.fd[j] if x[j] + p.fd[j] <= p.hi[j] else -p.fd[j]
        xp = x.copy()
        xp[j] += hstep
        out.append((j, hstep, xp))
    return out


def _assemble(r0: np.ndarray, cols: list, vecs: list, label: str = "") -> np.ndarray:
    Jm = np.empty((r0.size, len(cols)))
    for (j, hstep, _), v in zip(cols, vecs):
        check_length(f"{label} (Jacobian column {j})", r0.size, np.size(v))
        Jm[:, j] = (v - r0) / hstep
    return np.nan_to_num(Jm, nan=0.0, posinf=0.0, neginf=0.0)   # a diverged column carries no information


_BLAS = None     # threadpoolctl's controller of the BLAS libraries (made on first use)


def one_blas_thread():
    """Context manager: BLAS on one thread (the callers already run one process per core)."""
    global _BLAS
    if _BLAS is None:
        _BLAS = ThreadpoolController()
    return _BLAS.limit(limits=1, user_api="blas")


def _normal_equations(J: np.ndarray, r: np.ndarray) -> tuple:
    """(J^T J, J^T r, the floored diagonal of J^T J) of a linearization: computed once per iteration, shared
    by the damped steps of its trial dampings."""
    with one_blas_thread():
        A = J.T @ J
        g = J.T @ r
    dA = np.maximum(np.diag(A), 1e-12 * max(float(np.max(np.diag(A))), 1e-300))
    return A, g, dA


def _damped_step(normal: tuple, lam: float) -> np.ndarray | None:
    """Solve (J^T J + lam diag(J^T J)) d = -J^T r (normal = ``_normal_equations(J, r)``); None when the
    step is not finite."""
    A, g, dA = normal
    M = A + lam * np.diag(dA)
    try:
        d = -np.linalg.solve(M, g)
    except np.linalg.LinAlgError:
        d = -np.linalg.lstsq(M, g, rcond=None)[0]
    return d if np.all(np.isfinite(d)) else None


def _label(problems, i: int) -> str:
    return problems[i].label or f"least-squares problem {i}"


#: the most points per residual batch while a deadline is set: the deadline is checked between batches (a
#: lock-step iteration of 19 discovery terms was 500 simulations and 50 CPU-s: the former check before each
#: iteration let a diagnosis with a 75 CPU-s budget run to 172 CPU-s)
BUDGET_CHUNK = 64
#: a batch is sized to cost at most this share of the CPU time left before the deadline, at the dearest cost per
#: point measured so far in the fit: batches shrink as the deadline nears, so that the batch that passes it is
#: small (64 points of a 1539 Hz, four-sample dataset cost 45 CPU-s: a diagnosis with a 75 CPU-s budget ran
#: to 123 CPU-s when the deadline fell early in such a batch)
BUDGET_BATCH_SHARE = 0.25
#: points in a fit's first timed batch when nothing has been measured yet (its start points cost nothing that
#: could be measured: e.g. all cached)
BUDGET_FIRST_CHUNK = 8


class _Pace:
    """Batch sizes of a fit with a CPU-clock deadline ``deadline_s`` [s]: at most :data:`BUDGET_CHUNK` points, at
    least one, and no more than :data:`BUDGET_BATCH_SHARE` of the time left at the dearest cost per point
    measured so far (:data:`BUDGET_FIRST_CHUNK` points until a cost was measured)."""

    def __init__(self, deadline_s: float):
        self.deadline_s = float(deadline_s)
        self.s_per_point = 0.0        # [s] the dearest measured CPU cost of one point

    def timed(self, residuals: BatchResiduals, pts: list) -> list:
        """``residuals(pts)`` in one batch, its CPU cost per point recorded."""
        if not pts:
            return []
        t0 = cpu_clock.now()
        out = residuals(pts)
        self.s_per_point = max(self.s_per_point, (cpu_clock.now() - t0) / len(pts))
        return out

    def size(self, now_s: float) -> int:
        """Points in the next batch when the clock reads ``now_s`` [s]."""
        if self.s_per_point <= 0.0:
            return BUDGET_FIRST_CHUNK
        share = BUDGET_BATCH_SHARE * (self.deadline_s - now_s) / self.s_per_point
        return int(min(max(share, 1.0), BUDGET_CHUNK))


def _within_budget(residuals: BatchResiduals, pts: list, pace: _Pace | None):
    """``residuals(pts)``: in one batch without a deadline (``pace`` None), else in batches sized by ``pace``;
    None when the CPU-clock deadline passes before the last batch (the points evaluated so far are dropped)."""
    if pace is None:
        return residuals(pts) if pts else []
    out, k = [], 0
    while k < len(pts):
        now_s = cpu_clock.now()
        if now_s > pace.deadline_s:
            return None
        m = pace.size(now_s)
        out += pace.timed(residuals, pts[k:k + m])
        k += m
    return out


def levenberg_marquardt(problems: Sequence[BoxProblem], residuals: BatchResiduals,
                        settings: LMSettings = LMSettings()) -> list:
    """Solve several independent box-bounded least-squares problems in lock-step.

    Parameters
    ----------
    problems : sequence of BoxProblem
        The problems (x in any units; the cost is r @ r in the squared units of the residuals).
    residuals : callable
        Batch evaluator: ``residuals([(i, x), ...])`` returns the residual vector of problem ``i`` at
        ``x`` for every point, in order. Called once per iteration with every point of every active
        problem (plus once at the start and once per Jacobian that a rejected step left missing); while
        ``settings.deadline_s`` is set, in batches with the deadline checked between them, each of at most
        :data:`BUDGET_CHUNK` points and sized to cost no more than :data:`BUDGET_BATCH_SHARE` of the time left
        (a deadline passed between two batches ends the fit where it was, ``stop`` "time_budget").
    settings : LMSettings
        Iteration limit and stopping tolerances.

    Returns
    -------
    list of LMResult
        One per problem, in order.
    """
    n = len(problems)
    x = [np.clip(p.x0.astype(float), p.lo, p.hi) for p in problems]
    if settings.deadline_s is not None and cpu_clock.now() > settings.deadline_s:
        # the budget is spent: the start point's residuals only (no Jacobian: its columns cost a simulation each)
        r = [np.nan_to_num(ri, nan=1e6, posinf=1e6, neginf=-1e6) for ri in residuals([(i, x[i]) for i in range(n)])]
        return [LMResult(x=x[i], cost=float(r[i] @ r[i]), jacobian=None, residual=r[i], iterations=0,
                         stop="time_budget") for i in range(n)]
    pace = None if settings.deadline_s is None else _Pace(settings.deadline_s)
    cols0 = [_columns(problems[i], x[i]) for i in range(n)]
    col_pts = [(i, xp) for i in range(n) for _, _, xp in cols0[i]]
    if pace is None:                         # one batch: the start points and their Jacobians' columns
        vecs = residuals([(i, x[i]) for i in range(n)] + col_pts)
        starts, vecs = vecs[:n], vecs[n:]
    else:                                    # the start points first: a result even if the budget cuts the rest
        starts = pace.timed(residuals, [(i, x[i]) for i in range(n)])
        vecs = _within_budget(residuals, col_pts, pace)
    r = [np.nan_to_num(ri, nan=1e6, posinf=1e6, neginf=-1e6) for ri in starts]
    cost = [float(ri @ ri) for ri in r]
    if vecs is None:
        # the budget ran out while the start's Jacobian was computed: the start point only
        return [LMResult(x=x[i], cost=cost[i], jacobian=None, residual=r[i], iterations=0, stop="time_budget")
                for i in range(n)]
    J, pos = [], 0
    for i in range(n):
        k = len(cols0[i])
        J.append(_assemble(r[i], cols0[i], vecs[pos:pos + k], _label(problems, i)))
        pos += k
    lam = [1e-2] * n
    active = [True] * n
    stop = ["max_iter"] * n
    iters = [0] * n
    for _ in range(settings.max_iter):
        act = [i for i in range(n) if active[i]]
        if not act:
            break
        if settings.deadline_s is not None and cpu_clock.now() > settings.deadline_s:
            for i in act:
                stop[i] = "time_budget"
            break
        for i in act:
            iters[i] += 1
        need = [i for i in act if J[i] is None]
        if need:
            cl = {i: _columns(problems[i], x[i]) for i in need}
            vv = _within_budget(residuals, [(i, xp) for i in need for _, _, xp in cl[i]], pace)
            if vv is None:
                for i in act:
                    stop[i] = "time_budget"
                    iters[i] -= 1          # the iteration did not take place
                break
            pos = 0
            for i in need:
                k = len(cl[i])
                J[i] = _assemble(r[i], cl[i], vv[pos:pos + k], _label(problems, i))
                pos += k
        trials, pts = [], []
        for i in act:
            normal = _normal_equations(J[i], r[i])
            for mult in (0.1, 1.0, 10.0):
                d = _damped_step(normal, lam[i] * mult)
                if d is None:
                    continue
                xt = np.clip(x[i] + d, problems[i].lo, problems[i].hi)
                cl = _columns(problems[i], xt) if mult == 1.0 else []
                trials.append((i, mult, xt, cl, len(pts)))
                pts.append((i, xt))
                pts += [(i, xp) for _, _, xp in cl]
        vecs = _within_budget(residuals, pts, pace)
        if vecs is None:
            for i in act:
                stop[i] = "time_budget"
                iters[i] -= 1
            break
        best = {}
        for i, mult, xt, cl, p0 in trials:
            v = vecs[p0]
            check_length(_label(problems, i), r[i].size, np.size(v))
            c = float(v @ v) if np.all(np.isfinite(v)) else math.inf
            if math.isfinite(c) and (i not in best or c < best[i][0]):
                best[i] = (c, mult, xt, v, cl, p0)
        for i in act:
            if i in best and best[i][0] < cost[i]:
                c, mult, xt, v, cl, p0 = best[i]
                dec = cost[i] - c
                x[i], r[i] = xt, v
                J[i] = _assemble(v, cl, vecs[p0 + 1:p0 + 1 + len(cl)], _label(problems, i)) if cl else None
                lam[i] = max(lam[i] * mult / 3.0, 1e-8)
                if dec < max(settings.ftol * cost[i], settings.atol):
                    active[i] = False
                    stop[i] = "converged"
                cost[i] = c
            else:
                lam[i] *= 100.0
                if lam[i] > 1e8:
                    active[i] = False
                    stop[i] = "damping"
    return [LMResult(x=x[i], cost=cost[i], jacobian=J[i], residual=r[i], iterations=iters[i], stop=stop[i])
            for i in range(n)]


def jacobian(problem: BoxProblem, x: np.ndarray, residuals: Callable[[list], list]) -> tuple:
    """Forward-difference Jacobian of one problem at ``x`` (backward where a forward step leaves the box).

    ``residuals(xs) -> [vector]`` evaluates the problem at a list of points (called twice: at x, then at
    every column's point in one batch). Returns ``(J, r)``: J of shape (r.size, x.size), r = residual at x.
    """
    x = np.asarray(x, dtype=float)
    r = residuals([x])[0]
    cols = _columns(problem, x)
    vecs = residuals([xp for _, _, xp in cols])
    J = np.empty((r.size, x.size))
    for (j, h, _), v in zip(cols, vecs):
        check_length(f"{problem.label or 'least-squares problem'} (Jacobian column {j})", r.size, np.size(v))
        J[:, j] = (v - r) / h
    return J, r
