"""Stepping of the population runs (:mod:`harness.sim.population`): classic RK4 on the mechanical state
(x [m], v [m/s]) of a group of candidates with the same sub-step count, the current prescribed (exact
zero-order-hold RL solution at the stage times), the force from the test's
:class:`harness.sim.kernels.ForceTable`, the acceleration from :func:`fmu_src.diaphragm.acceleration`;
contact events with the FMU's semantics (:mod:`harness.sim.contact`); settle checks and linear tails
(:mod:`harness.sim.settle`). Units: SI.
"""
from __future__ import annotations

import copy
import numpy as np
from scipy.optimize import brentq

from fmu_src.diaphragm import acceleration

from . import settle
from .settle import Block, GroupState
from .contact import hermite_crossing
from .settings import PopulationSettings

__all__ = ["Block", "CandidateGroup", "run_group"]


class CandidateGroup:
    """Per-element constants of the candidates integrated together (one sub-step count)."""

    def __init__(self, tests, tid, C, m):
        self.single = len(set(tid.tolist())) == 1
        self.tid = tid
        T = [tests[i] for i in tid] if not self.single else None
        t0 = tests[int(tid[0])]
        offs = np.cumsum([0] + [ts.table.rows.shape[0] for ts in tests])
        self.table = np.vstack([ts.table.rows for ts in tests]) if len(tests) > 1 else tests[0].table.rows
        self.off = None
        if self.single:
            self.K1, self.K2, self.r0 = t0.K1, t0.K2, t0.r0
            self.inv = t0.table.inv_dr
            self.A = t0.r0 * t0.table.inv_dr + t0.table.n_ext
            self.off = int(offs[int(tid[0])]) or None
        else:
            self.K1 = np.array([ts.K1 for ts in T])
            self.K2 = np.array([ts.K2 for ts in T])
            self.r0 = np.array([ts.r0 for ts in T])
            self.inv = np.array([ts.table.inv_dr for ts in T])
            self.A = np.array([ts.r0 * ts.table.inv_dr + ts.table.n_ext for ts in T])
            self.off = offs[tid].astype(np.intp)
        self.C = np.asarray(C, dtype=float).copy()
        self.m = np.asarray(m, dtype=float).copy()
        # settle data per element: stable free equilibria (padded with NaN), stiffness there,
        # whether resting on the coil face is stable, length scale; stiffness bound
        E = max(1, max(tests[int(i)].eq_x.size for i in np.unique(tid)))
        eqx, eqk, eq2, eq3 = (np.full((len(tests), E), np.nan) for _ in range(4))
        for i in np.unique(tid):
            ts = tests[int(i)]
            eqx[i, :ts.eq_x.size] = ts.eq_x
            eqk[i, :ts.eq_k.size] = ts.eq_k
            eq2[i, :ts.eq_k.size] = ts.eq_h2
            eq3[i, :ts.eq_k.size] = ts.eq_h3
        self.eqx, self.eqk, self.eq2, self.eq3 = eqx[tid], eqk[tid], eq2[tid], eq3[tid]
        self.lin_k = np.full(tid.size, np.nan)
        self.cstab = np.array([tests[int(i)].contact_stable for i in range(len(tests))])[tid]
        self.xsc = np.array([tests[int(i)].x_scale for i in range(len(tests))])[tid]
        self.kmax = np.array([tests[int(i)].k_max for i in range(len(tests))])[tid]
        self.r0e = np.array([tests[int(i)].r0 for i in range(len(tests))])[tid]

    _PER_ELEMENT = ("tid", "C", "m", "eqx", "eqk", "eq2", "eq3", "lin_k", "cstab", "xsc", "kmax", "r0e")

    def compact(self, keep):
        for name in self._PER_ELEMENT:
            setattr(self, name, getattr(self, name)[keep])
        if not self.single:
            for name in ("K1", "K2", "r0", "inv", "A", "off"):
                setattr(self, name, getattr(self, name)[keep])

    def subset(self, sel) -> "CandidateGroup":
        """A copy restricted to the elements sel (shares the table)."""
        sub = copy.copy(self)
        sub.compact(sel)
        return sub

    def force(self, x, I2):
        """Em*I^2*G(r0 - x) [N] at x [m] and current squared I2 [A^2] (uniform-grid table gather, linear interpolation on a fine grid)."""
        s = self.A - x * self.inv        # r/dr + n_ext: the same numbers whatever else is in the batch
        i = s.astype(np.intp)
        w = s - i
        if self.off is not None:
            i += self.off
        # out-of-table indices are clipped (the end rows are then extrapolated; below r = 0 the
        # continuation is linear anyway, beyond r_max the diaphragm cannot be)
        c = self.table.take(i, axis=0, mode="clip")
        g = c[:, 1] * w
        g += c[:, 0]
        g *= I2
        return g

    def acc(self, x, v, I2):
        return acceleration(x, v, self.force(x, I2), self.K1, self.K2, self.C, self.m)


def _rk4(g: CandidateGroup, x, v, h, I2a, I2m, I2b):
    """One classic RK4 step of size h [s] (scalar or per-element array) with I^2 at start/mid/end."""
    a1 = g.acc(x, v, I2a)
    hh = 0.5 * h
    x2 = x + hh * v
    v2 = v + hh * a1
    a2 = g.acc(x2, v2, I2m)
    x3 = x + hh * v2
    v3 = v + hh * a2
    a3 = g.acc(x3, v3, I2m)
    x4 = x + h * v3
    v4 = v + h * a3
    a4 = g.acc(x4, v4, I2b)
    h6 = h / 6.0
    xn = x + h6 * (v + 2.0 * (v2 + v3) + v4)
    vn = v + h6 * (a1 + 2.0 * (a2 + a3) + a4)
    return xn, vn


def _i2_at(tests, tid, t):
    """I^2 [A^2] at times t (per element) for elements of tests tid."""
    out = np.empty(t.shape)
    for ti in np.unique(tid):
        sel = tid == ti
        out[sel] = tests[int(ti)].current_at(t[sel]) ** 2
    return out


def _partial_steps(tests, g: CandidateGroup, sel, state, span, n_sub):
    """Integrate elements sel of group g from state (x, v) over span (ts, te) (arrays of times [s]) with
    n_sub RK4 steps (exact current)."""
    x, v = state
    ts, te = span
    sub = g.subset(sel)
    xs, vs = x[sel].copy(), v[sel].copy()
    h = (te - ts) / n_sub
    for j in range(n_sub):
        ta = ts + j * h
        I2a = _i2_at(tests, sub.tid, ta)
        I2m = _i2_at(tests, sub.tid, ta + 0.5 * h)
        I2b = _i2_at(tests, sub.tid, ta + h)
        xs, vs = _rk4(sub, xs, vs, h, I2a, I2m, I2b)
    return xs, vs



def _events(tests, g: CandidateGroup, k, before, after, contact, n_sub):
    """Impacts on and releases from the coil face during interval k (FMU semantics, harness.sim.contact);
    before/after: (x, v) at the interval's start and end."""
    x0, v0 = before
    x1, v1 = after
    x1 = x1.copy()
    v1 = v1.copy()
    contact = contact.copy()
    r0 = g.r0 if not np.isscalar(g.r0) else np.full(x1.size, g.r0)
    dtv = np.array([tests[i].dt for i in g.tid]) if not g.single else tests[int(g.tid[0])].dt
    t0v = np.array([tests[i].t0 for i in g.tid]) if not g.single else tests[int(g.tid[0])].t0
    tk = t0v + k * dtv
    te = tk + dtv
    tk = np.broadcast_to(tk, x1.shape).astype(float)
    te = np.broadcast_to(te, x1.shape).astype(float)
    I2e = _i2_at(tests, g.tid, te)
    net_e = _net_contact(tests, g.tid, I2e)
    # candidates that were resting on the face during the whole interval
    rest = np.flatnonzero(contact)
    release_from = np.full(x1.size, np.nan)
    if rest.size:
        stay = net_e[rest] >= 0.0
        x1[rest] = r0[rest]
        v1[rest] = 0.0
        rel = rest[~stay]
        if rel.size:
            release_from[rel] = _release_time(tests, g.tid[rel], tk[rel], te[rel])
    # impacts of free candidates
    hit = np.flatnonzero(~contact & (x1 > r0))
    if hit.size:
        s = hermite_crossing(x0[hit], v0[hit], x1[hit], v1[hit], te[hit] - tk[hit], r0[hit])
        tc = tk[hit] + s * (te[hit] - tk[hit])
        net_c = _net_contact(tests, g.tid[hit], _i2_at(tests, g.tid[hit], tc))
        x1[hit] = r0[hit]
        v1[hit] = 0.0
        stick = net_c >= 0.0
        contact[hit[stick]] = True
        # stuck at impact but released before the end of the interval
        st = hit[stick]
        late = st[net_e[st] < 0.0]
        if late.size:
            tcs = tc[stick][net_e[st] < 0.0]
            release_from[late] = np.maximum(_release_time(tests, g.tid[late], tk[late], te[late]), tcs)
        # bounced off at once (net force pushes away at the impact instant): free from (r0, 0) at tc
        nb = hit[~stick]
        if nb.size:
            release_from[nb] = tc[~stick]
    rel = np.flatnonzero(np.isfinite(release_from))
    if rel.size:
        contact[rel] = False
        xs = np.array(x1)
        vs = np.array(v1)
        xs[rel] = r0[rel]
        vs[rel] = 0.0
        xr, vr = _partial_steps(tests, g, rel, (xs, vs), (release_from[rel], te[rel]), n_sub)
        again = xr >= r0[rel]
        xr[again] = r0[rel][again]
        vr[again] = 0.0
        contact[rel[again]] = net_e[rel[again]] >= 0.0
        x1[rel] = xr
        v1[rel] = vr
    return x1, v1, contact


def _net_contact(tests, tid, I2):
    out = np.empty(I2.shape)
    for ti in np.unique(tid):
        sel = tid == ti
        out[sel] = tests[int(ti)].net_contact_force(I2[sel])
    return out


def _release_time(tests, tid, tk, te):
    """Instant in [tk, te] at which the net contact force turns negative (exact current)."""
    out = np.empty(tk.shape)
    for q in range(tk.size):
        ts = tests[int(tid[q])]
        f = lambda t: float(ts.net_contact_force(ts.current_at(np.array([t]))[0] ** 2))  # noqa: E731
        a, b = float(tk[q]), float(te[q])
        fa = f(a)
        if fa < 0.0:
            out[q] = a
        else:
            out[q] = brentq(f, a, b, xtol=1e-15) if f(b) < 0.0 else b
    return out


def _current_nodes(tests, g: CandidateGroup, n_sub: int):
    """I^2 [A^2] at the RK4 stage times: (n_t-1, 2 n_sub+1) of the group's test, or stacked per test
    (n_tests, n_rows, 2 n_sub+1) when the group mixes tests."""
    uniq = np.unique(g.tid)
    if g.single:
        return tests[int(uniq[0])].i2_nodes(n_sub)
    n_rows = max(tests[int(i)].n_t for i in uniq) - 1
    used = set(uniq.tolist())
    stack = []
    for i in range(len(tests)):
        if i in used:
            a = tests[i].i2_nodes(n_sub)
            if a.shape[0] < n_rows:
                a = np.vstack([a, np.repeat(a[-1:], n_rows - a.shape[0], axis=0)])
            stack.append(a)
        else:
            stack.append(np.zeros((n_rows, 2 * n_sub + 1)))
    return np.stack(stack)


def run_group(tests, g: CandidateGroup, n_sub: int, settings: PopulationSettings, block: Block):
    """Integrate one group of candidates (same sub-step count) writing x [m] into block.H[:, block.cols].

    Returns k_fill, x_fill, settled, candidate steps, last row written.
    """
    n = g.tid.size
    nt_e = np.array([tests[i].n_t for i in g.tid])
    out = {"k_fill": nt_e.copy(), "x_fill": np.full(n, np.nan), "settled": np.zeros(n, dtype=bool),
           "steps": 0, "last": 0}
    st = GroupState(active=np.arange(n), cols=np.asarray(block.cols).copy(), x=np.zeros(n), v=np.zeros(n),
                    contact=np.zeros(n, dtype=bool), nt=nt_e, kq=np.array([tests[i].k_quiet for i in g.tid]),
                    out=out)
    k_last = int(nt_e.max()) - 1
    ends = set((nt_e - 1).tolist())
    nodes = _current_nodes(tests, g, n_sub)
    dt = tests[int(g.tid[0])].dt
    h = dt / n_sub
    H, k_begin = block.H, block.k_begin
    H[0, st.cols] = 0.0
    k = k_begin
    while k < k_last and st.active.size:
        # ---- one sample interval [t_k, t_k+1]
        x, v = st.x, st.v
        Nk = nodes[k] if g.single else nodes[g.tid, k, :].T
        for j in range(n_sub):
            x, v = _rk4(g, x, v, h, Nk[2 * j], Nk[2 * j + 1], Nk[2 * j + 2])
        out["steps"] += st.active.size
        # ---- contact events
        if st.contact.any() or np.any(x > g.r0):
            x, v, st.contact = _events(tests, g, k, (st.x, st.v), (x, v), st.contact, n_sub)
        st.x, st.v = x, v
        k += 1
        H[k - k_begin, st.cols] = x
        out["last"] = max(out["last"], k - k_begin)
        # ---- settle check / end of a record
        regular = k % settings.check_every == 0       # absolute sample index: independent of the batch
        if regular or k >= k_last or k + 1 in ends:
            if regular:
                done = settle.check(g, st, k, settings.settle_rtol, settings.linear_tol, block, dt)
            else:
                done = k >= nt_e[st.active] - 1
            if done.any():
                keep = ~done
                st.keep(keep)
                g.compact(keep)
    return out["k_fill"], out["x_fill"], out["settled"], out["steps"], out["last"]
