"""Settle-window truncation of the population runs (:mod:`harness.sim.mech`).

Once the current has stopped changing (I^2 within ``quiet_rtol`` of its final value), a candidate whose
energy distance from a stable equilibrium x_e, d = sqrt((x - x_e)^2 + m*v^2/k_e) with k_e the tangent
stiffness there, is below ``settle_rtol * max(|x_e|, x_scale)`` can never leave that neighbourhood again
(the energy only decreases under damping), so it is taken out of the integration and the rest of its
record is filled with x_e. Earlier still, as soon as d is small enough for the linearized motion to be
exact to the tolerance (|h2| d^2 / (2 k_e) + |h3| d^3 / (6 k_e), with h2, h3 the second and third
derivatives of the net restoring force at x_e), the rest of the record is the closed-form damped
oscillation about x_e (:func:`linear_tail`). Candidates resting on the coil face with the net force
pulling are settled at r0. Candidates that never settle are integrated to the end of the record. Settle
checks happen at absolute sample indices, so a candidate's record is bit-for-bit the same whatever else
is in the batch. Units: SI.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Block", "GroupState", "TailStart", "check", "settled", "linear_tail"]


@dataclass(frozen=True)
class Block:
    """Output block of a population run: x [m] at sample ``k_begin + row`` in H, the columns ``cols``
    of the candidates concerned."""

    H: np.ndarray
    k_begin: int
    cols: np.ndarray


@dataclass
class GroupState:
    """Mutable record of a group's integration: the active candidates (index into the group's
    original list), their columns, state x [m], v [m/s], contact flags, per-candidate record
    lengths n_t and quiet-current samples k_quiet, and the results so far (``out``)."""

    active: np.ndarray
    cols: np.ndarray
    x: np.ndarray
    v: np.ndarray
    contact: np.ndarray
    nt: np.ndarray
    kq: np.ndarray
    out: dict

    def keep(self, keep) -> None:
        """Drop the active candidates where keep is False."""
        self.active = self.active[keep]
        self.cols = self.cols[keep]
        self.x, self.v, self.contact = self.x[keep], self.v[keep], self.contact[keep]


@dataclass(frozen=True)
class TailStart:
    """Start of a linear tail: state x [m], v [m/s], equilibrium xe [m], tangent stiffness ke [N/m]."""

    x: np.ndarray
    v: np.ndarray
    xe: np.ndarray
    ke: np.ndarray


def check(g, st: GroupState, k: int, settle_rtol: float, linear_tol: float, block: Block, dt: float):
    """Settle check at sample k; records the settled candidates in st.out (and writes the linear tails
    into the block); returns the mask of the active candidates that leave the integration."""
    active, out = st.active, st.out
    done = np.zeros(active.size, dtype=bool)
    chk = k >= st.kq[active]
    if settle_rtol > 0 and chk.any():
        sel = np.flatnonzero(chk)
        ok, xe, lin, ke = settled(g, sel, st.x, st.v, st.contact, settle_rtol, linear_tol)
        done[sel[ok]] = True
        idx = active[sel[ok]]
        out["settled"][idx] = True
        out["k_fill"][idx] = k + 1
        out["x_fill"][idx] = xe[ok]
        if lin.any():
            q = sel[lin]
            start = TailStart(x=st.x[q], v=st.v[q], xe=xe[lin], ke=ke[lin])
            sub = Block(H=block.H, k_begin=block.k_begin, cols=st.cols[q])
            n_rows, reached = linear_tail(g, q, start, k, st.nt[active[q]], dt, settle_rtol, sub)
            done[q] = True
            idx = active[q]
            out["settled"][idx] = reached
            out["k_fill"][idx] = np.where(reached, k + 1 + n_rows, st.nt[active[q]])
            out["x_fill"][idx] = np.where(reached, xe[lin], np.nan)
            out["last"] = max(out["last"], int((k + n_rows).max()) - block.k_begin)
    done |= k >= st.nt[active] - 1
    return done


def linear_tail(g, q, start: TailStart, k: int, n_t, dt: float, settle_rtol: float, block: Block):
    """Write the exact solution of the linearized motion about x_e into H from sample k+1 on.

    m*d'' + C*d' + k_e*d = 0 with d = x - x_e, from (d0, v0) at sample k:
    d(tau) = A*exp(l1*tau) + B*exp(l2*tau), l1,2 = -sigma +- sqrt(sigma^2 - k_e/m) (complex
    when underdamped), evaluated by cumulative products of exp(l*dt) on the sample grid;
    near critical damping (|l1 - l2| < 1e-3 sigma) the limit (d0 + (v0 + sigma*d0)*tau)*exp(-sigma*tau).
    Written until an upper bound of |d| falls below the settle tolerance (the record is
    then filled with x_e) or the record ends. Returns (rows written, tolerance reached).
    """
    m, C = g.m[q], g.C[q]
    xe, ke = start.xe, start.ke
    d0 = start.x - xe
    v0 = start.v
    H, k_begin, cols = block.H, block.k_begin, block.cols
    sig = C / (2.0 * m)
    w02 = ke / m
    disc = (sig * sig - w02).astype(complex)
    mu = np.sqrt(disc)                                  # real (over) or imaginary (under)
    crit = np.abs(mu) < 1e-3 * sig
    l1, l2 = -sig + mu, -sig - mu
    den = np.where(crit, 1.0, l1 - l2)
    A = np.where(crit, 0.0, (v0 - l2 * d0) / den)
    B = d0 - A
    rate = -l1.real                                     # slowest decay rate
    tol = settle_rtol * np.maximum(np.abs(xe), g.xsc[q])
    c_exp = np.where(crit, np.inf, np.abs(A) + np.abs(B))
    c1 = np.abs(d0)
    c2 = np.abs(v0 + sig * d0)

    def bound(tau):
        e = np.exp(-rate * tau)
        return e * np.minimum(c_exp, c1 + c2 * tau)

    t_max = np.maximum((n_t - 1 - k) * dt, dt)
    # the bound decreases monotonically after its peak at 1/rate - c1/c2: bisection there
    with np.errstate(divide="ignore", invalid="ignore"):
        t_peak = np.where(c2 > 0, 1.0 / rate - c1 / np.where(c2 > 0, c2, 1.0), 0.0)
    lo = np.clip(np.nan_to_num(t_peak, nan=0.0, posinf=0.0), 0.0, t_max)
    hi = t_max.copy()
    for _ in range(24):
        mid = 0.5 * (lo + hi)
        ok = bound(mid) <= tol
        hi = np.where(ok, mid, hi)
        lo = np.where(ok, lo, mid)
    reached = bound(hi) <= tol
    n_rows = np.clip(np.ceil(hi / dt).astype(np.intp), 1, np.maximum(n_t - 1 - k, 1))
    # chunks of similar length (powers of two) so that the blocks are not much longer than needed
    bins = np.ceil(np.log2(n_rows)).astype(np.intp)
    for b in np.unique(bins):
        sel = np.flatnonzero(bins == b)
        N = int(n_rows[sel].max())
        tau = (np.arange(1, N + 1) * dt)[:, None]
        z1 = np.cumprod(np.broadcast_to(np.exp(l1[sel] * dt), (N, sel.size)), axis=0)
        z2 = np.cumprod(np.broadcast_to(np.exp(l2[sel] * dt), (N, sel.size)), axis=0)
        d = (A[sel] * z1 + B[sel] * z2).real
        cr = crit[sel]
        if cr.any():
            e = np.exp(-sig[sel][cr] * tau)
            d[:, cr] = (d0[sel][cr] + (v0[sel][cr] + sig[sel][cr] * d0[sel][cr]) * tau) * e
        H[k + 1 - k_begin:k + 1 + N - k_begin, cols[sel]] = xe[sel] + d
    return n_rows, reached


def settled(g, sel, x, v, contact, settle_rtol: float, linear_tail: float = 0.0):
    """Settle test for the elements sel at a steady current.

    Returns (settled, x_e, linear, k_e): settled: energy distance
    d = sqrt((x - x_e)^2 + m v^2 / k_e) from the nearest stable equilibrium x_e below
    tol = settle_rtol * max(|x_e|, x_scale) (or resting on the coil face where that is
    stable); linear: not settled yet, but so close that the linearized motion is exact to
    linear_tail * max(|x_e|, x_scale): |h2| d^2 / (2 k_e) + |h3| d^3 / (6 k_e) below it,
    with h2, h3 the second and third derivatives of the net restoring force at x_e
    (linear_tail = 0: never).
    """
    xc, vc, cc = x[sel], v[sel], contact[sel]
    eqx, eqk, eq2, eq3 = g.eqx[sel], g.eqk[sel], g.eq2[sel], g.eq3[sel]
    if eqx.shape[1] == 1:
        xe, ke, h2, h3 = eqx[:, 0], eqk[:, 0], eq2[:, 0], eq3[:, 0]
    else:
        d = np.abs(xc[:, None] - eqx)
        d = np.where(np.isnan(d), np.inf, d)
        near = np.argmin(d, axis=1)
        r = np.arange(sel.size)
        xe, ke, h2, h3 = eqx[r, near], eqk[r, near], eq2[r, near], eq3[r, near]
    with np.errstate(invalid="ignore"):
        dist2 = (xc - xe) ** 2 + g.m[sel] * vc * vc / ke
        tol = settle_rtol * np.maximum(np.abs(xe), g.xsc[sel])
        okf = (~cc) & (dist2 <= tol * tol)
        dd = np.sqrt(dist2)
        lin_tol = tol * (float(linear_tail) / settle_rtol) if linear_tail else 0.0
        lin = (~cc) & ~okf & ((np.abs(h2) * dist2 / (2 * ke) + np.abs(h3) * dd * dist2 / (6 * ke)) <= lin_tol)
    okc = cc & g.cstab[sel]
    ok = okf | okc
    if not linear_tail:
        lin = np.zeros_like(lin)
    xe_out = np.where(okc, g.r0e[sel], np.where(okf | lin, xe, np.nan))
    return ok, xe_out, lin, ke

