"""Inverse design: from targets to the feasible region of (wt%, D, gap, voltage) (``mpc-actuator design``).

1. Surfaces: the identified samples' Em, K1, K2, C, m fitted over (wt%, D)
   (:func:`harness.analysis.generalize.fit_surfaces`); the coil (a, kB, R, L): the samples' mean.
   Every (wt%, D) of the grid must lie inside the identified samples' convex hull: otherwise the job
   refuses (:class:`DesignError` naming the point and the hull), as the surfaces do not extrapolate.
2. Nominal sweep: every design of the grid through :func:`harness.analysis.design.evaluate.evaluate_block`,
   one Dask task per (D, gap) (all wt% x V of that pair: one force kernel per task),
   :mod:`harness.analysis.sweep`.
3. Probability of meeting the spec: for up to ``max_candidates`` feasible designs (those with the largest
   margin first), ``n_draws`` draws of every identified sample's parameters
   (:meth:`harness.analysis.uncertainty.ParameterUncertainty.draws`, one generator per sample seeded from
   (seed, sample id)), one surface fit per draw, the candidates evaluated under each; the probability
   is the share of draws meeting the spec (its binomial standard error is reported). The coil is held at
   its mean (its standard uncertainty is about 1e-4 relative).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from harness.analysis import generalize
from harness.analysis.design.evaluate import METRICS, Block, evaluate_block
from harness.analysis.design.space import Axis, DesignError, DesignSpace, Targets
from harness.analysis.sweep import ClusterSettings, cluster_client, run_tasks
from harness.analysis.uncertainty import PARAMS
from harness.analysis.uncertainty_run import sample_rng

__all__ = ["DesignSettings", "DesignResult", "surface_model", "nominal_params", "design", "default_space", "block_task"]

_FIT = ("Em", "K1", "K2", "C", "m")


@dataclass(frozen=True)
class DesignSettings:
    """n_draws: parameter draws per candidate for the probability; seed; max_candidates: feasible designs
    given a probability; t_step_s [s]: step-response duration; dt_s [s]: its output period."""
    n_draws: int = 32
    seed: int = 0
    max_candidates: int = 200
    t_step_s: float = 0.5
    dt_s: float = 1e-3

    def __post_init__(self):
        if not (self.n_draws >= 1 and self.max_candidates >= 0 and self.t_step_s > 0 and self.dt_s > 0):
            raise DesignError(f"invalid design settings {self!r}")


@dataclass
class DesignResult:
    """space, targets; metrics: {name: array of space.shape}; feasible: bool array (nominal);
    candidates: list of dicts (feasible designs with metrics and probability, best first);
    hull: text of the identified samples' ranges."""
    space: DesignSpace
    targets: Targets
    metrics: dict
    feasible: np.ndarray
    candidates: list
    hull: str
    settings: DesignSettings


def surface_model(training: dict):
    """(SurfaceFits of the identified samples, coil {a, kB, R, L}) from {id: ParameterUncertainty}."""
    if len(training) < 3:
        raise DesignError(f"the design needs at least 3 identified samples spanning (wt%, D), got {len(training)}")
    fits = generalize.fit_surfaces([(u.wt_pct, u.diameter_mm, u.params) for u in training.values()])
    ps = [u.params for u in training.values()]
    coil = {k: float(np.mean([getattr(p, k) for p in ps])) for k in ("a", "kB", "R", "L")}
    return fits, coil


def nominal_params(fits, space: DesignSpace) -> dict:
    """{name: (n_wt, n_D) array} of Em, K1, K2, C, m on the grid; :class:`DesignError` outside the hull."""
    W, D = space.wt_pct.values, space.diameter_mm.values
    out = {k: np.empty((W.size, D.size)) for k in _FIT}
    for i, w in enumerate(W):
        for j, d in enumerate(D):
            try:
                pred = generalize.predict(fits, float(w), float(d))
            except generalize.GeneralizationError:
                raise DesignError(f"(wt_pct={w:g}, diameter_mm={d:g}) lies outside the convex hull of the identified "
                                  f"samples ({fits.hull_text()}): the surfaces do not extrapolate; keep --wt-pct and "
                                  f"--diameter-mm inside it") from None
            for k in _FIT:
                out[k][i, j] = pred[k]
    return out


def block_task(args):
    """One (D, gap): all wt x V designs; args = (coil, D_m, gap_m, params {k: (n_wt,)}, V (n_V,), settings)."""
    coil, D_m, gap_m, par, V, st = args
    n_w, n_v = par["Em"].size, V.size
    p = {k: np.repeat(np.asarray(par[k], dtype=float), n_v) for k in _FIT}
    b = Block(a_m=coil["a"], kB_T_per_A=coil["kB"], R_Ohm=coil["R"], L_H=coil["L"], D_m=D_m, gap_m=gap_m,
              V_V=np.tile(V, n_w), params=p, t_step_s=st.t_step_s, dt_s=st.dt_s)
    m = evaluate_block(b)
    return {k: np.asarray(v).reshape(n_w, n_v) for k, v in m.items()}


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
    """Smallest relative margin over the given targets (> 0: met with room)."""
    r = []
    if targets.stroke_mm is not None:
        r.append(m["stroke_m"] * 1e3 / targets.stroke_mm - 1)
    if targets.blocked_force_N is not None:
        r.append(m["blocked_force_N"] / targets.blocked_force_N - 1)
    if targets.settling_ms is not None:
        r.append(1 - m["settling_s"] * 1e3 / targets.settling_ms)
    if targets.max_current_A is not None:
        r.append(1 - m["current_A"] / targets.max_current_A)
    if targets.max_power_W is not None:
        r.append(1 - m["power_W"] / targets.max_power_W)
    if targets.min_bandwidth_Hz is not None:
        r.append(m["bandwidth_Hz"] / targets.min_bandwidth_Hz - 1)
    return np.min(np.stack(r), axis=0)


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
    feasible = targets.met(metrics)
    idx = np.argwhere(feasible)
    margin = _margin(targets, metrics)[feasible]
    order = np.argsort(-margin, kind="stable")
    cand = [tuple(int(v) for v in idx[o]) for o in order]
    chosen = cand[:settings.max_candidates]
    prob = _probabilities(training, targets, space, chosen, coil, settings, where) if chosen else {}
    rows = []
    for c in cand:
        i, j, g, v = c
        row = {"wt_pct": float(W[i]), "diameter_mm": float(Dm[j]), "gap_mm": float(Gm[g]), "voltage_V": float(V[v])}
        row.update({k: (bool(metrics[k][c]) if k == "contact" else float(metrics[k][c])) for k in METRICS})
        p = prob.get(c)
        row["probability"] = None if p is None else p
        row["probability_se"] = None if p is None else math.sqrt(p * (1 - p) / settings.n_draws)
        rows.append(row)
    return DesignResult(space=space, targets=targets, metrics=metrics, feasible=feasible, candidates=rows,
                        hull=fits.hull_text(), settings=settings)


def _probabilities(training, targets, space, chosen, coil, settings, where) -> dict:
    W, Dm, Gm, V = (a.values for a in space.axes)
    draws = {sid: u.draws(settings.n_draws, sample_rng(settings.seed, sid, "design")) for sid, u in training.items()}
    nodes = [(u.wt_pct, u.diameter_mm, {k: draws[sid][:, PARAMS.index(k)] for k in _FIT})
             for sid, u in training.items()]
    groups: dict = {}
    for c in chosen:
        groups.setdefault((c[1], c[2]), []).append(c)
    keys = sorted(groups)
    jobs = [(coil, float(Dm[j]) / 1e3, float(Gm[g]) / 1e3, np.array([W[c[0]] for c in groups[(j, g)]]),
             np.array([V[c[3]] for c in groups[(j, g)]]), nodes, settings) for j, g in keys]
    res = run_tasks(_draw_task, jobs, where[0], desc="probability of meeting the spec (blocks)", client=where[1])
    out = {}
    for key, r in zip(keys, res):
        ok = targets.met(r)                                # (n_draws, n_c)
        for c, p in zip(groups[key], ok.mean(axis=0)):
            out[c] = float(p)
    return out


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
