"""Population runs of the identification: the diaphragm of a whole NSGA-II population of (C, m)
candidates on the step tests T3/T5 of several samples at once (paper section 3).

Everything except C and m is fixed for a test, so the work that does not depend on them is done once
(:func:`prepare_test`):

* the coil current I(t) follows from the measured voltage alone (exact RL solution with the voltage
  held over each sample interval, zero-order hold, as in :func:`fmu_src.model.simulate`), including its
  values at the Runge-Kutta stage times;
* the force kernel is turned into a :class:`harness.sim.kernels.ForceTable` of Em*G(r);
* the static equilibria at the final current (they do not depend on C and m).

The mechanical state (x [m], v [m/s]) of all candidates is then advanced together with the classic
4th-order Runge-Kutta method on the data grid (:mod:`harness.sim.mech`), ``n_sub`` equal sub-steps per
sample interval chosen per candidate from its stiffness, with the contact semantics of the FMU's
integrator (:mod:`harness.sim.contact`: impact located on the step's Hermite interpolant, rest while
the net force pulls, release located on the exact current). Settled candidates leave the integration
(settle-window truncation, linear tails: :mod:`harness.sim.settle`).

Step size: RK4 sub-steps per sample interval (a power of two per candidate) keep omega*h and the
accumulated phase error (about (omega h)^4 / (240 pi zeta^2) of the amplitude) below ``rk_tol`` and
(C/m)*h below 2 (a fast overdamped mode), with omega and zeta from the largest tangent stiffness the
test can reach.

Units: SI throughout (s, V, A, Ohm, H, m, m/s, N, kg).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq
from scipy.signal import lfilter

from fmu_src.diaphragm import spring_force, tangent_stiffness
from fmu_src.field import ForceKernel

from . import mech
from .kernels import ForceTable, kernel as cached_kernel
from .results import BatchResult
from .settings import MechParams, PopulationSettings, SimInputError

__all__ = ["zoh_current", "MechTest", "prepare_test", "integrate", "integrate_one", "substeps_for"]

_ACC_OMEGA_H = 0.5
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
        raise SimInputError(f"t and V must be 1-D arrays of the same length, got {t.shape} and {V.shape}")
    if not (R > 0 and L > 0 and math.isfinite(R) and math.isfinite(L)):
        raise SimInputError(f"R [Ohm] and L [H] must be positive and finite, got R={R!r}, L={L!r}")
    dt = np.diff(t)
    if dt.size and np.allclose(dt, dt[0], rtol=1e-9, atol=0.0):
        a = math.exp(-dt[0] * R / L)
        # I[k+1] = a*I[k] + (1 - a)*V[k]/R
        # y[0] = zi = I0, y[k+1] = (1 - a) V[k] / R + a y[k]
        y, _ = lfilter([0.0, (1.0 - a) / R], [1.0, -a], V, zi=[I0])
        return y
    I = np.empty_like(t)
    I[0] = I0
    a = np.exp(-dt * R / L)
    for k in range(dt.size):
        I[k + 1] = a[k] * I[k] + (1.0 - a[k]) * V[k] / R
    return I


# ----------------------------------------------------------------------------- one test
@dataclass(eq=False)
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
    table: ForceTable = field(repr=False)   # Em*G(r0 - x), linear interpolation
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


def prepare_test(t, V, params: MechParams, I0: float = 0.0, quiet_rtol: float = 1e-6) -> MechTest:
    """Precompute one test for :func:`integrate`.

    Parameters
    ----------
    t : array
        Uniform time grid [s] (any sample period).
    V : array
        Measured voltage [V], V[k] held on [t[k], t[k+1]).
    params : MechParams
        The test's fixed parameters (gap r0 included); the force kernel is
        ``harness.sim.kernels.kernel(a, D, kB, r0)``.
    I0 : float
        Initial current [A]. The diaphragm starts at rest at x = 0.
    quiet_rtol : float
        The current counts as steady from the sample on where I^2 stays within quiet_rtol (relative
        to max I^2) of its final value (settle checks start there).
    """
    t = np.asarray(t, dtype=float)
    V = np.asarray(V, dtype=float)
    if t.ndim != 1 or t.size < 2 or V.shape != t.shape:
        raise SimInputError(f"t and V must be 1-D arrays of the same length >= 2, got {t.shape} and {V.shape}")
    dt = float((t[-1] - t[0]) / (t.size - 1))
    if not (dt > 0) or np.max(np.abs(np.diff(t) - dt)) > 1e-6 * dt:
        raise SimInputError("batched integration needs a uniform, increasing time grid")
    p = params
    R, L, r0, Em, K1, K2 = p.R, p.L, p.r0, p.Em, p.K1, p.K2
    kern = cached_kernel(p.a, p.D, p.kB, r0)
    I = zoh_current(t, V, R, L, I0)
    nz = np.flatnonzero((V != 0.0) | (I != 0.0))
    k_start = int(nz[0]) if nz.size else t.size - 1
    I2 = I * I
    I2_end = float(I2[-1])
    scale = max(float(np.max(I2)), 1e-300)
    dev = np.abs(I2 - I2_end) > quiet_rtol * scale
    last = np.flatnonzero(dev)
    k_quiet = int(last[-1]) + 1 if last.size else 0
    eq_x, eq_k, eq_h2, eq_h3 = _stable_equilibria(kern, r0, Em, K1, K2, I2_end)
    eq_max = _stable_equilibria(kern, r0, Em, K1, K2, float(np.max(I2)))[0]
    contact_stable = bool(Em * I2_end * kern.G0 - spring_force(r0, K1, K2) >= 0.0)
    x_scale = max([abs(x) for x in eq_x] + [abs(eq_max[0]) if eq_max.size else r0] + [1e-3 * r0])
    # stiffness bound over the range the diaphragm can reach (up to the coil face)
    I2_max = float(np.max(I2))
    x_hi = min(r0, 2.0 * float(np.max(eq_x)) + 0.05e-3) if eq_x.size else r0
    xg = np.linspace(0.0, x_hi, 201)
    k_mag = Em * I2_max * np.max(np.abs(kern.derivative(r0 - xg)))
    k_max = float(tangent_stiffness(x_hi, K1, K2) + k_mag)
    return MechTest(t0=float(t[0]), dt=dt, n_t=int(t.size), V=V, I=I, R=float(R), L=float(L), r0=float(r0),
                    Em=float(Em), K1=float(K1), K2=float(K2), kernel=kern, k_start=k_start, k_quiet=k_quiet,
                    I2_end=I2_end, eq_x=eq_x, eq_k=eq_k, eq_h2=eq_h2, eq_h3=eq_h3, contact_stable=contact_stable,
                    x_scale=x_scale, k_max=k_max, table=ForceTable.build(kern, Em, r0))


def _check_candidates(tests, which, C, m) -> None:
    if not (which.shape == C.shape == m.shape) or which.ndim != 1:
        raise SimInputError("which, C and m must be 1-D arrays of the same length")
    if which.size and (which.min() < 0 or which.max() >= len(tests)):
        raise SimInputError("which holds an index outside the list of tests")
    if not (np.all(np.isfinite(C)) and np.all(C >= 0)):
        raise SimInputError("C [N.s/m] must be finite and >= 0")
    if not (np.all(np.isfinite(m)) and np.all(m > 0)):
        raise SimInputError("m [kg] must be finite and > 0")
    if len({round(ts.dt, 15) for ts in tests}) > 1:
        raise SimInputError("all tests of a batch need the same sample period (integrate one batch per period)")


def integrate(tests, which, C, m, settings: PopulationSettings = PopulationSettings()) -> BatchResult:
    """Integrate the diaphragm of every candidate j on test ``tests[which[j]]`` with C[j], m[j].

    Parameters
    ----------
    tests : sequence of MechTest
        Prepared tests, all with the same sample period.
    which : int array (n,)
        Test index per candidate.
    C : array (n,)
        Damping [N.s/m] (>= 0).
    m : array (n,)
        Moving mass [kg] (> 0).
    settings : PopulationSettings
        Tolerances (settle test, sub-steps, linear tails).

    Returns
    -------
    BatchResult
        x [m] of every candidate on its test's grid (compact form).
    """

    tests = list(tests)
    which = np.asarray(which, dtype=np.intp)
    C = np.asarray(C, dtype=float)
    m = np.asarray(m, dtype=float)
    _check_candidates(tests, which, C, m)
    n = which.size
    nt = np.array([tests[i].n_t for i in which], dtype=np.intp)
    s = settings
    if s.substeps is None:
        nsub = np.ones(n, dtype=np.intp)
        for ti in np.unique(which):
            sel = which == ti
            nsub[sel] = substeps_for(tests[int(ti)], C[sel], m[sel], s.max_substeps, s.rk_tol)
    else:
        nsub = np.broadcast_to(np.asarray(s.substeps, dtype=np.intp), (n,)).copy()
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
        block = mech.Block(H=H, k_begin=k_begin, cols=gidx)
        g = mech.CandidateGroup(tests, which[gidx], C[gidx], m[gidx])
        kf, xf, st, nsteps, last = mech.run_group(tests, g, int(ns), s, block)
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


def integrate_one(test: MechTest, C, m, settings: PopulationSettings = PopulationSettings()) -> BatchResult:
    """:func:`integrate` for candidates that all run the same test."""
    C = np.atleast_1d(np.asarray(C, dtype=float))
    return integrate([test], np.zeros(C.size, dtype=np.intp), C, np.broadcast_to(m, C.shape), settings)
