"""Design advice (issue 21): rank the feasible designs by what the user minimises, refine the best ones off
the grid, give every design its probability of meeting the spec, and the trade-off (Pareto) front.

Objectives (``--minimise``, :data:`OBJECTIVES`): ``power`` (steady coil power V^2/R [W], the default),
``current`` (V/R [A]), ``diameter`` (D [mm]), ``filler`` (wt% [wt%]). Ranking: ascending objective, ties
broken by the larger probability, then the larger margin; with ``--min-probability p`` the designs whose
linearised probability reaches p come first (:func:`rank`). The refinement starts from the first designs
of that ranking and, with p > 0.5, meets a spec tightened by z sigma (:func:`robust_targets`: z =
Phi^-1(p), sigma the linearised relative standard deviation of each uncertain target's metric at the
start times the bound), so that
the refined design keeps (about) the probability p instead of sitting on the spec at 0.5.

Refinement (:func:`refine_task`): a local optimisation from a grid design with
``scipy.optimize.minimize(method="SLSQP")`` over the free axes of the space (a fixed axis stays fixed),
in scaled coordinates: (wt%, D) as the surfaces' own fit coordinates (log, scaled to [0, 1] over the
samples), gap and voltage scaled to [0, 1] over their ranges. Constraints:

* bounds: the space's ranges;
* the convex hull of the identified samples' (wt%, D) (:class:`Hull`, linear inequalities in the fit
  coordinates, where the surfaces' triangulation lives); a trial point of the optimiser outside it is
  evaluated where the segment from the start leaves the hull (continuous, so the finite differences work);
* the spec, on the smooth static metrics at the design (:func:`static_metrics`): current, power, blocked
  force, the static operating point as the stroke (no pull-in unless contact is allowed) and the
  small-signal bandwidth, as relative margins >= 0.

The step-response metrics (stroke at the end of the step, 2 % settling time, contact) are not smooth
enough for a gradient method; the optimiser's result is checked by the full evaluation
(:func:`harness.analysis.design.evaluate.evaluate_block`) and, if that misses the spec, moved back along
the segment to its (feasible) grid start by bisection (``BISECTIONS`` full evaluations) to the last point
that meets it. The segment lies in the hull (both ends do; the hull is convex) and the objective is
monotone along it, so the refined design is feasible, inside the hull and never worse than its start.

Probability of meeting the spec (:func:`linearised_probabilities`), for every design: the delta method.
The metrics m_t of the targets on stroke, blocked force, settling time and bandwidth are linearised in
the 5 x n_samples node parameters (Em, K1, K2, C, m of every identified sample): the design's parameters
depend on the nodes through the surfaces (weights w_i(wt%, D) of the Clough-Tocher interpolant, exactly
linear in the node values, here in their logarithms), the metrics on the design's parameters through
forward differences of the full evaluation (relative step ``FD_STEP``, all designs of one (D, gap) batched
in one evaluation). With the samples' covariances (independent between samples) this gives a Gaussian for
the targets' margins; P = Phi(mu/sigma) for one uncertain target, else the share of ``LIN_DRAWS`` draws of
that Gaussian (common random numbers: monotone in the spec) meeting all. Current and power do not depend
on the uncertain parameters (the coil is held at its mean, as in the Monte Carlo): met or not. Unless
contact is allowed, the clearance gap - stroke >= 0 and the static pull-in margin (pull-in current -
current >= 0) are two more uncertain targets (a design whose stroke ends close to the coil face, or near
pull-in, reaches the face under part of the draws; pull-in is a saddle-node, so the linearisation is rough
there: measured against Monte Carlo in ``benchmarks/bench_design_probability.py``). A design whose perturbed evaluation is
not finite (e.g. it stops settling) gets no linearised probability (None).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import minimize
from scipy.spatial import ConvexHull
from scipy.stats import norm

from harness.analysis.identification import generalize
from harness.analysis.design.evaluate import Block, bandwidth, evaluate_block, static_point
from harness.analysis.design.space import DesignError, Targets
from harness.sim.kernels import kernel

__all__ = ["OBJECTIVES", "OBJECTIVE_LABELS", "objective_key", "rank", "pareto_front", "Hull", "static_metrics",
           "smooth_margins", "refine_task", "node_weights", "jacobian_task", "linearised_probabilities",
           "uncertain_targets", "shortfalls", "robust_targets", "FD_STEP", "LIN_DRAWS", "BISECTIONS"]

_FIT = ("Em", "K1", "K2", "C", "m")
#: objective name -> the design's key (minimised)
OBJECTIVES = {"power": "power_W", "current": "current_A", "diameter": "diameter_mm", "filler": "wt_pct"}
OBJECTIVE_LABELS = {"power": "coil power [W]", "current": "coil current [A]", "diameter": "diameter D [mm]",
                    "filler": "filler fraction [wt%]"}
FD_STEP = 1e-3          # relative step of the forward differences of the metrics in Em, K1, K2, C, m
LIN_DRAWS = 4096        # draws of the linearised Gaussian (two or more uncertain targets)
BISECTIONS = 10         # full evaluations moving a refined design back towards its start


def objective_key(name: str) -> str:
    """The design key minimised for ``--minimise name``; :class:`DesignError` naming the option otherwise."""
    if name not in OBJECTIVES:
        raise DesignError(f"--minimise must be one of {', '.join(OBJECTIVES)}, got {name!r}")
    return OBJECTIVES[name]


def _score(p) -> float:
    return -1.0 if p is None or not math.isfinite(p) else float(p)


def rank(rows: list, objective: str, min_probability: float = 0.0) -> list:
    """The designs (dicts) sorted: those whose linearised probability reaches ``min_probability`` first, each
    group by ascending objective, then larger linearised probability, then larger margin."""
    key = objective_key(objective)
    return sorted(rows, key=lambda r: (_score(r.get("probability_linearised")) < min_probability, r[key],
                                       -_score(r.get("probability_linearised")), -r["margin_pct"]))


def pareto_front(objective, score) -> np.ndarray:
    """Indices of the non-dominated points (objective minimised, score maximised), by ascending objective:
    a point is kept when its score exceeds that of every point with a smaller (or equal, listed before it)
    objective."""
    obj = np.asarray(objective, dtype=float)
    sc = np.nan_to_num(np.asarray(score, dtype=float), nan=-np.inf)
    order = np.lexsort((-sc, obj))
    keep, best = [], -np.inf
    for i in order:
        if sc[i] > best:
            keep.append(int(i))
            best = sc[i]
    return np.array(keep, dtype=int)


# ============================================================================ the hull
@dataclass(frozen=True)
class Hull:
    """The convex hull of the identified samples' (wt%, D) in the surfaces' fit coordinates q (log if the
    fits are, scaled to [0, 1] over the samples): inside when A q + b <= 0 (every row)."""
    lo: np.ndarray
    span: np.ndarray
    log: bool
    A: np.ndarray
    b: np.ndarray

    @classmethod
    def from_fits(cls, fits) -> "Hull":
        P = np.column_stack([fits.wt_pct, fits.diameter_mm]).astype(float)
        if fits.log_coords:
            P = np.log(P)
        lo, span = P.min(axis=0), P.max(axis=0) - P.min(axis=0)
        Q = (P - lo) / span
        eq = ConvexHull(Q).equations
        return cls(lo, span, bool(fits.log_coords), eq[:, :2], eq[:, 2])

    def scaled(self, wt_pct, diameter_mm) -> np.ndarray:
        P = np.column_stack(np.broadcast_arrays(np.asarray(wt_pct, float), np.asarray(diameter_mm, float)))
        return ((np.log(P) if self.log else P) - self.lo) / self.span

    def unscaled(self, q) -> tuple[float, float]:
        P = np.asarray(q, float) * self.span + self.lo
        P = np.exp(P) if self.log else P
        return float(P[0]), float(P[1])

    def slack(self, q) -> np.ndarray:
        """-(A q + b): >= 0 inside (distance to each edge, in fit coordinates)."""
        return -(self.A @ np.asarray(q, float) + self.b)

    def diameter_span(self, wt_pct: float) -> tuple[float, float] | None:
        """(lo, hi) diameter_mm [mm] of the hull at ``wt_pct`` [wt%] (its edges are straight in the fit
        coordinates, so curved in (wt%, D) when those are logarithmic); None if no D is inside at that wt%."""
        c = ((math.log(wt_pct) if self.log else float(wt_pct)) - self.lo[0]) / self.span[0]
        lo, hi = -np.inf, np.inf
        for (a0, a1), b in zip(self.A, self.b):
            r = -(b + a0 * c)                               # a1 qd <= r
            if abs(a1) < 1e-12:
                if r < -1e-9:
                    return None
            elif a1 > 0:
                hi = min(hi, r / a1)
            else:
                lo = max(lo, r / a1)
        if not lo <= hi + 1e-9:
            return None
        return self.unscaled([c, lo])[1], self.unscaled([c, hi])[1]


# ============================================================================ the smooth model
def static_metrics(fits, coil: dict, design: tuple) -> dict:
    """Smooth metrics of one design (wt% [wt%], D [mm], gap [mm], V [V]): current_A, power_W, blocked_force_N,
    static_stroke_m (the static operating point; the gap when pulled in), pulled (bool), bandwidth_Hz."""
    w, d, g, V = (float(v) for v in design)
    p = {k: np.array([v]) for k, v in generalize.predict(fits, w, d).items()}
    r0 = g / 1e3
    G = kernel(coil["a"], d / 1e3, coil["kB"], r0)
    I = np.array([V / coil["R"]])
    EmI2 = p["Em"] * I ** 2
    x, pulled = static_point(G, r0, EmI2, p["K1"], p["K2"])
    bw = 0.0 if pulled[0] else float(bandwidth(G, r0, x, I, p, coil["R"], coil["L"])[0])
    return {"current_A": float(I[0]), "power_W": float(V * I[0]), "blocked_force_N": float(EmI2[0] * G.eval(np.array([r0]))[0]),
            "static_stroke_m": float(x[0]), "pulled": bool(pulled[0]), "bandwidth_Hz": bw}


def smooth_margins(targets: Targets, m: dict) -> np.ndarray:
    """Relative margins (>= 0: met) of the targets on the smooth metrics ``m`` (:func:`static_metrics`); the
    stroke counts -1 when pulled in and contact is not allowed."""
    r = []
    if targets.stroke_mm is not None:
        ok = targets.allow_contact or not m["pulled"]
        r.append(m["static_stroke_m"] * 1e3 / targets.stroke_mm - 1 if ok else -1.0)
    return np.array(r + targets.bound_margins(m), dtype=float)


def _full(fits, coil, design, st) -> dict:
    """The full evaluation (step response included) of one design (wt%, D mm, gap mm, V)."""
    w, d, g, V = design
    p = {k: np.array([v]) for k, v in generalize.predict(fits, w, d).items()}
    b = Block(a_m=coil["a"], kB_T_per_A=coil["kB"], R_Ohm=coil["R"], L_H=coil["L"], D_m=d / 1e3, gap_m=g / 1e3,
              V_V=np.array([V]), params=p, t_step_s=st.t_step_s, dt_s=st.dt_s)
    return {k: v[0] for k, v in evaluate_block(b).items()}


def _fits_of(nodes):
    return generalize.fit_surfaces([(w, d, dict(v)) for w, d, v in nodes])


class _Problem:
    """The scaled variables of one refinement: x = (q_wt, q_D, gap, V), each 0-1 over its range (q: the
    hull's fit coordinates); z = x at the free axes."""

    def __init__(self, fits, space, start):
        self.hull = Hull.from_fits(fits)
        axes = space.axes
        self.free = [k for k, a in enumerate(axes) if a.n > 1 and a.hi > a.lo]
        qlo = self.hull.scaled(axes[0].lo, axes[1].lo)[0]
        qhi = self.hull.scaled(axes[0].hi, axes[1].hi)[0]
        self.lo = np.array([qlo[0], qlo[1], axes[2].lo, axes[3].lo])
        self.hi = np.array([qhi[0], qhi[1], axes[2].hi, axes[3].hi])
        self.start = tuple(float(v) for v in start)
        self.x0 = self.x_of(self.start)

    def x_of(self, des) -> np.ndarray:
        q = self.hull.scaled(des[0], des[1])[0]
        x = np.array([q[0], q[1], des[2], des[3]], float)
        x[2:] = np.where(self.hi[2:] > self.lo[2:], (x[2:] - self.lo[2:]) / np.where(self.hi[2:] > self.lo[2:],
                                                                                      self.hi[2:] - self.lo[2:], 1), 0)
        return x

    def full(self, z) -> np.ndarray:
        x = self.x0.copy()
        x[self.free] = z
        return x

    def design(self, z) -> tuple:
        """(wt%, D mm, gap mm, V) at z; (wt%, D) pulled back towards the start onto the hull if outside."""
        x = self.full(z)
        q = self._pull(x[:2])
        w, d = self.hull.unscaled(q)
        w = w if 0 in self.free else self.start[0]
        d = d if 1 in self.free else self.start[1]
        g, V = (self.lo[2:] + x[2:] * (self.hi[2:] - self.lo[2:])).tolist()
        return (w, d, g, V)

    def _pull(self, q) -> np.ndarray:
        q0 = self.x0[:2]
        rate = self.hull.A @ (q - q0)
        room = np.maximum(self.hull.slack(q0), 0.0)
        t = np.min(np.where(rate > 0, room / np.where(rate > 0, rate, 1.0), np.inf))
        return q0 + min(1.0, t) * (q - q0)

    def bounds(self) -> list:
        return [(self.lo[k], self.hi[k]) if k < 2 else (0.0, 1.0) for k in self.free]


def refine_task(args) -> dict:
    """One refinement (module docstring). args = (nodes [(wt%, D mm, {name: SI})], coil {a, kB, R, L},
    targets, space, start (wt%, D mm, gap mm, V), objective name, settings (t_step_s, dt_s)).
    Returns {"start", "design": (wt%, D mm, gap mm, V), "metrics": full metrics, "moved": bool, "optimizer": text}."""
    nodes, coil, targets, space, start, objective, st = args
    fits = _fits_of(nodes)
    pb = _Problem(fits, space, start)
    key = OBJECTIVES[objective]
    index = {"wt_pct": 0, "diameter_mm": 1, "current_A": 3, "power_W": 3}[key]
    start_m = _full(fits, coil, pb.start, st)
    start_obj = _objective(key, pb.start, start_m)
    out = {"start": pb.start, "design": pb.start, "metrics": start_m, "moved": False}
    if index not in pb.free:
        return dict(out, optimizer="not refined: the objective's axis is fixed")
    j = pb.free.index(index)
    hull_free = 0 in pb.free or 1 in pb.free

    def f(z):
        return z[j] * z[j] if key == "power_W" else z[j]

    def cons(z):
        c = smooth_margins(targets, static_metrics(fits, coil, pb.design(z)))
        return np.concatenate([pb.hull.slack(pb.full(z)[:2]), c]) if hull_free else c

    z0 = pb.x0[pb.free]
    bnd = pb.bounds()
    res = minimize(f, z0, method="SLSQP", bounds=bnd, constraints=[{"type": "ineq", "fun": cons}],
                   options={"maxiter": 100, "ftol": 1e-10, "eps": 1e-6})
    z1 = np.clip(res.x, [b[0] for b in bnd], [b[1] for b in bnd])
    ok_t, bad_t = 0.0, None
    for _ in range(BISECTIONS + 1):
        t = 1.0 if bad_t is None else 0.5 * (ok_t + bad_t)
        des = pb.design(z0 + t * (z1 - z0))
        try:
            m = _full(fits, coil, des, st)
        except generalize.GeneralizationError:
            m = None
        if (m is not None and bool(targets.met({k: np.array([v]) for k, v in m.items()})[0])
                and _objective(key, des, m) <= start_obj):
            ok_t = t
            out.update(design=des, metrics=m, moved=True)
            if bad_t is None:
                break
        else:
            bad_t = t
        if bad_t - ok_t < 2.0 ** -BISECTIONS:
            break
    return dict(out, optimizer=f"SLSQP: {res.message} ({res.nit} iterations); {ok_t:.4g} of the step kept")


def _objective(key, des, m) -> float:
    return {"wt_pct": des[0], "diameter_mm": des[1]}.get(key, m.get(key))


# ============================================================================ linearised probability
def node_weights(nodes, wt_pct, diameter_mm) -> np.ndarray:
    """(n_designs, n_nodes) weights w_i of the surfaces at the designs: an interpolated log value is
    sum_i w_i log(value_i) (the Clough-Tocher interpolant is linear in the node values; found by fitting
    log Em = unit vectors on the same nodes)."""
    out = []
    for i in range(len(nodes)):
        unit = [(w, d, {k: (math.e if j == i else 1.0) for k in _FIT}) for j, (w, d, _) in enumerate(nodes)]
        out.append(np.log(generalize.predict_arrays(_fits_of(unit), wt_pct, diameter_mm)["Em"]))
    return np.stack(out, axis=-1)


def uncertain_targets(targets: Targets) -> list:
    """[(metric key, threshold SI, sign)]: met when sign * (metric - threshold) >= 0 (the targets whose metric
    depends on the uncertain parameters)."""
    out = []
    if targets.stroke_mm is not None:
        out.append(("stroke_m", targets.stroke_mm / 1e3, 1.0))
    if targets.blocked_force_N is not None:
        out.append(("blocked_force_N", targets.blocked_force_N, 1.0))
    if targets.settling_ms is not None:
        out.append(("settling_s", targets.settling_ms / 1e3, -1.0))
    if targets.min_bandwidth_Hz is not None:
        out.append(("bandwidth_Hz", targets.min_bandwidth_Hz, 1.0))
    return out


def jacobian_task(args) -> dict:
    """Metrics and their derivatives in the design's Em, K1, K2, C, m for designs sharing (D, gap).
    args = (coil, D_m, gap_m, V (n,), params {name: (n,)}, settings). Returns {"nominal": {metric: (n,)},
    "d": {metric: (n, 5)}} (forward differences, relative step ``FD_STEP``; absolute FD_STEP for a zero)."""
    coil, D_m, gap_m, V, par, st = args
    n = V.size
    reps = {k: [np.asarray(par[k], float)] for k in _FIT}
    steps = []
    for j, k in enumerate(_FIT):
        h = np.where(np.abs(par[k]) > 0, FD_STEP * np.abs(par[k]), FD_STEP)
        steps.append(h)
        for q, kk in enumerate(_FIT):
            reps[kk].append(np.asarray(par[kk], float) + (h if q == j else 0.0))
    b = Block(a_m=coil["a"], kB_T_per_A=coil["kB"], R_Ohm=coil["R"], L_H=coil["L"], D_m=D_m, gap_m=gap_m,
              V_V=np.tile(V, 6), params={k: np.concatenate(v) for k, v in reps.items()}, t_step_s=st.t_step_s,
              dt_s=st.dt_s)
    m = evaluate_block(b)
    nominal = {k: np.asarray(v)[:n] for k, v in m.items()}
    d = {}
    for k in ("stroke_m", "blocked_force_N", "settling_s", "bandwidth_Hz", "pull_in_current_A"):
        v = np.asarray(m[k], float).reshape(6, n)
        with np.errstate(invalid="ignore"):
            d[k] = np.stack([(v[1 + j] - v[0]) / steps[j] for j in range(5)], axis=1)
    return {"nominal": nominal, "d": d}


def linearised_probabilities(targets: Targets, nominal: dict, d: dict, dtheta: np.ndarray, cov: np.ndarray,
                             seed: int = 0, sd_out: dict | None = None) -> np.ndarray:
    """P(spec) of n designs by the delta method (module docstring).

    nominal: {metric: (n,)} (current_A and power_W included; with gap_m [m] and contact not allowed, the
    clearance gap - stroke >= 0 and, with pull_in_current_A, the pull-in margin I_pull-in - I >= 0 are more
    uncertain targets: a draw ending on the coil face fails, as in the Monte Carlo); d: {metric: (n, 5)}
    derivatives in the design's
    (Em, K1, K2, C, m); dtheta: (n, 5, n_nodes) derivatives of the design's parameters in the nodes' (same
    parameter); cov: (n_nodes, 5, 5) the nodes' covariances. Returns (n,) probabilities (NaN: not finite).
    sd_out: if given, filled with {metric: (n,) standard deviation of the metric [its SI unit]} of the
    uncertain targets' metrics.
    """
    n = dtheta.shape[0]
    det = np.ones(n, bool)
    if targets.max_current_A is not None:
        det &= nominal["current_A"] <= targets.max_current_A
    if targets.max_power_W is not None:
        det &= nominal["power_W"] <= targets.max_power_W
    ut = uncertain_targets(targets)
    mus = [s * (np.asarray(nominal[k], float) - thr) for k, thr, s in ut]
    grads = [s * d[k] for k, _, s in ut]
    names = [k for k, _, _ in ut]
    if not targets.allow_contact and "gap_m" in nominal:        # clearance to the coil face, gap - stroke >= 0
        mus.append(np.asarray(nominal["gap_m"], float) - np.asarray(nominal["stroke_m"], float))
        grads.append(-d["stroke_m"])
        names.append("clearance_m")
        if "pull_in_current_A" in nominal:                      # no static pull-in: I_pull-in - I >= 0
            mus.append(np.asarray(nominal["pull_in_current_A"], float) - np.asarray(nominal["current_A"], float))
            grads.append(d["pull_in_current_A"])
            names.append("pull_in_current_A")
    if not mus:
        return det.astype(float)
    mu = np.stack(mus, axis=1)                                                                       # (n, T)
    # gradient in the node parameters: (n, T, nodes, 5)
    g = np.stack(grads, axis=1)[:, :, None, :] * np.transpose(dtheta, (0, 2, 1))[:, None]
    S = np.einsum("ntia,iab,nuib->ntu", g, cov, g)                                                  # (n, T, T)
    finite = np.isfinite(mu).all(axis=1) & np.isfinite(S).all(axis=(1, 2))
    if sd_out is not None:
        sd_out.update({k: np.sqrt(np.abs(S[:, t, t])) for t, k in enumerate(names)})
    mu = np.where(np.isfinite(mu), mu, 0.0)
    S = np.where(np.isfinite(S), S, 0.0)
    T = mu.shape[1]
    if T == 1:
        sd = np.sqrt(S[:, 0, 0])
        with np.errstate(divide="ignore", invalid="ignore"):
            p = np.where(sd > 0, norm.cdf(mu[:, 0] / np.where(sd > 0, sd, 1.0)), (mu[:, 0] >= 0).astype(float))
    else:
        z = np.random.default_rng(seed).standard_normal((LIN_DRAWS, T))
        p = np.empty(n)
        for a in range(0, n, 256):
            Sb = S[a:a + 256] + np.eye(T) * 1e-300
            w, U = np.linalg.eigh(Sb)                                   # S = U diag(w) U^T (S may be singular)
            L = U * np.sqrt(np.maximum(w, 0.0))[:, None, :]
            x = mu[a:a + 256, None, :] + np.einsum("dt,nut->ndu", z, L)
            p[a:a + 256] = (x >= 0).all(axis=2).mean(axis=1)
    return np.where(finite, p * det, np.nan)


def shortfalls(targets: Targets, row: dict) -> list:
    """The targets a design (a row: metrics in SI) misses: [(option, value, limit, unit)] in the option's unit
    (e.g. ("--stroke-mm", 0.62, 1.0, "mm")); contact as ("--allow-contact", 1, 0, "contact")."""
    out = []
    checks = (("--stroke-mm", targets.stroke_mm, row["stroke_m"] * 1e3, 1, "mm"),
              ("--blocked-force-N", targets.blocked_force_N, row["blocked_force_N"], 1, "N"),
              ("--settling-ms", targets.settling_ms, row["settling_s"] * 1e3, -1, "ms"),
              ("--max-current-A", targets.max_current_A, row["current_A"], -1, "A"),
              ("--max-power-W", targets.max_power_W, row["power_W"], -1, "W"),
              ("--min-bandwidth-Hz", targets.min_bandwidth_Hz, row["bandwidth_Hz"], 1, "Hz"))
    for opt, lim, val, sign, unit in checks:
        if lim is not None and not (sign * (val - lim) >= 0):
            out.append((opt, float(val), float(lim), unit))
    if not targets.allow_contact and row["contact"]:
        out.append(("--allow-contact", 1.0, 0.0, "contact"))
    return out


def robust_targets(targets: Targets, sd_rel: dict, p_min: float) -> Targets:
    """The spec tightened so that a design meeting it has each uncertain target met with probability about
    p_min under the linearisation: every bound on stroke, blocked force, bandwidth (minimum) raised and on the
    settling time (maximum) lowered by z sigma, z = Phi^-1(p_min), sigma = sd_rel x the bound (sd_rel: {metric:
    the metric's standard deviation / its value} at a design, e.g. the refinement's start: the relative
    spread, which changes little between nearby designs). p_min <= 0.5 or no sd: the spec itself."""
    z = float(norm.ppf(p_min)) if p_min > 0 else -np.inf
    if z <= 0:
        return targets
    f = {k: 1.0 + z * float(sd_rel.get(k, 0.0)) for k in ("stroke_m", "blocked_force_N", "bandwidth_Hz", "settling_s")}
    return replace(targets,
                   stroke_mm=None if targets.stroke_mm is None else targets.stroke_mm * f["stroke_m"],
                   blocked_force_N=None if targets.blocked_force_N is None else targets.blocked_force_N * f["blocked_force_N"],
                   min_bandwidth_Hz=None if targets.min_bandwidth_Hz is None else targets.min_bandwidth_Hz * f["bandwidth_Hz"],
                   settling_ms=None if targets.settling_ms is None else targets.settling_ms / f["settling_s"])
