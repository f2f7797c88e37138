"""Simulation jobs of the diagnosis -> simulator calls, and their outputs on the measured grids.

The one place of the diagnosis that calls the simulator (``harness.sim.simulator.simulate``). A *job* is
(prepared sample, ``Params``); :func:`run_jobs` simulates the tests of many jobs in a few batches (sweeps:
one run per gap; step tests: one run from the step instant at constant voltage; other series: the measured
voltage replayed, held, linear or a cubic spline between samples as the data say, ``Series.hold``) and returns per job
{test: :class:`SeriesSim` | :class:`SweepSim`}. Every test at its own simulation period (:func:`sim_period`:
the rig's sample period, subdivided below 1 kHz, multiplied above 2 kHz; one simulator batch per period,
:func:`harness.sim.simulator.simulate_by_period`). A step test whose step instant lies ``step_delay_s``
before its first sample (``Series.step_delay_s``) is simulated from the step instant and read at the
measured samples, ``step_delay_s`` + k dt after it (cubic Lagrange interpolation of the simulator's output
grid, whose period is at most 1 ms: error about 0.01 mA for an 8 ms coil).

Invariant: every residual lies on measured samples chosen from the record and the settings alone
(:func:`step_offsets`, :func:`sweep_window_s`, the replayed records' own samples), so that its length is
fixed per dataset whatever the parameters or the other runs of a batch (checked by the fits' evaluator).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from harness.data.protocol import sweep_average_mask
from harness.sim.settings import Schedule
from harness.sim.simulator import PARAM_FIELDS, Runs, simulate_by_period

from harness.analysis.identification.analytic import CUBIC_SUBDIVISION, cubic_drive

from .prepare import SampleData, Sweep

CHANNELS = ("y", "I")     # the reading (displacement [m] or blocked force [N]) and the current [A]


@dataclass(frozen=True)
class SeriesSim:
    """A simulated time series: local time ``t_s`` [s] (0 at the onset; the measured time when the voltage
    was replayed), current ``I_A`` [A] and reading ``y`` [m or N]."""
    t_s: np.ndarray
    I_A: np.ndarray
    y: np.ndarray


@dataclass(frozen=True)
class SweepSim:
    """A simulated sweep: mean current ``I_A`` [A] and reading ``y`` [m or N] over the averaging window of
    each gap's hold (NaN for gaps not simulated)."""
    I_A: np.ndarray
    y: np.ndarray


class Chi2(NamedTuple):
    """Chi-square of one (test, channel) and its number of residuals."""
    chi2: float
    n: int


@dataclass(frozen=True)
class Trace:
    """A test's measured and simulated signals on the measured grid: ``kind`` "series" | "sweep", ``x``
    (time [s] or gap [mm]), reading ``y_meas``/``y_sim`` [m or N], current ``I_meas``/``I_sim`` [A]."""
    kind: str
    x: np.ndarray
    y_meas: np.ndarray
    y_sim: np.ndarray
    I_meas: np.ndarray
    I_sim: np.ndarray
    blocked: bool


@dataclass(frozen=True)
class JobOptions:
    """How :func:`run_jobs` simulates: ``full`` (series outputs on every sample, else fine for ``fine_s``
    [s] after the onset then coarse), ``fit_gaps`` (sweeps: only the gaps of the sweep's fit mask) and
    ``max_rate_hz`` (a rig sampling faster is simulated and compared at every q-th sample, :func:`decimation`)."""
    full: bool = False
    fine_s: float = 0.5
    fit_gaps: bool = False
    max_rate_hz: float = 2000.0


def decimation(dt: float, max_rate_hz: float) -> int:
    """q >= 1: a test sampled every ``dt`` [s] is simulated with the period q dt and compared at every q-th
    sample, so that neither rate exceeds about ``max_rate_hz`` (q = floor(1 / (dt max_rate_hz)); 1 at and below
    that rate). Data-defined (the record's period and a setting), never the parameters'. The model's fastest
    time constants (the coil's L/R, ms; the diaphragm's period, >= 10 ms) are resolved many times over at
    2 kHz; the simulator's sub-steps follow the stiffness whatever the period."""
    return max(1, int(math.floor(1.0 / (dt * max_rate_hz) + 1e-9)))


def shortest_compared_period_s(samples, names, max_rate_hz: float) -> float:
    """The shortest period [s] at which the fits compare the tests ``names`` of prepared samples (nan if none has
    one): a test's sample period, times its :func:`decimation` at ``max_rate_hz`` [Hz]. A lag faster than it is as
    invisible to the fits as one faster than the record's period (a 10 us lag start at 10 kHz, compared at 2 kHz,
    sized every coarse step of its runs: one Jacobian batch of a discovery round cost 53 CPU-s; session 21)."""
    periods = [float(t.dt) * decimation(float(t.dt), max_rate_hz)
               for sd in samples for n, t in sd.tests.items() if n in names and hasattr(t, "dt")]
    return min(periods) if periods else float("nan")


#: [Hz] a rig sampling slower is simulated with its period subdivided (:func:`subdivision`)
MIN_SIM_RATE_HZ = 1000.0


def subdivision(dt: float) -> int:
    """M >= 1: a test sampled every ``dt`` [s] slower than :data:`MIN_SIM_RATE_HZ` is simulated with the period
    dt / M (M = ceil(dt MIN_SIM_RATE_HZ)), so that the simulation's outputs resolve the coil's millisecond rise:
    a step between two samples is read from them by cubic interpolation at ``step_delay_s`` + k dt, whose error
    grows as (period / tau)^4 (at 150 Hz and tau = 8 ms: 15 mA on the simulator's own period, 6 noise floors;
    at 1 ms: 0.01 mA). 1 at and above that rate."""
    return max(1, int(math.ceil(dt * MIN_SIM_RATE_HZ - 1e-9)))


def sim_period(dt: float, max_rate_hz: float) -> float:
    """The simulation period [s] of a test sampled every ``dt`` [s]: q dt (:func:`decimation`) for a fast rig,
    dt / M (:func:`subdivision`) for a slow one, else dt."""
    return dt * decimation(dt, max_rate_hz) / subdivision(dt)


#: a cubic drive is replayed on the simulation's own period when its spline departs from the linear reading by less
#: than this fraction of the drive's largest |V| at mid-interval (:func:`spline_is_linear`), else on at least
#: ``CUBIC_SUBDIVISION`` sub-periods per sample
CUBIC_LINEAR_TOL = 1e-5


def spline_is_linear(V) -> bool:
    """The cubic spline through the samples V [V] is within :data:`CUBIC_LINEAR_TOL` of the linear reading at every
    mid-interval (the drive is slow against the sample rate: no sub-periods needed). From the data alone."""
    V = np.asarray(V, dtype=float)
    if V.size < 4:
        return True
    mid = cubic_drive(V, 2)[1::2]
    return bool(np.max(np.abs(mid - 0.5 * (V[:-1] + V[1:]))) <= CUBIC_LINEAR_TOL * max(np.max(np.abs(V)), 1e-300))


class _Rows:
    """Simulation rows collected from the jobs: constant-input rows (with their sample period) and
    replayed-voltage rows grouped by (samples, period, hold)."""

    def __init__(self):
        self.const, self.const_v, self.pvals, self.blk, self.dts = [], [], [], [], []
        self.grid, self.gvals = {}, {}

    def add_const(self, key, row, blocked, V_on, dt):
        self.const.append(key)
        self.pvals.append(row)
        self.blk.append(blocked)
        self.const_v.append(V_on)
        self.dts.append(float(dt))


def _collect(jobs, names, opts: JobOptions) -> _Rows:
    rows = _Rows()
    ir0 = PARAM_FIELDS.index("r0")
    for j, ((sd, p), nm) in enumerate(zip(jobs, names)):
        base = [getattr(p, k) for k in PARAM_FIELDS]
        for name in nm:
            test = sd.tests.get(name)
            if test is None:
                continue
            if isinstance(test, Sweep):
                for gi, g in enumerate(test.gaps):
                    if opts.fit_gaps and test.fit_mask is not None and not test.fit_mask[gi]:
                        continue
                    row = list(base)
                    row[ir0] = float(g)
                    rows.add_const((j, name, gi), row, test.blocked, test.V_on, sim_period(test.dt, opts.max_rate_hz))
                continue
            row = list(base)
            row[ir0] = test.r0
            q = decimation(test.dt, opts.max_rate_hz)
            if test.V_on is not None:
                rows.add_const((j, name, None), row, test.blocked, test.V_on, sim_period(test.dt, opts.max_rate_hz))
            else:
                # the measured voltage replayed; decimated (every q-th sample, linear between them: a drive
                # held for one fast sample period is, at q periods, a piecewise-linear one), or subdivided
                # (M sub-periods per sample, as the hold says: repeated, interpolated, or on the cubic
                # spline through the samples at CUBIC_SUBDIVISION or more sub-periods, read linear there)
                M = subdivision(test.dt)
                V = test.V[::q] if q > 1 else test.V
                hold = "linear" if q > 1 else test.hold
                if hold == "cubic":
                    M = M if spline_is_linear(V) else max(M, CUBIC_SUBDIVISION)
                    V, hold = (cubic_drive(V, M) if M > 1 else V), "linear"
                elif M > 1:
                    fine = np.arange((V.size - 1) * M + 1) / M
                    V = (np.interp(fine, np.arange(V.size), V) if hold == "linear"
                         else np.append(np.repeat(V[:-1], M), V[-1]))
                key = (V.size - 1, round(test.dt * q / M, 15), hold, M)
                rows.grid.setdefault(key, []).append((j, name))
                rows.gvals.setdefault(key, ([], [], []))
                rows.gvals[key][0].append(row)
                rows.gvals[key][1].append(test.blocked)
                rows.gvals[key][2].append(V if hold == "linear" else V[:-1])
    return rows


def lagrange_weights(t_grid, t_query) -> tuple:
    """Cubic Lagrange interpolation on the increasing grid t_grid (n,) at t_query (m,) as (nodes, weights), both
    (m, 4): the four grid points around each query (two at the ends; the grid may be non-uniform) and their
    weights, so that the interpolant of Y (..., n) is ``sum(Y[..., nodes] * weights, axis=-1)``. Needs n >= 4."""
    t_grid = np.asarray(t_grid, dtype=float)
    q = np.asarray(t_query, dtype=float)
    n = t_grid.size
    j = np.clip(np.searchsorted(t_grid, q) - 2, 0, n - 4)
    nodes = j[:, None] + np.arange(4)[None, :]
    tn = t_grid[nodes]                                  # (m, 4)
    w = np.ones_like(tn)
    for a in range(4):
        for b in range(4):
            if a != b:
                w[:, a] *= (q - tn[:, b]) / (tn[:, a] - tn[:, b])
    return nodes, w


def lagrange_at(t_grid, Y, t_query) -> np.ndarray:
    """Cubic Lagrange interpolation of Y (..., n) on the increasing grid t_grid (n,) at t_query (m,)
    (:func:`lagrange_weights`; linear for fewer than four grid points)."""
    q = np.asarray(t_query, dtype=float)
    if np.size(t_grid) < 4:
        return np.stack([np.interp(q, t_grid, y) for y in np.atleast_2d(Y)]).reshape(np.shape(Y)[:-1] + q.shape)
    nodes, w = lagrange_weights(t_grid, q)
    return np.sum(np.asarray(Y)[..., nodes] * w, axis=-1)


def mean_weights(t_grid, t_query) -> np.ndarray:
    """Weights v (n,) on the grid t_grid such that ``Y @ v`` is the mean of the cubic Lagrange interpolant of Y
    (..., n) over the times t_query (:func:`lagrange_at`): one dot product per run instead of an interpolation."""
    t_grid = np.asarray(t_grid, dtype=float)
    v = np.zeros(t_grid.size)
    if t_grid.size < 4:
        for k in range(t_grid.size):
            e = np.zeros(t_grid.size)
            e[k] = 1.0
            v[k] = np.interp(t_query, t_grid, e).mean()
        return v
    nodes, w = lagrange_weights(t_grid, t_query)
    np.add.at(v, nodes.ravel(), w.ravel() / len(t_query))
    return v


def step_offsets(test, fine_s: float | None, coarse_out: int, q: int = 1) -> np.ndarray:
    """Measured samples at which a step test is compared with its simulation: offsets j from the first sample
    with the input on (sample ``test.k_on + j``), chosen from the record and the schedule alone, never from a
    simulated response, so that a residual's length is fixed per dataset whatever the parameters.

    Every q-th sample (:func:`decimation`) for ``fine_s`` [s] after the onset, then every ``coarse_out`` q-th
    (the quasi-static remainder, where the simulator's outputs are coarse); every sample when ``fine_s`` is
    None (traces and held-out tests: read from the simulation by interpolation).
    """
    n_loc = test.t.size - test.k_on
    if fine_s is None:
        return np.arange(n_loc)
    n_fine = min((n_loc - 1) // q, int(round(fine_s / (test.dt * q))))
    return q * np.concatenate([np.arange(n_fine + 1), np.arange(n_fine + coarse_out, (n_loc - 1) // q + 1,
                                                                    coarse_out)])


def sweep_window_s(test) -> np.ndarray:
    """Times [s] from the energizing of a sweep point at which the rig's samples are averaged for its reading:
    the samples of the hold (``k dt``, k = 1 .. round(hold_s / dt)) in its last ``avg_s``."""
    t = np.arange(1, max(int(round(test.hold_s / test.dt)), 1) + 1) * test.dt
    return t[sweep_average_mask(t, test.avg_s)]


def param_key(p) -> tuple:
    """The simulated parameters of Params ``p`` as a hashable tuple (floats, simulator order): a cache key."""
    return tuple(float(getattr(p, k)) for k in PARAM_FIELDS)


def _param_columns(values) -> dict:
    A = np.array(values, dtype=float)
    return {k: A[:, i] for i, k in enumerate(PARAM_FIELDS)}


def _run_const(jobs, rows: _Rows, group: list, opts: JobOptions, out: list):
    const = rows.const
    any_series = any(const[r][2] is None for r in group)
    te = 0.0
    for r in group:
        j, name, gi = const[r]
        test = jobs[j][0].tests[name]
        te = max(te, test.hold_s if gi is not None else (test.t.size - 1 - test.k_on) * test.dt + test.step_delay_s)
    group = list(group)
    dts = np.array([rows.dts[r] for r in group])
    te = max(math.ceil(te / float(np.max(dts)) - 1e-9), 1) * float(np.max(dts))   # whole periods of every batch
    runs = Runs(_param_columns([rows.pvals[r] for r in group]), np.array([rows.blk[r] for r in group]),
                np.array([rows.const_v[r] for r in group]), dt=dts)
    sched = Schedule(t_end=te, fine_s=te if (opts.full and any_series) else opts.fine_s)
    sweeps = {}
    for idx, sim in simulate_by_period(runs, sched):
        series = {}             # measured test -> the batch's runs of it, [(job, run)] (the jobs of one sample
        for rr, r in enumerate(idx):    # with other parameters: finite-difference columns, candidates)
            j, name, gi = const[group[r]]
            if gi is None:
                test = jobs[j][0].tests[name]
                series.setdefault(id(test), (test, []))[1].append((j, name, rr))
            else:
                sweeps.setdefault((j, name), []).append((gi, rr, sim))
        for test, runs_of_test in series.values():
            tl = step_offsets(test, None if opts.full else opts.fine_s, sched.coarse_out,
                              decimation(test.dt, opts.max_rate_hz)) * test.dt
            # read at the measured samples (data-defined), wherever the batch's output grid lies; the weights
            # once for all the runs of a test (a 20 kHz dataset spent a third of its diagnosis making them
            # again for each run)
            rrs = [rr for _, _, rr in runs_of_test]
            YI = lagrange_at(sim.t, np.stack([sim.I[rrs], sim.y[rrs]]), tl + test.step_delay_s)
            for k, (j, name, _) in enumerate(runs_of_test):
                out[j][name] = SeriesSim(tl, YI[0, k], YI[1, k])
    weights = {}                # (simulation, window) -> averaging weights on its output grid
    for (j, name), lst in sweeps.items():
        test = jobs[j][0].tests[name]
        Im = np.full(test.gaps.size, np.nan)
        ym = np.full(test.gaps.size, np.nan)
        tq = sweep_window_s(test)
        for gi, rr, sim in lst:
            # the mean over the rig's samples of the averaging window (data-defined), not over the batch's grid
            key = (id(sim), tq.size, float(tq[0]), float(tq[-1]))
            if key not in weights:
                weights[key] = mean_weights(sim.t, tq)
            Im[gi] = sim.I[rr] @ weights[key]
            ym[gi] = sim.y[rr] @ weights[key]
        out[j][name] = SweepSim(Im, ym)


def run_jobs(jobs, names, opts: JobOptions = JobOptions()) -> list:
    """Simulate jobs [(SampleData, Params)] on the tests ``names`` (a list per job, or one list for all).

    Returns per job {test: SeriesSim | SweepSim}; series outputs on the simulator's grid (every sample
    while fine, then every coarse step) unless ``opts.full`` (every sample).
    """
    if names and isinstance(names[0], str):
        names = [names] * len(jobs)
    rows = _collect(jobs, names, opts)
    out = [dict() for _ in jobs]
    # constant-input rows: the series and the sweeps in separate batches when the series need the
    # full grid (a sweep only needs the mean over its averaging window)
    groups = [list(range(len(rows.const)))]
    if opts.full:
        groups = [[r for r, c in enumerate(rows.const) if c[2] is None],
                  [r for r, c in enumerate(rows.const) if c[2] is not None]]
    for group in groups:
        if group:
            _run_const(jobs, rows, group, opts, out)
    for key, grid_rows in rows.grid.items():
        (n, dt, hold, M), (pv, bl, Vs) = key, rows.gvals[key]
        for idx, sim in simulate_by_period(Runs(_param_columns(pv), np.array(bl), np.array(Vs), dt=dt, hold=hold)):
            for rr, r in enumerate(idx):
                j, name = grid_rows[r]
                out[j][name] = SeriesSim(sim.t[::M], sim.I[rr, ::M], sim.y[rr, ::M])     # the rig's samples
    return out


def residual_parts(sd: SampleData, sims: dict, names, robust_c: float | None = None) -> dict:
    """Normalized residuals (measured - simulated) / sigma: {(test, channel "y" | "I"): z array}.

    Sweep residuals pass through c*asinh(z/c) with c = ``robust_c`` (when given).
    """
    out = {}
    for name in names:
        if name not in sims:
            continue
        test = sd.tests[name]
        s = sims[name]
        if isinstance(s, SweepSim):
            ok = np.isfinite(s.y)            # gaps left out of a fit are NaN
            zy = (test.y[ok] - s.y[ok]) / test.sig_y
            zI = (test.I[ok] - s.I_A[ok]) / test.sig_I
            if robust_c:
                zy = robust_c * np.arcsinh(zy / robust_c)
                zI = robust_c * np.arcsinh(zI / robust_c)
        else:
            tl, Is, ys = s.t_s, s.I_A, s.y
            idx = test.k_on + np.rint(tl / test.dt).astype(np.intp)
            sel = (tl + test.step_delay_s > 0.0) | (test.V_on is None)
            idx, Is, ys = idx[sel], Is[sel], ys[sel]
            # a channel whose converter's rounding shapes its noise: the rounded reading's exact moments at the
            # readings' own level (fixed weights: the cost stays quadratic in the simulated values)
            zy = _standardized(test.y, idx, ys, test.weights_y, test.sig_y)
            zI = _standardized(test.I, idx, Is, test.weights_I, test.sig_I)
        out[(name, "y")] = zy
        out[(name, "I")] = zI
    return out


def _standardized(meas, idx, sim, weights, floor: float) -> np.ndarray:
    """(measured - simulated) / floor, or with a quantized channel's per-reading (offset, scale)."""
    if weights is None:
        return (meas[idx] - sim) / floor
    off, sc = weights
    return (meas[idx] - sim - off[idx]) / sc[idx]


def chi2_parts(parts: dict) -> dict:
    """{(test, channel): Chi2(chi-square, n)} of residual parts {(test, channel): z}."""
    return {k: Chi2(float(z @ z), int(z.size)) for k, z in parts.items()}


def full_traces(sd: SampleData, sims: dict) -> dict:
    """Simulated signals on the measured grids: {test: Trace} (coarse output steps interpolated)."""
    out = {}
    for name, s in sims.items():
        test = sd.tests[name]
        if isinstance(s, SweepSim):
            out[name] = Trace(kind="sweep", x=test.gaps * 1e3, y_meas=test.y, y_sim=s.y, I_meas=test.I,
                              I_sim=s.I_A, blocked=test.blocked)
            continue
        tl, Is, ys = s.t_s, s.I_A, s.y
        idx = test.k_on + np.rint(tl / test.dt).astype(np.intp)
        ok = idx < test.t.size
        yf = np.zeros(test.t.size)
        If = np.zeros(test.t.size)
        yf[idx[ok]] = ys[ok]
        If[idx[ok]] = Is[ok]
        # points the output grid skipped (coarse part) are interpolated
        have = np.zeros(test.t.size, dtype=bool)
        have[idx[ok]] = True
        have[:test.k_on] = True
        if not have.all():
            k = np.flatnonzero(have)
            miss = np.flatnonzero(~have)
            yf[miss] = np.interp(miss, k, yf[k])
            If[miss] = np.interp(miss, k, If[k])
        out[name] = Trace(kind="series", x=test.t, y_meas=test.y, y_sim=yf, I_meas=test.I, I_sim=If,
                          blocked=test.blocked)
    return out
