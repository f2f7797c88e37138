"""Population runs of the identification: the diaphragm of a whole NSGA-II population of (C, m)
candidates on the step tests T3/T5 of several samples at once (paper section 3), on the one vectorized
simulator's compiled core (:mod:`harness.sim.core`: RK4, the FMU's physics and contact semantics).

Everything except C and m is fixed for a test, so the work that does not depend on them is done once
(:func:`prepare_test`): the coil current on the sample grid (exact RL solution with the voltage held over
each sample interval, zero-order hold, :func:`zoh_current`), the sample from which it is steady, the stable
static equilibria at the final current and whether resting on the coil face is stable there (they do not
depend on C and m), and a bound of the tangent stiffness.

:func:`integrate` then hands every candidate to the core as one run: the parameters of its test with its
C and m, the measured voltage (zero-order hold), the current prescribed by the exact RL solution at the RK4
stage times (``core.C_EXACT``: the plain coil, as in :func:`fmu_src.model.simulate`), ``n_sub`` equal RK4
sub-steps per sample interval chosen per candidate from its stiffness and damping (:func:`substeps_for`),
and the core's equilibrium settle test: once the current is steady, a candidate whose energy distance from
a stable equilibrium x_e is below ``settle_rtol * max(|x_e|, x_scale)`` leaves the integration and the rest
of its record is x_e (checks at absolute sample indices every ``check_every`` samples, so that a
candidate's record is bit-for-bit the same whatever else is in the batch); earlier still, once its motion
about x_e is linear to ``linear_tail``, the rest of its record is the closed-form damped oscillation about
x_e (written by the core) until it is within the settle tolerance.

Step size: RK4 sub-steps per sample interval (a power of two per candidate) keep omega*h and the
accumulated phase error (about (omega h)^4 / (240 pi zeta^2) of the amplitude) below ``rk_tol`` and
(C/m)*h below 2 (a fast overdamped mode), with omega and zeta from the largest tangent stiffness the
test can reach.

Units: SI throughout (s, V, A, Ohm, H, m, m/s, N, kg).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq
from scipy.signal import lfilter

from fmu_src.diaphragm import spring_force, tangent_stiffness
from fmu_src.field import ForceKernel

from . import core, physics
from .kernels import kernel as cached_kernel
from .results import BatchResult
from .settings import MechParams, PopulationSettings, SimInputError
from .simulator import Runs

__all__ = ["zoh_current", "MechTest", "prepare_test", "integrate", "integrate_one", "substeps_for"]

_ACC_OMEGA_H = 0.5
_STAB_DAMP_H = 2.0
_COL = {name: i for i, name in enumerate(core.STATE_COLUMNS)}

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
        # I[k+1] = a*I[k] + (1 - a)*V[k]/R; lfilter's state zi is y[0] itself (transposed direct form II:
        # y[0] = b0*V[0] + zi, b0 = 0), so zi = I0 gives I[1] = a*I0 + (1 - a)*V[0]/R
        y, _ = lfilter([0.0, (1.0 - a) / R], [1.0, -a], V, zi=[I0])
        y[0] = I0
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
    params: MechParams        # the test's fixed parameters (gap r0 included)
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
    first_s: float | None = None  # a step between samples: only the last first_s [s] of interval k_start is
    #                               integrated (from rest, under V[k_start]); None: the whole interval

    @property
    def t(self) -> np.ndarray:
        return self.t0 + self.dt * np.arange(self.n_t)

    @property
    def r0(self) -> float:
        return self.params.r0

    @property
    def G0(self) -> float:
        return self.kernel.G0

    def net_contact_force(self, I2):
        """Magnetic minus spring force [N] on the coil face for current squared I2 [A^2]."""
        p = self.params
        return p.Em * np.asarray(I2) * self.kernel.G0 - spring_force(p.r0, p.K1, p.K2)


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


def prepare_test(t, V, params: MechParams, I0: float = 0.0, quiet_rtol: float = 1e-6,
                 onset_delay_s: float | None = None) -> MechTest:
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
    onset_delay_s : float, optional
        A step from rest that began between two samples: V is zero (and I0 is 0) up to sample k0, the first
        that reads the stepped voltage, and the step began ``onset_delay_s`` [s] before t[k0] (0 .. the
        sample period). V[k0] then acts from t[k0] - onset_delay_s on: interval k0 - 1 is integrated over its
        last onset_delay_s only (``first_s``), from rest, so that the response on the grid is the one of the
        step at its instant (exact but for the RK4 error), at any sample rate. A held "equivalent" voltage
        over the whole interval instead (the mean, or the one that gives the right current at t[k0]) moves
        the force earlier by up to half a period: at 136 Hz, with the step half-way between samples, the
        least-squares mass came out 4.7 % (6 sd) high. None or 0: V[k] held over [t[k], t[k+1]) throughout.
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
    first_s = None
    if onset_delay_s is not None and onset_delay_s > 0.0:
        on = np.flatnonzero(V != 0.0)
        k0 = int(on[0]) if on.size else 0
        if I0 != 0.0 or k0 < 1:
            raise SimInputError(f"onset_delay_s needs a step from rest (I0 = 0, zero voltage before the step), "
                                f"got I0={I0!r} A and the first non-zero voltage at sample {k0}")
        d = min(float(onset_delay_s), dt)
        if d < dt:
            first_s = d
        # the current on the grid: the RL coil's from the instant on (an interval voltage that gives it at t[k0])
        Veq = V.copy()
        Veq[k0 - 1] = V[k0] * math.expm1(-d * R / L) / math.expm1(-dt * R / L)
        I = zoh_current(t, Veq, R, L, I0)
        V = V.copy()
        V[k0 - 1] = V[k0]                  # held from the onset, over the last first_s of the interval
    else:
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
    if eq_x.size > core.N_EQ:
        raise SimInputError(f"{eq_x.size} stable equilibria at the final current; the simulator knows {core.N_EQ}")
    eq_max = _stable_equilibria(kern, r0, Em, K1, K2, float(np.max(I2)))[0]
    contact_stable = bool(Em * I2_end * kern.G0 - spring_force(r0, K1, K2) >= 0.0)
    x_scale = max([abs(x) for x in eq_x] + [abs(eq_max[0]) if eq_max.size else r0] + [1e-3 * r0])
    # stiffness bound over the range the diaphragm can reach (up to the coil face)
    I2_max = float(np.max(I2))
    x_hi = min(r0, 2.0 * float(np.max(eq_x)) + 0.05e-3) if eq_x.size else r0
    xg = np.linspace(0.0, x_hi, 201)
    k_mag = Em * I2_max * np.max(np.abs(kern.derivative(r0 - xg)))
    k_max = float(tangent_stiffness(x_hi, K1, K2) + k_mag)
    return MechTest(t0=float(t[0]), dt=dt, n_t=int(t.size), V=V, I=I, params=p, kernel=kern, k_start=k_start,
                    k_quiet=k_quiet, I2_end=I2_end, eq_x=eq_x, eq_k=eq_k, eq_h2=eq_h2, eq_h3=eq_h3,
                    contact_stable=contact_stable, x_scale=x_scale, k_max=k_max, first_s=first_s)


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


# ----------------------------------------------------------------------------- population
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
        Tolerances (settle test, sub-steps).

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
    if n == 0:
        return BatchResult(n_t=nt, k_begin=0, H=np.zeros((0, 0)), k_fill=nt.copy(), x_fill=np.zeros(0),
                           settled=np.zeros(0, dtype=bool), substeps=nsub)
    ks = np.array([tests[i].k_start for i in which], dtype=np.intp)
    k_begin = int(ks.min())
    # one part per record length and first active interval (a step between samples is integrated from its
    # onset within that interval): a part that starts later is at rest before, zeros in the block
    parts = []
    for v, kb in sorted({(int(a), int(b)) for a, b in zip(nt, ks)}):
        idx = np.flatnonzero((nt == v) & (ks == kb))
        x, last, kf, xf, st = _run(tests, which[idx], (C[idx], m[idx], nsub[idx]), kb, s)
        if kb > k_begin:
            x = np.concatenate([np.zeros((x.shape[0], kb - k_begin)), x], axis=1)
            last = last + (kb - k_begin)
        parts.append((idx, (x, last, kf, xf, st)))
    R = max(int(last.max()) + 1 for _, (_, last, _, _, _) in parts)
    H = np.empty((R, n))
    k_fill, x_fill, settled = nt.copy(), np.full(n, np.nan), np.zeros(n, dtype=bool)
    steps = 0
    for idx, (x, last, kf, xf, st) in parts:
        # x up to each run's last output, then its fill value (from k_fill on, inside the block too)
        core.time_major(x, last, xf, H, idx)
        k_fill[idx], x_fill[idx], settled[idx] = kf, xf, st
        steps += int(np.sum(kf - k_begin - 1))
    return BatchResult(n_t=nt, k_begin=k_begin, H=H, k_fill=k_fill, x_fill=x_fill, settled=settled, substeps=nsub,
                       candidate_steps=steps)


def _run(tests, which, cand, k_begin: int, s: PopulationSettings):
    """Candidates (C, m, n_sub) = cand on tests[which] (all with the same record length) through the core,
    from sample k_begin on. Returns x [m] (n, outputs) from sample k_begin (valid up to column last), last,
    k_fill, x_fill, settled."""
    C, m, nsub = cand
    n = which.size
    uniq, pos = np.unique(which, return_inverse=True)
    ts = [tests[int(i)] for i in uniq]
    n_t = ts[0].n_t
    n_int = n_t - 1 - k_begin
    V = np.stack([t.V[k_begin:n_t - 1] for t in ts])           # one row per test; run -> row: C_VROW
    prm = {k: np.zeros(n) for k in physics.PARAM_FIELDS}
    for k in ("a", "r0", "D", "kB", "R", "L", "Em", "K1", "K2"):
        prm[k] = np.array([getattr(t.params, k) for t in ts])[pos]
    prm["C"], prm["m"] = C, m
    # the per-run constants (the voltage goes to the core apart, one row per test)
    c = physics.constants(Runs(params=prm, blocked=np.zeros(n, dtype=bool), V=np.zeros(n), dt=ts[0].dt))
    P = physics.param_blocks(c)
    P[:, core.C_VROW] = pos
    P[:, core.C_H] = ts[0].dt / nsub
    P[:, core.C_PER] = nsub
    E = max(1, max(t.eq_x.size for t in ts))
    eq = {k: np.full((len(ts), E), np.nan) for k in ("x_e", "k_e", "h2", "h3")}
    for i, t in enumerate(ts):
        for k, v in (("x_e", t.eq_x), ("k_e", t.eq_k), ("h2", t.eq_h2), ("h3", t.eq_h3)):
            eq[k][i, :v.size] = v
    eq = {k: v[pos] for k, v in eq.items()}
    eq.update({"x_scale": np.array([t.x_scale for t in ts])[pos], "rtol": s.settle_rtol, "linear_tol": s.linear_tol,
               "contact_stable": np.array([t.contact_stable for t in ts])[pos],
               "k_quiet": np.array([t.k_quiet - k_begin for t in ts], dtype=float)[pos], "exact_current": True})
    core.settle_block(P, eq)
    S = core.new_state(P)
    S[:, _COL["I"]] = np.array([t.I[k_begin] for t in ts])[pos]
    out = _out_buffer((4, n, n_int + 1))
    out[1, :, 0] = 0.0                                  # at rest at sample k_begin
    last = np.zeros(n, dtype=np.intp)
    sample = k_begin + 1 + np.arange(n_int)             # the sample of each output column 1 + k
    check = (sample % s.check_every == 0) if s.settle_rtol > 0 else np.zeros(n_int, dtype=bool)
    first = np.array([ts[0].dt if t.first_s is None else t.first_s for t in ts])[pos]
    if n_int > 0 and np.any(first < ts[0].dt):
        # the first interval from each run's onset on (from rest: the rest of it changes nothing), then the others
        P[:, core.C_H] = first / nsub
        core.run_part(P, c["kt"].coef, S, np.ascontiguousarray(V[:, :1]), out, np.array([1, 1, 1, 0.0]),
                      check[:1], last)
        P[:, core.C_H] = ts[0].dt / nsub
        if n_int > 1:
            core.run_part(P, c["kt"].coef, S, np.ascontiguousarray(V[:, 1:]), out, np.array([n_int - 1, 2, 1, 0.0]),
                          check[1:], last)
    else:
        core.run_part(P, c["kt"].coef, S, np.ascontiguousarray(V), out, np.array([n_int, 1, 1, 0.0]), check, last)
    fill = S[:, _COL["fill"]]
    settled = (S[:, _COL["active"]] == 0.0) & np.isfinite(fill)
    k_fill = np.where(settled, k_begin + last + 1, n_t)
    x_fill = np.where(settled, fill, out[1, np.arange(n), last])
    return out[1], last, k_fill, x_fill, settled


_OUT: dict = {}      # shape -> buffer
_OUT_MAX = 4


def _out_buffer(shape) -> np.ndarray:
    """The core's output array for a population part, one per shape, reused while the shape recurs (every
    generation of a search): no fresh pages to fault in per call. The parts of one ``integrate`` call
    differ in their record length, hence in shape, so they never share a buffer. Only out[1] (x) is
    written (equilibrium settle mode); every entry a result reads is written in the call (a run's columns
    up to its last; ``core.time_major`` fills the rest of its record), so the contents left from an earlier
    call are never read."""
    buf = _OUT.get(shape)
    if buf is None:
        if len(_OUT) >= _OUT_MAX:
            _OUT.clear()
        buf = _OUT[shape] = np.empty(shape)
    return buf


def integrate_one(test: MechTest, C, m, settings: PopulationSettings = PopulationSettings()) -> BatchResult:
    """:func:`integrate` for candidates that all run the same test."""
    C = np.atleast_1d(np.asarray(C, dtype=float))
    return integrate([test], np.zeros(C.size, dtype=np.intp), C, np.broadcast_to(m, C.shape), settings)
