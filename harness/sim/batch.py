"""Batched integration of the diaphragm for a whole population of (C, m) candidates.

The identification (paper section 3) simulates the step tests T3 and T5 for
every candidate (C, m) of an NSGA-II population. Everything except C and m is
fixed for a test, so the work that does not depend on them is done once:

* the coil current I(t) follows from the measured voltage alone (exact RL
  solution with the voltage held over each sample interval, zero-order hold,
  as in :func:`fmu_src.model.simulate`), including its values at the Runge-Kutta
  stage times;
* the force kernel (:class:`fmu_src.field.ForceKernel`) is turned into one table of
  Em*G(r) on a uniform grid 16 times finer than the kernel's spline, gathered per
  candidate with linear interpolation (error ~1e-8 of G);
* the static equilibria at the final current (they do not depend on C and m).

The mechanical state (x [m], v [m/s]) of all candidates is then advanced
together with the classic 4th-order Runge-Kutta method on the data grid,
``n_sub`` equal sub-steps per sample interval, chosen per candidate from its
stiffness (so a candidate's trajectory does not depend on the other
candidates in the batch). The right-hand side is :func:`fmu_src.diaphragm.acceleration`
with F = Em*I(t)^2*G(r0 - x), the same physics as the scalar model.

Contact with the coil face (x = r0) is handled as in :mod:`fmu_src.model`: a
perfectly inelastic impact (x = r0, v = 0), the diaphragm rests while the net
force Em*I^2*G(0) - (K1*r0^2 + K2)*r0 pulls toward the coil and is released
when it changes sign. Impact and release instants inside a sample interval are
located (cubic Hermite interpolation of the step for the impact, the exact
current for the release) and the rest of the interval is integrated from there.

Step size: RK4 sub-steps per sample interval (a power of two per candidate) keep
omega*h and the accumulated phase error (about (omega h)^4 / (240 pi zeta^2) of the
amplitude) below ``rk_tol`` and (C/m)*h below 2 (a fast overdamped mode), with omega and
zeta from the largest tangent stiffness the test can reach.

Settle-window truncation: once the current has stopped changing (I^2 within
``quiet_rtol`` of its final value), a candidate whose energy distance from a stable
equilibrium x_e, d = sqrt((x - x_e)^2 + m*v^2/k_e) with k_e the tangent stiffness
there, is below ``settle_rtol * max(|x_e|, x_scale)`` can never leave that
neighbourhood again (the energy only decreases under damping), so it is taken out of
the integration and the rest of its record is filled with x_e. Earlier still, as soon
as d is small enough for the linearized motion to be exact to the tolerance
(|h2| d^2 / (2 k_e) + |h3| d^3 / (6 k_e), with h2, h3 the second and third derivatives
of the net restoring force at x_e), the rest of the record is the closed-form damped
oscillation about x_e (``linear_tail``). Candidates resting on the coil face with the
net force pulling are settled at r0. Candidates that never settle are integrated to the
end of the record. Settle checks happen at absolute sample indices, so a candidate's
record is bit-for-bit the same whatever else is in the batch.

Units: SI throughout (s, V, A, Ohm, H, m, m/s, N, kg).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq
from scipy.signal import lfilter

from fmu_src.diaphragm import acceleration, spring_force, tangent_stiffness
from fmu_src.field import ForceKernel, make_kernel

__all__ = ["zoh_current", "MechTest", "prepare_test", "BatchResult", "integrate", "integrate_one",
           "substeps_for"]

# RK4 steps h are chosen so that the phase error of the oscillation, about
# (omega h)^4 / (240 pi zeta^2) of its amplitude summed over its decay, stays below rk_tol,
# with omega*h <= _ACC_OMEGA_H, and (C/m)*h <= _STAB_DAMP_H (stability of a fast overdamped
# mode); omega and zeta use the largest tangent stiffness the test can reach.
_ACC_OMEGA_H = 0.5
TABLE_REFINE = 16     # force-table nodes per spline segment of the ForceKernel
_STAB_DAMP_H = 2.0


# ----------------------------------------------------------------------------- current
def zoh_current(t, V, R: float, L: float, I0: float = 0.0) -> np.ndarray:
    """Coil current [A] on the grid t [s] for the voltage V [V] held over each interval.

    Exact solution of V = R*I + L*dI/dt with V[k] applied on [t[k], t[k+1])
    (zero-order hold), starting from I0 [A] at t[0]. R in Ohm, L in H.
    """
    t = np.asarray(t, dtype=float)
    V = np.asarray(V, dtype=float)
    if t.shape != V.shape or t.ndim != 1:
        raise ValueError(f"t and V must be 1-D arrays of the same length, got {t.shape} and {V.shape}")
    if not (R > 0 and L > 0 and math.isfinite(R) and math.isfinite(L)):
        raise ValueError(f"R [Ohm] and L [H] must be positive and finite, got R={R!r}, L={L!r}")
    dt = np.diff(t)
    if dt.size and np.allclose(dt, dt[0], rtol=1e-9, atol=0.0):
        a = math.exp(-dt[0] * R / L)
        # I[k+1] = a*I[k] + (1 - a)*V[k]/R
        y, _ = lfilter([0.0, (1.0 - a) / R], [1.0, -a], V, zi=[a * I0])
        y[0] = I0
        return y
    I = np.empty_like(t)
    I[0] = I0
    a = np.exp(-dt * R / L)
    for k in range(dt.size):
        I[k + 1] = a[k] * I[k] + (1.0 - a[k]) * V[k] / R
    return I


# ----------------------------------------------------------------------------- one test
@dataclass
class MechTest:
    """Everything about one test that does not depend on C and m (see :func:`prepare_test`)."""
    t0: float                 # first sample time [s]
    dt: float                 # sample period [s]
    n_t: int                  # number of samples
    V: np.ndarray             # voltage [V], V[k] held on [t_k, t_k+1)
    I: np.ndarray             # current on the grid [A]
    R: float                  # [Ohm]
    L: float                  # [H]
    r0: float                 # gap [m]
    Em: float                 # [N.m/T^2]
    K1: float                 # [N/m^3]
    K2: float                 # [N/m]
    kernel: ForceKernel
    k_start: int              # first interval with a non-zero input (state is at rest before)
    k_quiet: int              # from this sample on, I^2 stays within a tiny tolerance of I_end^2
    I2_end: float             # final current squared [A^2]
    eq_x: np.ndarray          # stable free equilibria at I_end [m]
    eq_k: np.ndarray          # tangent stiffness there [N/m]
    eq_h2: np.ndarray         # second derivative of the net restoring force there [N/m^2]
    eq_h3: np.ndarray         # third derivative [N/m^3]
    contact_stable: bool      # resting on the coil face is stable at I_end
    x_scale: float            # length scale for the settle tolerance [m]
    k_max: float              # upper bound of the tangent stiffness over the reachable range [N/m]
    # Em*G(r0 - x) table: rows of cubic coefficients in w in [0, 1) of a segment of width dr
    table: np.ndarray = field(repr=False)
    inv_dr: float = 0.0       # 1/dr [1/m] of the force table
    n_ext: int = 0            # number of table rows below r = 0 (linear continuation of G)
    _nodes: dict = field(default_factory=dict, repr=False)

    @property
    def t(self) -> np.ndarray:
        return self.t0 + self.dt * np.arange(self.n_t)

    @property
    def G0(self) -> float:
        return self.kernel.G0

    def net_contact_force(self, I2):
        """Magnetic minus spring force [N] on the coil face for current squared I2 [A^2]."""
        return self.Em * np.asarray(I2) * self.kernel.G0 - spring_force(self.r0, self.K1, self.K2)

    def i2_nodes(self, n_sub: int) -> np.ndarray:
        """I^2 [A^2] at the 2*n_sub + 1 equally spaced RK4 stage times of each interval, shape (n_t-1, 2n_sub+1)."""
        arr = self._nodes.get(n_sub)
        if arr is None:
            frac = np.arange(2 * n_sub + 1) / (2.0 * n_sub)
            Vr = self.V[:-1, None] / self.R
            arr = Vr + (self.I[:-1, None] - Vr) * np.exp(-frac[None, :] * self.dt * self.R / self.L)
            arr = np.ascontiguousarray(arr * arr)
            self._nodes[n_sub] = arr
        return arr

    def current_at(self, t) -> np.ndarray:
        """Exact current [A] at arbitrary times t [s] inside the record (array)."""
        t = np.asarray(t, dtype=float)
        k = np.clip(np.floor((t - self.t0) / self.dt + 1e-9).astype(np.intp), 0, self.n_t - 2)
        tk = self.t0 + k * self.dt
        Vr = self.V[k] / self.R
        return Vr + (self.I[k] - Vr) * np.exp(-(t - tk) * self.R / self.L)


def _x_table(kernel: ForceKernel, Em: float, r_lo: float, r_hi: float, dr: float) -> tuple[np.ndarray, int]:
    """Em*G(r) [N/A^2] tabulated for a gather with linear interpolation: rows (v_j, v_{j+1} - v_j).

    Nodes r_j = (j - n_ext)*dr from r_lo <= 0 to r_hi, values from the kernel spline
    (``ForceKernel.eval``, including its linear continuation below r = 0). With dr a
    sixteenth of the spline's spacing the interpolation error is ~1e-8 of G (it is
    (dr^2/8)|G''|), far below the integration tolerance, and the gather costs half the
    numpy calls of a cubic Horner evaluation. Returns (table, n_ext).
    """
    n_ext = int(math.ceil(-r_lo / dr))
    n = int(math.ceil(r_hi / dr)) + 1
    r = (np.arange(-n_ext, n + 1)) * dr
    v = Em * kernel.eval(r)
    return np.ascontiguousarray(np.column_stack([v[:-1], np.diff(v)])), n_ext


def _stable_equilibria(kernel: ForceKernel, r0, Em, K1, K2, I2):
    """Stable free equilibria x [m] in [0, r0) at current squared I2 [A^2].

    Roots of the net restoring force h(x) = K1 x^3 + K2 x - Em I2 G(r0 - x) with h' > 0.
    Returns (x, h', h'', h''') as arrays (derivatives in N/m, N/m^2, N/m^3).
    """
    xs = np.linspace(0.0, r0, 4001)
    h = spring_force(xs, K1, K2) - Em * I2 * kernel.eval(r0 - xs)

    def hf(x):
        return spring_force(x, K1, K2) - Em * I2 * float(kernel(r0 - x))

    def dh(x):
        return tangent_stiffness(x, K1, K2) + Em * I2 * float(kernel.derivative(r0 - x))

    roots = [0.0] if h[0] == 0.0 else []
    for i in np.flatnonzero(np.sign(h[:-1]) * np.sign(h[1:]) < 0):
        roots.append(brentq(hf, xs[i], xs[i + 1], xtol=1e-15, rtol=1e-14))
    out = []
    for x in roots:
        k = dh(x)
        if k > 0:
            e = max(1e-3 * r0, 1e-7)
            h2 = (dh(x + e) - dh(x - e)) / (2 * e)
            h3 = (dh(x + e) - 2 * k + dh(x - e)) / (e * e)
            out.append((x, k, h2, h3))
    arr = np.array(out, dtype=float).reshape(-1, 4)
    return arr[:, 0], arr[:, 1], arr[:, 2], arr[:, 3]


def prepare_test(t, V, R: float, L: float, r0: float, Em: float, K1: float, K2: float,
                 kernel: ForceKernel | None = None, a: float | None = None, D: float | None = None,
                 kB: float | None = None, I0: float = 0.0, quiet_rtol: float = 1e-6) -> MechTest:
    """Precompute one test for :func:`integrate`.

    Parameters (SI): t [s] uniform grid; V [V] measured voltage, V[k] held on
    [t[k], t[k+1]); R [Ohm], L [H] coil; r0 [m] gap; Em [N.m/T^2]; K1 [N/m^3];
    K2 [N/m]; kernel: a :class:`ForceKernel` covering r in [0, 2*r0 + 0.02]
    (default ``make_kernel(a, D, kB, r0)``); I0 [A] initial current.
    The diaphragm starts at rest at x = 0.
    """
    t = np.asarray(t, dtype=float)
    V = np.asarray(V, dtype=float)
    if t.ndim != 1 or t.size < 2 or V.shape != t.shape:
        raise ValueError(f"t and V must be 1-D arrays of the same length >= 2, got {t.shape} and {V.shape}")
    dt = float((t[-1] - t[0]) / (t.size - 1))
    if not (dt > 0) or np.max(np.abs(np.diff(t) - dt)) > 1e-6 * dt:
        raise ValueError("batched integration needs a uniform, increasing time grid")
    for name, val, pos in (("R", R, True), ("L", L, True), ("r0", r0, True), ("Em", Em, False),
                           ("K1", K1, False), ("K2", K2, True)):
        if not math.isfinite(val) or (val <= 0 if pos else val < 0):
            raise ValueError(f"parameter {name} must be {'> 0' if pos else '>= 0'} and finite, got {val!r}")
    if kernel is None:
        if a is None or D is None or kB is None:
            raise ValueError("give either kernel or a, D and kB")
        kernel = make_kernel(a, D, kB, r0)
    I = zoh_current(t, V, R, L, I0)
    nz = np.flatnonzero((V != 0.0) | (I != 0.0))
    k_start = int(nz[0]) if nz.size else t.size - 1
    I2 = I * I
    I2_end = float(I2[-1])
    scale = max(float(np.max(I2)), 1e-300)
    dev = np.abs(I2 - I2_end) > quiet_rtol * scale
    last = np.flatnonzero(dev)
    k_quiet = int(last[-1]) + 1 if last.size else 0
    eq_x, eq_k, eq_h2, eq_h3 = _stable_equilibria(kernel, r0, Em, K1, K2, I2_end)
    eq_max = _stable_equilibria(kernel, r0, Em, K1, K2, float(np.max(I2)))[0]
    contact_stable = bool(Em * I2_end * kernel.G0 - spring_force(r0, K1, K2) >= 0.0)
    x_scale = max([abs(x) for x in eq_x] + [abs(eq_max[0]) if eq_max.size else r0] + [1e-3 * r0])
    # stiffness bound over the range the diaphragm can reach (up to the coil face)
    I2_max = float(np.max(I2))
    x_hi = min(r0, 2.0 * float(np.max(eq_x)) + 0.05e-3) if eq_x.size else r0
    xg = np.linspace(0.0, x_hi, 201)
    k_mag = Em * I2_max * np.max(np.abs(kernel.derivative(r0 - xg)))
    k_max = float(tangent_stiffness(x_hi, K1, K2) + k_mag)
    dr = kernel.r_max / (TABLE_REFINE * 1200)
    table, n_ext = _x_table(kernel, Em, -r0 - 4 * dr, kernel.r_max, dr)
    return MechTest(t0=float(t[0]), dt=dt, n_t=int(t.size), V=V, I=I, R=float(R), L=float(L), r0=float(r0),
                    Em=float(Em), K1=float(K1), K2=float(K2), kernel=kernel, k_start=k_start, k_quiet=k_quiet,
                    I2_end=I2_end, eq_x=eq_x, eq_k=eq_k, eq_h2=eq_h2, eq_h3=eq_h3, contact_stable=contact_stable, x_scale=x_scale,
                    k_max=k_max, table=table, inv_dr=1.0 / dr, n_ext=n_ext)


def _max_step(kmax, C, m, rk_tol: float = 1e-4):
    """Largest RK4 step [s] for the accuracy/stability rules (see the comment at _ACC_OMEGA_H).

    rk_tol: tolerated phase error of the oscillation relative to its amplitude, summed over
    its decay: (omega h)^4 / (240 pi zeta^2) <= rk_tol, omega h <= _ACC_OMEGA_H.
    """
    omega = np.sqrt(kmax / m)
    zeta = np.maximum(C / (2.0 * np.sqrt(kmax * m)), 1e-3)
    oh = np.minimum(_ACC_OMEGA_H, (240.0 * math.pi * zeta * zeta * rk_tol) ** 0.25)
    return np.minimum(oh / omega, _STAB_DAMP_H * m / np.maximum(C, 1e-300))


def substeps_for(test: MechTest, C, m, max_substeps: int = 64, rk_tol: float = 1e-4) -> np.ndarray:
    """RK4 sub-steps per sample interval (power of two) for each candidate (C [N.s/m], m [kg])."""
    C = np.asarray(C, dtype=float)
    m = np.asarray(m, dtype=float)
    need = test.dt / _max_step(test.k_max, C, m, rk_tol)
    n = np.exp2(np.ceil(np.log2(np.maximum(need, 1.0)))).astype(np.intp)
    return np.minimum(n, max_substeps)


# ----------------------------------------------------------------------------- result
@dataclass
class BatchResult:
    """Displacement x [m] of every candidate on its test's sample grid.

    Candidate j is at rest (x = 0) at samples k < ``k_begin``; ``H[r, j]`` is x at sample
    ``k_begin + r`` (time-major block, ``R = H.shape[0]`` rows); from ``k_fill[j]`` on
    (``n_t[j]`` if it never settled) x equals ``x_fill[j]`` (also inside the block).
    Samples at or after ``k_begin + R`` are all fill values.
    """
    n_t: np.ndarray            # samples per candidate's test
    k_begin: int
    H: np.ndarray              # (R, n) time-major block
    k_fill: np.ndarray
    x_fill: np.ndarray
    settled: np.ndarray        # bool
    substeps: np.ndarray       # RK4 sub-steps per sample interval
    candidate_steps: int = 0   # sample intervals integrated, summed over candidates (cost measure)

    @property
    def n(self) -> int:
        return int(self.k_fill.size)

    def columns(self, lo: int, hi: int) -> "BatchResult":
        """Candidates lo..hi-1 as their own result (a view of the block, rows trimmed)."""
        kf = self.k_fill[lo:hi]
        R = int(min(self.H.shape[0], max(0, int(kf.max(initial=self.k_begin)) - self.k_begin)))
        return BatchResult(n_t=self.n_t[lo:hi], k_begin=self.k_begin, H=self.H[:R, lo:hi], k_fill=kf,
                           x_fill=self.x_fill[lo:hi], settled=self.settled[lo:hi],
                           substeps=self.substeps[lo:hi])

    def dense(self, k_lo: int, k_hi: int, idx=None) -> np.ndarray:
        """x [m] over samples [k_lo, k_hi) as a time-major array (k_hi - k_lo, len(idx))."""
        idx = np.arange(self.n) if idx is None else np.asarray(idx, dtype=np.intp)
        R = self.H.shape[0]
        b0, b1 = self.k_begin, self.k_begin + R
        parts = []
        if k_lo < b0:
            parts.append(np.zeros((min(b0, k_hi) - k_lo, idx.size)))
        a, b = max(k_lo, b0), min(k_hi, b1)
        if b > a:
            parts.append(self.H[a - b0:b - b0][:, idx] if idx.size != self.n else self.H[a - b0:b - b0])
        if k_hi > b1:
            parts.append(np.broadcast_to(self.x_fill[idx], (k_hi - max(k_lo, b1), idx.size)))
        if not parts:
            return np.zeros((0, idx.size))
        return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=0)

    def full(self, idx=None) -> np.ndarray:
        """x [m] as a dense candidate-major array (len(idx), max n_t)."""
        nt = int(self.n_t.max()) if self.n else 0
        return np.ascontiguousarray(self.dense(0, nt, idx).T)

    def range_sum(self, a) -> np.ndarray:
        """Sum of x [m] over samples k >= a[j] (to the end of the record) per candidate j."""
        a = np.broadcast_to(np.asarray(a, dtype=np.intp), (self.n,))
        R = self.H.shape[0]
        b0, b1 = self.k_begin, self.k_begin + R
        lo = np.clip(a, b0, b1)
        s = np.zeros(self.n)
        if R:
            amin = int(lo.min())
            blk = self.H[amin - b0:]
            if np.all(lo == amin):
                s += blk.sum(axis=0)
            else:
                rows = np.arange(amin, b1)[:, None]
                s += np.where(rows >= lo[None, :], blk, 0.0).sum(axis=0)
        tail0 = np.maximum(a, b1)
        s += np.where(self.n_t > tail0, (self.n_t - tail0) * np.nan_to_num(self.x_fill), 0.0)
        return s

    def tail_mean(self, n_tail: int) -> np.ndarray:
        """Mean of the last n_tail samples per candidate [m]."""
        return self.range_sum(self.n_t - n_tail) / n_tail

    def mean_before(self, k: int) -> np.ndarray:
        """Mean of the samples before index k per candidate [m]."""
        if k <= 0:
            return np.full(self.n, np.nan)
        return (self.range_sum(0) - self.range_sum(k)) / k

    def sum_sq_error(self, y) -> np.ndarray:
        """Sum over all samples of (x - y)^2 [m^2] per candidate; y [m] on the (common) grid."""
        y = np.asarray(y, dtype=float)
        nt = y.size
        R = self.H.shape[0]
        b0 = self.k_begin
        b1 = min(b0 + R, nt)
        tot = np.full(self.n, float(np.sum(y[:b0] ** 2)))
        if b1 > b0:
            d = self.H[:b1 - b0] - y[b0:b1, None]
            tot += np.einsum("ij,ij->j", d, d)
        if nt > b1:
            yt = y[b1:]
            xf = np.nan_to_num(self.x_fill)
            tot += (nt - b1) * xf * xf - 2.0 * xf * float(yt.sum()) + float(np.dot(yt, yt))
        return tot

    def values_at(self, k, idx=None) -> np.ndarray:
        """x [m] at sample k[q] of candidate idx[q] (default idx = all candidates)."""
        k = np.asarray(k, dtype=np.intp)
        idx = np.arange(self.n) if idx is None else np.asarray(idx, dtype=np.intp)
        R = self.H.shape[0]
        out = np.zeros(k.shape)
        inb = (k >= self.k_begin) & (k < self.k_begin + R)
        out[inb] = self.H[k[inb] - self.k_begin, idx[inb]]
        after = k >= self.k_begin + R
        out[after] = self.x_fill[idx[after]]
        return out

    def last_outside(self, center, tol, k_min: int = 0) -> np.ndarray:
        """Largest sample index k >= k_min with |x_k - center| > tol per candidate, -1 if none."""
        center = np.asarray(center, dtype=float)
        tol = np.asarray(tol, dtype=float)
        out = np.full(self.n, -1, dtype=np.intp)
        R = self.H.shape[0]
        b0, b1 = self.k_begin, self.k_begin + R
        fo = (self.n_t > b1) & (np.abs(np.nan_to_num(self.x_fill) - center) > tol)
        out = np.where(fo, self.n_t - 1, out)
        lo = max(k_min, b0)
        if b1 > lo:
            M = np.abs(self.H[lo - b0:] - center) > tol
            anyo = M.any(axis=0)
            last = lo + (M.shape[0] - 1 - np.argmax(M[::-1], axis=0))
            out = np.where((out < 0) & anyo, last, out)
        if b0 - 1 >= k_min:
            ro = np.abs(center) > tol
            out = np.where(ro & (out < 0), b0 - 1, out)
        return out


# ----------------------------------------------------------------------------- integration
class _Group:
    """Per-element constants of the candidates integrated together (one sub-step count)."""

    def __init__(self, tests, tid, C, m):
        self.single = len(set(tid.tolist())) == 1
        self.tid = tid
        T = [tests[i] for i in tid] if not self.single else None
        t0 = tests[int(tid[0])]
        offs = np.cumsum([0] + [ts.table.shape[0] for ts in tests])
        self.table = np.vstack([ts.table for ts in tests]) if len(tests) > 1 else tests[0].table
        self.off = None
        if self.single:
            self.K1, self.K2, self.r0 = t0.K1, t0.K2, t0.r0
            self.inv = t0.inv_dr
            self.A = t0.r0 * t0.inv_dr + t0.n_ext
            self.off = int(offs[int(tid[0])]) or None
        else:
            self.K1 = np.array([ts.K1 for ts in T])
            self.K2 = np.array([ts.K2 for ts in T])
            self.r0 = np.array([ts.r0 for ts in T])
            self.inv = np.array([ts.inv_dr for ts in T])
            self.A = np.array([ts.r0 * ts.inv_dr + ts.n_ext for ts in T])
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

    def subset(self, sel) -> "_Group":
        """A copy restricted to the elements sel (shares the table)."""
        import copy
        sub = copy.copy(self)
        sub.compact(sel)
        return sub

    def force(self, x, I2):
        """Em*I^2*G(r0 - x) [N] (uniform-grid table gather, linear interpolation on a fine grid)."""
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


def _rk4(g: _Group, x, v, h, I2a, I2m, I2b):
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


def _partial_steps(tests, g: _Group, sel, x, v, ts, te, n_sub):
    """Integrate elements sel of group g from times ts to te (arrays) with n_sub RK4 steps (exact current)."""
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


def _hermite_cross(x0, v0, x1, v1, h, r0):
    """Fraction s in (0, 1] of the step where the cubic Hermite interpolant first reaches r0."""
    lo = np.zeros_like(x0)
    hi = np.ones_like(x0)
    for _ in range(40):
        s = 0.5 * (lo + hi)
        s2, s3 = s * s, s * s * s
        p = ((2 * s3 - 3 * s2 + 1) * x0 + (s3 - 2 * s2 + s) * h * v0 + (-2 * s3 + 3 * s2) * x1
             + (s3 - s2) * h * v1)
        above = p >= r0
        hi = np.where(above, s, hi)
        lo = np.where(above, lo, s)
    return hi


def _run_group(tests, tid, C, m, n_sub, settle_rtol, check_every, k_begin, gidx, H, linear_tail=True):
    """Integrate one group of candidates (same sub-step count) writing x into H[:, gidx].

    Returns k_fill, x_fill, settled, candidate steps, last row written.
    """
    n = tid.size
    g = _Group(tests, tid, C, m)
    nt_e = np.array([tests[i].n_t for i in tid])
    kq_e = np.array([tests[i].k_quiet for i in tid])
    out = {"k_fill": nt_e.copy(), "x_fill": np.full(n, np.nan), "settled": np.zeros(n, dtype=bool),
           "steps": 0, "last": 0}
    active = np.arange(n)
    x = np.zeros(n)
    v = np.zeros(n)
    contact = np.zeros(n, dtype=bool)
    k_last = int(nt_e.max()) - 1
    ends = set((nt_e - 1).tolist())
    uniq = np.unique(tid)
    single = g.single
    node_stack = None
    if not single:
        n_rows = max(tests[int(i)].n_t for i in uniq) - 1
        stack = []
        for i in range(len(tests)):
            if i in set(uniq.tolist()):
                a = tests[i].i2_nodes(n_sub)
                if a.shape[0] < n_rows:
                    a = np.vstack([a, np.repeat(a[-1:], n_rows - a.shape[0], axis=0)])
                stack.append(a)
            else:
                stack.append(np.zeros((n_rows, 2 * n_sub + 1)))
        node_stack = np.stack(stack)
    else:
        nodes = tests[int(uniq[0])].i2_nodes(n_sub)
    dt = tests[int(tid[0])].dt
    h = dt / n_sub
    r0_e = g.r0
    cols = gidx.copy()              # columns of H of the active candidates
    H[0, cols] = 0.0
    k = k_begin
    while k < k_last and active.size:
        # ---- one sample interval [t_k, t_k+1]
        x_old, v_old = x, v
        if single:
            Nk = nodes[k]
            for j in range(n_sub):
                x, v = _rk4(g, x, v, h, Nk[2 * j], Nk[2 * j + 1], Nk[2 * j + 2])
        else:
            Nk = node_stack[g.tid, k, :]
            for j in range(n_sub):
                x, v = _rk4(g, x, v, h, Nk[:, 2 * j], Nk[:, 2 * j + 1], Nk[:, 2 * j + 2])
        out["steps"] += active.size
        # ---- contact events
        if contact.any() or np.any(x > r0_e):
            x, v, contact = _events(tests, g, k, x_old, v_old, x, v, contact, n_sub)
        k += 1
        H[k - k_begin, cols] = x
        out["last"] = max(out["last"], k - k_begin)
        # ---- settle check / end of a record
        regular = k % check_every == 0       # absolute sample index: independent of the batch
        if regular or k >= k_last or k + 1 in ends:
            if regular:
                done = _check(g, active, x, v, contact, k, kq_e, nt_e, settle_rtol, out, H, k_begin, cols,
                              dt, linear_tail)
            else:
                done = k >= nt_e[active] - 1
            if done.any():
                keep = ~done
                active = active[keep]
                cols = cols[keep]
                x, v, contact = x[keep], v[keep], contact[keep]
                g.compact(keep)
                r0_e = g.r0
    return out["k_fill"], out["x_fill"], out["settled"], out["steps"], out["last"]


def _check(g, active, x, v, contact, k, kq_e, nt_e, settle_rtol, out, H, k_begin, cols, dt, linear_tail):
    """Settle check at sample k; records the settled ones in out (and writes the linear tails
    into H); returns the mask of the active candidates that leave the integration."""
    done = np.zeros(active.size, dtype=bool)
    chk = k >= kq_e[active]
    if settle_rtol > 0 and chk.any():
        sel = np.flatnonzero(chk)
        lt = (settle_rtol if linear_tail is True else float(linear_tail)) if linear_tail else 0.0
        ok, xe, lin, ke = _settled(g, sel, x, v, contact, settle_rtol, lt)
        done[sel[ok]] = True
        idx = active[sel[ok]]
        out["settled"][idx] = True
        out["k_fill"][idx] = k + 1
        out["x_fill"][idx] = xe[ok]
        if lin.any():
            q = sel[lin]
            n_rows, reached = _linear_tail(g, q, ke[lin], x, v, xe[lin], k, nt_e[active[q]], dt, settle_rtol,
                                           H, k_begin, cols[q])
            done[q] = True
            idx = active[q]
            out["settled"][idx] = reached
            out["k_fill"][idx] = np.where(reached, k + 1 + n_rows, nt_e[active[q]])
            out["x_fill"][idx] = np.where(reached, xe[lin], np.nan)
            out["last"] = max(out["last"], int((k + n_rows).max()) - k_begin)
    done |= k >= nt_e[active] - 1
    return done


def _linear_tail(g, q, ke, x, v, xe, k, n_t, dt, settle_rtol, H, k_begin, cols):
    """Write the exact solution of the linearized motion about x_e into H from sample k+1 on.

    m*d'' + C*d' + k_e*d = 0 with d = x - x_e, from (d0, v0) at sample k:
    d(tau) = A*exp(l1*tau) + B*exp(l2*tau), l1,2 = -sigma +- sqrt(sigma^2 - k_e/m) (complex
    when underdamped), evaluated by cumulative products of exp(l*dt) on the sample grid;
    near critical damping (|l1 - l2| < 1e-3 sigma) the limit (d0 + (v0 + sigma*d0)*tau)*exp(-sigma*tau).
    Written until an upper bound of |d| falls below the settle tolerance (the record is
    then filled with x_e) or the record ends. Returns (rows written, tolerance reached).
    """
    m, C = g.m[q], g.C[q]
    d0 = x[q] - xe
    v0 = v[q]
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


def _settled(g: _Group, sel, x, v, contact, settle_rtol, linear_tail=0.0):
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


def _events(tests, g: _Group, k, x0, v0, x1, v1, contact, n_sub):
    """Impacts on and releases from the coil face during interval k (see module docstring)."""
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
        s = _hermite_cross(x0[hit], v0[hit], x1[hit], v1[hit], te[hit] - tk[hit], r0[hit])
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
        xr, vr = _partial_steps(tests, g, rel, xs, vs, release_from[rel], te[rel], n_sub)
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


def integrate(tests, which, C, m, settle_rtol: float = 1e-5, check_every: int = 10,
              max_substeps: int = 64, substeps=None, rk_tol: float = 1e-4,
              linear_tail: bool | float = True) -> BatchResult:
    """Integrate the diaphragm of every candidate j on test ``tests[which[j]]`` with C[j], m[j].

    tests: list of :class:`MechTest` with the same sample period; which: int array;
    C [N.s/m], m [kg]: arrays (> 0, >= 0 for C). settle_rtol: relative energy
    distance at which a candidate counts as settled (its record is then filled with
    the equilibrium; 0: integrate every candidate to the end); check_every: samples
    between settle checks (at absolute sample indices, so that a candidate's result
    does not depend on the rest of the batch). ``substeps`` overrides the per-candidate
    RK4 sub-step count (int or array); rk_tol: see :func:`substeps_for`. linear_tail:
    leave the integration as soon as the motion is linear to this relative tolerance
    (True: settle_rtol; False: never) and write the exact solution of the linearized
    motion until it is within settle_rtol of the equilibrium (see :func:`_linear_tail`).
    """
    tests = list(tests)
    which = np.asarray(which, dtype=np.intp)
    C = np.asarray(C, dtype=float)
    m = np.asarray(m, dtype=float)
    if not (which.shape == C.shape == m.shape) or which.ndim != 1:
        raise ValueError("which, C and m must be 1-D arrays of the same length")
    if which.size and (which.min() < 0 or which.max() >= len(tests)):
        raise ValueError("which holds an index outside the list of tests")
    if not (np.all(np.isfinite(C)) and np.all(C >= 0)):
        raise ValueError("C [N.s/m] must be finite and >= 0")
    if not (np.all(np.isfinite(m)) and np.all(m > 0)):
        raise ValueError("m [kg] must be finite and > 0")
    dts = {round(ts.dt, 15) for ts in tests}
    if len(dts) > 1:
        raise ValueError("all tests of a batch need the same sample period")
    n = which.size
    nt = np.array([tests[i].n_t for i in which], dtype=np.intp)
    if substeps is None:
        nsub = np.ones(n, dtype=np.intp)
        for ti in np.unique(which):
            sel = which == ti
            nsub[sel] = substeps_for(tests[int(ti)], C[sel], m[sel], max_substeps, rk_tol)
    else:
        nsub = np.broadcast_to(np.asarray(substeps, dtype=np.intp), (n,)).copy()
    k_begin = min(tests[int(i)].k_start for i in np.unique(which)) if n else 0
    k_fill = nt.copy()
    x_fill = np.full(n, np.nan)
    settled = np.zeros(n, dtype=bool)
    n_rows = int(nt.max()) - k_begin if n else 0
    H = np.empty((max(n_rows, 1), n))     # pages are committed only where written
    steps = 0
    rows = 1
    for ns in np.unique(nsub):
        gidx = np.flatnonzero(nsub == ns)
        kf, xf, st, nsteps, last = _run_group(tests, which[gidx], C[gidx], m[gidx], int(ns), settle_rtol,
                                              check_every, k_begin, gidx, H, linear_tail=linear_tail)
        k_fill[gidx] = kf
        x_fill[gidx] = xf
        settled[gidx] = st
        steps += nsteps
        rows = max(rows, last + 1)
    # unsettled candidates keep their last value as fill (beyond their record's end)
    R = int(min(rows, n_rows)) if n else 0
    H = H[:R]
    if n and R:
        kf_rel = k_fill - k_begin                   # first fill row per candidate
        unset = ~settled
        if unset.any():
            last_rows = np.clip(np.minimum(nt, k_fill) - 1 - k_begin, 0, R - 1)
            x_fill[unset] = H[last_rows[unset], np.flatnonzero(unset)]
        need = kf_rel < R
        if need.any():
            lo = int(max(kf_rel[need].min(), 0))
            r_idx = np.arange(lo, R)[:, None]
            np.copyto(H[lo:], np.broadcast_to(x_fill, (R - lo, n)), where=r_idx >= kf_rel[None, :])
    return BatchResult(n_t=nt, k_begin=k_begin, H=H, k_fill=k_fill, x_fill=x_fill,
                       settled=settled, substeps=nsub, candidate_steps=steps)


def integrate_one(test: MechTest, C, m, **kw) -> BatchResult:
    """:func:`integrate` for candidates that all run the same test."""
    C = np.atleast_1d(np.asarray(C, dtype=float))
    return integrate([test], np.zeros(C.size, dtype=np.intp), C, np.broadcast_to(m, C.shape), **kw)
