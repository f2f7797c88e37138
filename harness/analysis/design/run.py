"""Inverse design: from targets to the feasible region of (wt%, D, gap, voltage) (``mpc-actuator design``),
and design advice (:mod:`harness.analysis.design.advice`).

1. Surfaces: the identified samples' Em, K1, K2, C, m fitted over (wt%, D)
   (:func:`harness.analysis.identification.generalize.fit_surfaces`); the coil (a, kB, R, L): the samples' mean.
   The surfaces do not extrapolate: a wt% or D of the grid outside the samples' range is refused
   (:class:`DesignError` naming the point and the hull); the grid's (wt%, D) outside the samples' convex
   hull (taken in the surfaces' log coordinates, so its edges curve in (wt%, D)) are left out, and if none is
   inside, the job is refused with the hull's D span at the first wt% of the grid.
2. Nominal sweep: every design of the grid through :func:`harness.analysis.design.evaluate.evaluate_block`,
   one Dask task per (D, gap) (all wt% x V of that pair: one force kernel per task),
   :mod:`harness.analysis.core.sweep`.
3. Every feasible design gets its linearised (delta-method) probability of meeting the spec
   (:func:`harness.analysis.design.advice.linearised_probabilities`; one Dask task per (D, gap) for the
   metrics' derivatives) and the designs are ranked by ``settings.objective`` (``--minimise``).
4. Refinement: the ``settings.refine`` best grid designs are refined off the grid
   (:func:`harness.analysis.design.advice.refine_task`, one Dask task each) against the spec tightened to
   keep ``settings.min_probability`` (:func:`harness.analysis.design.advice.robust_targets`); a refined
   design that moved joins the candidates (source "refined"; one equal to another refined design at three
   significant digits is dropped) with its own linearised probability.
5. Monte-Carlo check: the first ``max_candidates`` of the ranking get ``n_draws`` draws of every
   identified sample's parameters (:meth:`harness.analysis.identification.parameter_uncertainty.ParameterUncertainty.draws`, one
   generator per sample seeded from (seed, sample id)), one surface fit per draw, the candidates evaluated
   under each; that probability is the share of draws meeting the spec (its binomial standard error is
   reported). The coil is held at its mean (its standard uncertainty is about 1e-4 relative).
6. The trade-off front: the candidates not dominated in (objective minimised, linearised probability
   maximised) (:func:`harness.analysis.design.advice.pareto_front`).

When no design of the grid meets the spec, nothing is refined: the ``NEAREST`` designs with the largest
(least negative) margin are returned with their probabilities as ``nearest`` (the report lists them with
what they miss).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from harness.analysis.identification import generalize
from harness.analysis.design import advice
from harness.analysis.design.evaluate import METRICS, Block, evaluate_block
from harness.analysis.design.space import Axis, DesignError, DesignSpace, Targets
from harness.analysis.core.sweep import ClusterSettings, cluster_client, run_tasks
from harness.analysis.identification.parameter_uncertainty import PARAMS
from harness.analysis.uncertainty.run import sample_rng

__all__ = ["DesignSettings", "DesignResult", "surface_model", "nominal_params", "design", "default_space", "block_task",
           "linearised", "monte_carlo", "NEAREST"]

_FIT = ("Em", "K1", "K2", "C", "m")
NEAREST = 10            # designs listed when none meets the spec


@dataclass(frozen=True)
class DesignSettings:
    """Settings of the inverse design.

    Parameters
    ----------
    n_draws : int
        Parameter draws per candidate for the Monte-Carlo probability of meeting the spec.
    seed : int
        Random seed of the draws.
    max_candidates : int
        Candidates (first of the ranking) given a Monte-Carlo probability.
    t_step_s : float
        Step-response duration [s].
    dt_s : float
        Its output period [s].
    objective : str
        What is minimised: ``power``, ``current``, ``diameter`` or ``filler``.
    refine : int
        Grid designs (best first) refined off the grid (0: none).
    min_probability : float
        The linearised probability of meeting the spec a recommended design must reach (ranked first; the
        refinement keeps it, see :func:`harness.analysis.design.advice.robust_targets`).
    """
    n_draws: int = 32
    seed: int = 0
    max_candidates: int = 200
    t_step_s: float = 0.5
    dt_s: float = 1e-3
    objective: str = "power"
    refine: int = 5
    min_probability: float = 0.95

    def __post_init__(self):
        advice.objective_key(self.objective)
        if not 0 <= self.min_probability < 1:
            raise DesignError(f"--min-probability must be in [0, 1), got {self.min_probability!r}")
        if not (self.n_draws >= 1 and self.max_candidates >= 0 and self.t_step_s > 0 and self.dt_s > 0
                and self.refine >= 0):
            raise DesignError(f"invalid design settings {self!r}")


@dataclass
class DesignResult:
    """space, targets; metrics: {name: array of space.shape}; feasible: bool array (nominal);
    candidates: list of dicts (feasible designs, grid and refined, with metrics, margin and probabilities,
    ranked by the objective); hull: text of the identified samples' ranges; settings; front: indices into
    candidates of the trade-off front (objective vs linearised probability), by ascending objective;
    nearest: when nothing is feasible, the designs of the largest margin (dicts like candidates); outside_hull:
    the grid's (wt%, D) points outside the identified samples' hull, left out (metrics NaN there)."""
    space: DesignSpace
    targets: Targets
    metrics: dict
    feasible: np.ndarray
    candidates: list
    hull: str
    settings: DesignSettings
    front: list = field(default_factory=list)
    nearest: list = field(default_factory=list)
    outside_hull: int = 0

    @property
    def evaluated(self) -> int:
        """Designs of the grid evaluated: those whose (wt%, D) lies inside the hull."""
        n_wd = self.space.wt_pct.n * self.space.diameter_mm.n
        return self.space.size // n_wd * (n_wd - self.outside_hull)

def surface_model(training: dict):
    """(SurfaceFits of the identified samples, coil {a, kB, R, L}) from {id: ParameterUncertainty}."""
    if len(training) < 3:
        raise DesignError(f"the design needs at least 3 identified samples spanning (wt%, D), got {len(training)}")
    fits = generalize.fit_surfaces([(u.wt_pct, u.diameter_mm, u.params) for u in training.values()])
    ps = [u.params for u in training.values()]
    coil = {k: float(np.mean([getattr(p, k) for p in ps])) for k in ("a", "kB", "R", "L")}
    return fits, coil


def nominal_params(fits, space: DesignSpace) -> dict:
    """{name: (n_wt, n_D) array} of Em, K1, K2, C, m on the grid, NaN at the (wt%, D) outside the identified
    samples' hull (left out of the design; the default grid, the samples' bounding box, reaches outside the hull
    unless they fill it). :class:`DesignError` (one line) when a wt% or D of the grid lies outside the samples'
    range or when no (wt%, D) of the grid lies inside the hull."""
    W, D = space.wt_pct.values, space.diameter_mm.values
    for name, vals, samples in (("wt_pct", W, fits.wt_pct), ("diameter_mm", D, fits.diameter_mm)):
        bad = [v for v in vals if not samples.min() * (1 - 1e-9) <= v <= samples.max() * (1 + 1e-9)]
        if bad:
            w = bad[0] if name == "wt_pct" else W[0]
            d = bad[0] if name == "diameter_mm" else D[0]
            raise DesignError(f"(wt_pct={w:g}, diameter_mm={d:g}) lies outside the convex hull of the identified "
                              f"samples ({fits.hull_text()}): the surfaces do not extrapolate; keep --wt-pct and "
                              f"--diameter-mm inside it")
    Wg, Dg = np.meshgrid(W, D, indexing="ij")
    out = {k: v.reshape(Wg.shape) for k, v in generalize.predict_arrays(fits, Wg.ravel(), Dg.ravel()).items()}
    inside = np.isfinite(out["Em"])
    if not inside.any():
        w, d = float(W[0]), float(D[0])
        span = advice.Hull.from_fits(fits).diameter_span(w)
        where = (f"at wt_pct={w:g} it spans diameter_mm {span[0]:.4g}-{span[1]:.4g}" if span else
                 f"it holds no diameter at wt_pct={w:g}")
        raise DesignError(f"no (wt_pct, diameter_mm) of the grid lies inside the convex hull of the identified "
                          f"samples, e.g. (wt_pct={w:g}, diameter_mm={d:g}): the hull is taken in the surfaces' "
                          f"coordinates (log wt%, log D), where its edges are straight, so in (wt%, D) they curve: "
                          f"{where} (samples at {sorted(set(zip(fits.wt_pct.tolist(), fits.diameter_mm.tolist())))})")
    return out


def block_task(args):
    """One (D, gap): all wt x V designs; args = (coil, D_m, gap_m, params {k: (n_wt,)}, V (n_V,), settings)."""
    coil, D_m, gap_m, par, V, st = args
    n_v = V.size
    ok = np.isfinite(np.asarray(par["Em"], dtype=float))          # wt% inside the hull at this D
    out = {k: np.full((ok.size, n_v), False if k == "contact" else np.nan, dtype=bool if k == "contact" else float)
           for k in METRICS}
    n_w = int(ok.sum())
    if n_w:
        p = {k: np.repeat(np.asarray(par[k], dtype=float)[ok], n_v) for k in _FIT}
        b = Block(a_m=coil["a"], kB_T_per_A=coil["kB"], R_Ohm=coil["R"], L_H=coil["L"], D_m=D_m, gap_m=gap_m,
                  V_V=np.tile(V, n_w), params=p, t_step_s=st.t_step_s, dt_s=st.dt_s)
        for k, v in evaluate_block(b).items():
            out[k][ok] = np.asarray(v).reshape(n_w, n_v)
    return out


def _draw_task(args):
    """Candidates of one (D, gap) under every parameter draw: args = (coil, D_m, gap_m, wt (n_c,), V (n_c,),
    nodes (list of (w, d, {name: (n_draws,)})), settings). Returns {metric: (n_draws, n_c)}."""
    coil, D_m, gap_m, wt, V, nodes, st = args
    n_d = len(next(iter(nodes))[2]["Em"])
    n_c = wt.size
    par = {k: np.empty((n_d, n_c)) for k in _FIT}
    for j in range(n_d):
        fits = generalize.fit_surfaces([(w, d, {k: float(v[k][j]) for k in _FIT}) for w, d, v in nodes])
        for c in range(n_c):
            pred = generalize.predict(fits, float(wt[c]), D_m * 1e3)
            for k in _FIT:
                par[k][j, c] = pred[k]
    b = Block(a_m=coil["a"], kB_T_per_A=coil["kB"], R_Ohm=coil["R"], L_H=coil["L"], D_m=D_m, gap_m=gap_m,
              V_V=np.tile(V, n_d), params={k: par[k].ravel() for k in _FIT}, t_step_s=st.t_step_s, dt_s=st.dt_s)
    m = evaluate_block(b)
    return {k: np.asarray(v).reshape(n_d, n_c) for k, v in m.items()}


def _margin(targets: Targets, m: dict) -> np.ndarray:
    """Smallest relative margin over the given targets (> 0: met with room); a design reaching the coil face
    when contact is not allowed has at most -1 (-100 %: it fails whatever its other margins, and is listed
    after the designs that only miss a bound when nothing is feasible)."""
    r = []
    if targets.stroke_mm is not None:
        r.append(m["stroke_m"] * 1e3 / targets.stroke_mm - 1)
    if targets.settling_ms is not None:
        r.append(1 - m["settling_s"] * 1e3 / targets.settling_ms)
    out = np.min(np.stack(r + targets.bound_margins(m)), axis=0)
    if not targets.allow_contact:
        out = np.where(np.asarray(m["contact"], dtype=bool), np.minimum(out, -1.0), out)
    return out


def design(training: dict, targets: Targets, space: DesignSpace, settings: DesignSettings = DesignSettings(),
           cluster: ClusterSettings = ClusterSettings()) -> DesignResult:
    """The feasible region and the candidates' probabilities (module docstring).

    training: {id: ParameterUncertainty} of the identified samples (``uncertainty.json``).
    """
    fits, coil = surface_model(training)
    par = nominal_params(fits, space)
    W, Dm, Gm, V = (a.values for a in space.axes)
    jobs = [(coil, float(d) / 1e3, float(g) / 1e3, {k: par[k][:, j] for k in _FIT}, V, settings)
            for j, d in enumerate(Dm) for g in Gm]
    with cluster_client(cluster) as client:
        res = run_tasks(block_task, jobs, cluster, desc="design sweep (D x gap blocks)", client=client)
        return _finish(training, targets, space, settings, (cluster, client), (fits, coil, res))


def _finish(training, targets, space, settings, where, model) -> DesignResult:
    fits, coil, res = model
    W, Dm, Gm, V = (a.values for a in space.axes)
    metrics = {k: np.empty(space.shape, dtype=bool if k == "contact" else float) for k in METRICS}
    for q, r in enumerate(res):
        j, g = divmod(q, Gm.size)
        for k in METRICS:
            metrics[k][:, j, g, :] = r[k]
    feasible = targets.met(metrics) & np.isfinite(metrics["current_A"])      # not outside the hull
    margin = _margin(targets, metrics)
    idx = np.argwhere(feasible)
    if not len(idx):                                   # nothing feasible: the designs nearest to the spec
        flat = np.argsort(-np.nan_to_num(margin.ravel(), nan=-np.inf), kind="stable")
        flat = flat[np.isfinite(metrics["current_A"].ravel()[flat])][:NEAREST]   # inside the hull
        idx = np.array(np.unravel_index(flat, space.shape)).T
    rows = []
    for c in map(tuple, idx):
        row = {"source": "grid", "wt_pct": float(W[c[0]]), "diameter_mm": float(Dm[c[1]]), "gap_mm": float(Gm[c[2]]),
               "voltage_V": float(V[c[3]])}
        row.update(_metric_row({k: metrics[k][c] for k in METRICS}, targets))
        rows.append(row)
    linearised(training, targets, rows, coil, settings, where)
    if not feasible.any():
        rows.sort(key=lambda r: -r["margin_pct"])
        monte_carlo(training, targets, rows, coil, settings, where)
        return DesignResult(space=space, targets=targets, metrics=metrics, feasible=feasible, candidates=[],
                            hull=fits.hull_text(), settings=settings, nearest=rows,
                            outside_hull=_outside(metrics))
    rows = advice.rank(rows, settings.objective, settings.min_probability)
    refined = _refine(training, targets, space, settings, where, (coil, rows[:settings.refine]))
    rows = advice.rank(rows + refined, settings.objective, settings.min_probability)
    monte_carlo(training, targets, rows[:settings.max_candidates], coil, settings, where)
    for r in rows[settings.max_candidates:]:
        r["probability_mc"] = r["probability_mc_se"] = None
    key = advice.objective_key(settings.objective)
    front = advice.pareto_front([r[key] for r in rows], [np.nan if r["probability_linearised"] is None
                                                         else r["probability_linearised"] for r in rows])
    return DesignResult(space=space, targets=targets, metrics=metrics, feasible=feasible, candidates=rows,
                        hull=fits.hull_text(), settings=settings, front=[int(i) for i in front],
                        outside_hull=_outside(metrics))


def _outside(metrics) -> int:
    """Grid points (wt%, D) left out of the design: outside the identified samples' hull."""
    return int((~np.isfinite(metrics["current_A"][:, :, 0, 0])).sum())


def _metric_row(m: dict, targets: Targets) -> dict:
    """The metrics of one design as a row (contact bool, the rest float) and its margin [%]."""
    row = {k: (bool(m[k]) if k == "contact" else float(m[k])) for k in METRICS}
    row["margin_pct"] = float(100 * _margin(targets, {k: np.array([v]) for k, v in m.items()})[0])
    return row


def _nodes(training):
    return [(u.wt_pct, u.diameter_mm, {k: float(getattr(u.params, k)) for k in _FIT}) for u in training.values()]


def _refine(training, targets, space, settings, where, job) -> list:
    """Rows of the refined designs that moved (one Dask task per start; duplicates dropped)."""
    coil, starts = job
    if not starts:
        return []
    args = [(_nodes(training), coil, advice.robust_targets(targets, r.get("sd_rel") or {}, settings.min_probability),
             space, (r["wt_pct"], r["diameter_mm"], r["gap_mm"], r["voltage_V"]), settings.objective, settings)
            for r in starts]
    out, seen = [], set()
    for r in run_tasks(advice.refine_task, args, where[0], desc="refining the best designs", client=where[1]):
        key = tuple(float(f"{v:.3g}") for v in r["design"])          # equal at three significant digits
        if not r["moved"] or key in seen:
            continue
        seen.add(key)
        w, d, g, v = r["design"]
        row = {"source": "refined", "wt_pct": w, "diameter_mm": d, "gap_mm": g, "voltage_V": v}
        row.update(_metric_row(r["metrics"], targets))
        row["refined_from"] = "wt_pct {:.4g}, diameter_mm {:.4g}, gap_mm {:.4g}, voltage_V {:.4g}".format(*r["start"])
        row["start_design"] = tuple(float(v) for v in r["start"])       # (wt%, D mm, gap mm, V) of the grid start
        out.append(row)
    linearised(training, targets, out, coil, settings, where)
    return out


def _groups(rows) -> dict:
    """{(diameter_mm, gap_mm): [row indices]} (one force kernel per group)."""
    groups: dict = {}
    for i, r in enumerate(rows):
        groups.setdefault((r["diameter_mm"], r["gap_mm"]), []).append(i)
    return groups


def linearised(training, targets, rows, coil, settings, where=(ClusterSettings(), None)) -> None:
    """Set rows' "probability_linearised" (delta method, :func:`advice.linearised_probabilities`); rows: dicts
    with wt_pct, diameter_mm, gap_mm, voltage_V and the metrics; where: (ClusterSettings, client or None)."""
    if not rows:
        return
    nodes = _nodes(training)
    fits = generalize.fit_surfaces([(w, d, v) for w, d, v in nodes])
    wt = np.array([r["wt_pct"] for r in rows])
    dm = np.array([r["diameter_mm"] for r in rows])
    theta = generalize.predict_arrays(fits, wt, dm)
    wts = advice.node_weights(nodes, wt, dm)                                     # (n, nodes)
    node_val = np.array([[v[k] for k in _FIT] for _, _, v in nodes])             # (nodes, 5)
    dtheta = np.stack([theta[k][:, None] * wts / node_val[None, :, q] if fits.log_values[k] else wts
                       for q, k in enumerate(_FIT)], axis=1)                     # (n, 5, nodes)
    ix = [PARAMS.index(k) for k in _FIT]
    cov = np.stack([u.cov[np.ix_(ix, ix)] for u in training.values()])
    groups = _groups(rows)
    keys = list(groups)
    jobs = [(coil, d / 1e3, g / 1e3, np.array([rows[i]["voltage_V"] for i in groups[(d, g)]]),
             {k: theta[k][groups[(d, g)]] for k in _FIT}, settings) for d, g in keys]
    res = run_tasks(advice.jacobian_task, jobs, where[0], desc="linearised probabilities (blocks)", client=where[1])
    n = len(rows)
    der = {k: np.full((n, 5), np.nan) for k in ("stroke_m", "blocked_force_N", "settling_s", "bandwidth_Hz",
                                                 "pull_in_current_A")}
    for key, r in zip(keys, res):
        for k in der:
            der[k][groups[key]] = r["d"][k]
    nominal = {k: np.array([r[k] for r in rows], dtype=float) for k in METRICS if k != "contact"}
    nominal["gap_m"] = np.array([r["gap_mm"] for r in rows]) / 1e3
    sd: dict = {}
    p = advice.linearised_probabilities(targets, nominal, der, dtheta, cov, seed=settings.seed, sd_out=sd)
    for j, (r, v) in enumerate(zip(rows, p)):
        r["probability_linearised"] = float(v) if math.isfinite(v) else None
        r["sd_rel"] = {k: float(sd[k][j] / abs(r[k])) for k in sd if k in r and math.isfinite(sd[k][j]) and r[k] != 0}


def monte_carlo(training, targets, rows, coil, settings, where=(ClusterSettings(), None)) -> None:
    """Set rows' "probability_mc" (share of settings.n_draws parameter draws meeting the spec) and
    "probability_mc_se"; rows and where as in :func:`linearised`."""
    for r in rows:
        r["probability_mc"] = r["probability_mc_se"] = None
    if not rows:
        return
    draws = {sid: u.draws(settings.n_draws, sample_rng(settings.seed, sid, "design")) for sid, u in training.items()}
    nodes = [(u.wt_pct, u.diameter_mm, {k: draws[sid][:, PARAMS.index(k)] for k in _FIT})
             for sid, u in training.items()]
    groups = _groups(rows)
    keys = list(groups)
    jobs = [(coil, d / 1e3, g / 1e3, np.array([rows[i]["wt_pct"] for i in groups[(d, g)]]),
             np.array([rows[i]["voltage_V"] for i in groups[(d, g)]]), nodes, settings) for d, g in keys]
    res = run_tasks(_draw_task, jobs, where[0], desc="probability of meeting the spec (blocks)", client=where[1])
    for key, r in zip(keys, res):
        ok = targets.met(r)                                # (n_draws, n_c)
        for i, p in zip(groups[key], ok.mean(axis=0)):
            rows[i]["probability_mc"] = float(p)
            rows[i]["probability_mc_se"] = math.sqrt(p * (1 - p) / settings.n_draws)


def default_space(training: dict, spec: dict | None = None, points: int = 12) -> DesignSpace:
    """The design grid from ``spec`` ({"wt_pct", "diameter_mm", "gap_mm", "voltage_V": [value] or [lo, hi] or
    None}) and ``points`` per ranged axis; defaults: the identified samples' wt% and D ranges, gap 3-12 mm,
    voltage 1-12 V."""
    spec = dict(spec or {})
    ws = [u.wt_pct for u in training.values()]
    ds = [u.diameter_mm for u in training.values()]
    defaults = {"wt_pct": [min(ws), max(ws)], "diameter_mm": [min(ds), max(ds)], "gap_mm": [3.0, 12.0],
                "voltage_V": [1.0, 12.0]}
    axes = {k: Axis.parse(k, spec.get(k) or v, points) for k, v in defaults.items()}
    return DesignSpace(**axes)
