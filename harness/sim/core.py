"""The compiled stepping core of the vectorized simulator (:mod:`harness.sim.simulator`): classic RK4 of
each run of a batch through a part of the output schedule, with the contact events of the FMU's
integrator and the exact sensor lag, in one numba-compiled loop (runs outer, steps inner).

The physics is the FMU's: the right-hand side is ``fmu_src.effects.rates`` (the whole model on a parameter
block laid out by ``fmu_src.specs.BLOCK``), the magnetic force ``fmu_src.effects.force`` on the force
kernel ``fmu_src.field.kernel_value``, the net contact force ``fmu_src.effects.contact_force``: the very
function objects the FMU's compiled integrator compiles (``fmu_src.integrator.COMPILED_PHYSICS``), compiled
here from the same objects and inlined into the stepping loop (``PHYSICS``). The
sensor lag is not a state of the RK4 here (its switch is 0 in the core's parameter block) but solved
exactly over each step (:mod:`harness.sim.contact` has the events' location rules).

Per run (row r of the arrays):

* ``P[r]``: the parameter block (``fmu_src.specs.BLOCK`` head; the RK4 state y is ``Y_STATES``: I, x, v
  and every effect state of ``fmu_src.specs.EFFECTS`` except the sensor lag's, in catalogue order, so
  that a new effect's states are integrated without an edit here; the lag's switch 0), the force-kernel
  entries at the FMU integrator's positions (``K_SMAX`` ... ``K_DG0``), then the core's own entries
  (``C_OFF`` ... , see :func:`param_block` and :func:`settle_block`);
* ``S[r]``: the state (columns ``STATE_COLUMNS``): y, then x_sensor [m], F_sensor [N], F [N] (magnetic
  force at the state), fm (1.0 moving, 0.0 held), contact (1.0/0.0), active (1.0, 0.0 once frozen as
  settled), the reading and current at the last settle check, and the fill value [m] of a run frozen by
  the equilibrium settle test.

Two settle tests freeze runs at the settle checks the caller asks for (``check``): without equilibria
(``C_XSC`` 0) a run without slow states whose reading and current changed by less than ``C_TOLY`` and
tol_I since the previous check (constant inputs of :func:`harness.sim.simulator.simulate`); with them
(the identification's population runs, :mod:`harness.sim.population`) a run is settled once, from the
output column ``C_KQ`` on (the current has stopped changing), its energy distance from the nearest stable
equilibrium x_e, sqrt((x - x_e)^2 + m v^2/k_e), is below ``C_RTOL * max(|x_e|, C_XSC)`` (or it rests on
the coil face where that is stable): under damping it can never leave again, and its record from there
on is x_e (the ``fill`` column); earlier still, once the motion about x_e is linear to ``C_LTOL``, the
rest of its record is the closed-form damped oscillation about x_e (the displacement only) until it is
within the settle tolerance (then x_e) or the record ends. The current may be prescribed (``C_EXACT``: the
exact RL solution of a zero-order-hold voltage for the plain coil, I(t) = V/R + (I0 - V/R) exp(-t R/L), at
the RK4 stage times).

Contact, as ``fmu_src.integrator``: a free diaphragm whose step ends at or beyond the coil face hits it at
the instant located on the step's cubic Hermite interpolant (x = r0, v = 0); it rests there if the net
contact force at that instant pulls toward the coil, else it is free at once. A resting diaphragm is
released at the instant the net contact force changes sign (linear inside the step; on the exact current
where it is prescribed); the rest of the step is then integrated free from (r0, 0) (only the mechanics are
taken from this partial step). Blocked runs: x = v = 0 always. Sensor lag y_s' = (u - y_s)/tau_s solved
exactly for u quadratic through its values at the step's start, middle (third-order continuous extension of
RK4) and end (two linear pieces for x in a step with an impact or release). Units: SI.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from fmu_src import integrator as J
from fmu_src.specs import BASE_STATES, BLOCK, EFFECTS
from fmu_src.terms import LAG_STATES

from .contact import hermite_crossing, sign_change_fraction

__all__ = ["PHYSICS", "EXACT_EFFECT", "Y_STATES", "NY_EFFECTS", "STATE_COLUMNS", "C_OFF", "C_NY", "C_OWNK", "C_TOLY", "C_SLOW", "C_TAUS", "C_LAGE",
           "C_BLOCKED", "C_H", "C_PER", "C_EXACT", "C_XSC", "C_RTOL", "C_CSTAB", "C_KQ", "C_LTOL", "C_VROW", "C_EQ", "N_EQ",
           "NPAR", "OWN_H_RATE", "OWN_MAX_PER",
           "param_block", "settle_block", "new_state", "run_part", "time_major", "rhs"]

J.register_compiled_module(__name__, __file__)
_jit = numba.njit(cache=True, error_model="numpy")
_jit_inline = numba.njit(cache=True, error_model="numpy", inline="always")

# the physics the core calls: the very functions the FMU's integrator compiles (fmu_src.integrator.COMPILED_PHYSICS,
# made from fmu_src.effects / fmu_src.field), compiled here once more from the same function objects, inlined
# into the stepping loop (IEEE arithmetic as there: no fast-math, the same results)
PHYSICS = {k: numba.njit(inline="always", error_model="numpy")(getattr(f, "py_func", f))
           for k, f in J.COMPILED_PHYSICS.items() if k in ("rates", "force", "contact_force", "kernel_value",
                                                           "sensor_readings")}
_rates, _force, _contact_force, _kernel_value, _readings = (PHYSICS[k] for k in (
    "rates", "force", "contact_force", "kernel_value", "sensor_readings"))
_TERMS = BLOCK.terms     # the term set's switch (fmu_src.terms; 1.0: its lag states are integrated too)

# the effect whose states the core solves exactly over each step instead of integrating them (the sensor lag)
EXACT_EFFECT = "sensor_lag"
# the RK4 state y: the FMU's base states, then every other effect state in catalogue order (fmu_src.specs),
# then the term set's lag states (fmu_src.terms); a run integrates the first C_NY of them (NY_EFFECTS while
# every term is off: no work for the term set)
Y_STATES = (BASE_STATES + tuple(s for name, e in EFFECTS.items() if name != EXACT_EFFECT for s in e.states)
            + LAG_STATES)
NY = len(Y_STATES)
NY_EFFECTS = NY - len(LAG_STATES)
STATE_COLUMNS = Y_STATES + ("xs", "Fs", "F", "fm", "contact", "active", "chk_y", "chk_I", "fill")
_I, _X, _V = (Y_STATES.index(n) for n in BASE_STATES)
_XS, _FS, _F, _FM, _CT, _ACT, _CHY, _CHI, _FILL = range(NY, len(STATE_COLUMNS))
NSTATE = len(STATE_COLUMNS)
_R0, _R, _L, _C, _M = (BLOCK.param[n] for n in ("r0", "R", "L", "C", "m"))
# the core's entries after the FMU integrator's force-kernel entries
C_OFF = J.K_DG0 + 1       # first column of the run's kernel in the stacked coefficient table
C_TOLY = C_OFF + 1        # settle tolerance of the reading [m or N]
C_SLOW = C_OFF + 2        # 1.0: slow states (coil heating, creep): never frozen
C_TAUS = C_OFF + 3        # sensor lag time constant [s] (0: none)
C_LAGE = C_OFF + 4        # exp(-h/tau_s) of the part's step h (0 without lag)
C_BLOCKED = C_OFF + 5     # 1.0: blocked mode
C_H = C_OFF + 6           # step [s] in the current part of the schedule
C_PER = C_OFF + 7         # steps per output in the current part
C_EXACT = C_OFF + 8       # 1.0: the current prescribed (exact RL solution of the zero-order-hold voltage)
C_XSC = C_OFF + 9         # equilibrium settle test: length scale [m] (0: the change test)
C_RTOL = C_OFF + 10       # equilibrium settle test: relative tolerance
C_CSTAB = C_OFF + 11      # equilibrium settle test: 1.0 resting on the coil face is stable
C_KQ = C_OFF + 12         # equilibrium settle test: first output column checked (the current is steady)
C_LTOL = C_OFF + 13       # equilibrium settle test: relative tolerance of the linear tail (0: none)
C_VROW = C_OFF + 14       # the run's row of the voltage array V (param_block: its own row r)
N_EQ = 3                  # stable equilibria per run the settle test knows (NaN: none)
C_EQ = C_OFF + 15         # equilibrium q at C_EQ + 4q: x_e [m], k_e [N/m], h2 [N/m^2], h3 [N/m^3]
C_NY = C_EQ + 4 * N_EQ    # states of y the run integrates (NY_EFFECTS, or NY with the term set on)
C_OWNK = C_NY + 1         # a lag with its own rate (Dahl's) on: its rate |dz'/dz| per unit speed [1/m] (0: none)
NPAR = C_OWNK + 1
OWN_H_RATE, OWN_MAX_PER = 0.5, 4096   # C_OWNK > 0: an output is redone with twice the sub-steps (at least C_PER, at
# most OWN_MAX_PER) while a sub-step's h*|v|*C_OWNK at its start or end exceeds OWN_H_RATE (RK4: stable to 2.78)
# rows of the work array of one run
_W_K, _W_TMP, _W_YN, _W_Y0, _W_OLD, _W_SCR, _W_END = 0, 4, 5, 6, 7, 8, 9
_W_ROWS = 10


def param_block(head, kt, extra) -> np.ndarray:
    """(N, NPAR) parameter blocks.

    Parameters
    ----------
    head : list
        ``fmu_src.model.block_head`` entries, each a float or an (N,) array (the lag's switch 0; the
        effect states' indices their positions in ``Y_STATES``).
    kt : harness.sim.kernels.KernelTable
        The runs' force kernels (stacked).
    extra : dict
        (N,) arrays ``tol_y`` [m or N], ``slow`` (bool), ``tau_s`` [s], ``blocked`` (bool).
    """
    n = kt.off.size
    P = np.zeros((n, NPAR))
    for i, v in enumerate(head):
        P[:, i] = v
    P[:, J.K_SMAX], P[:, J.K_DR], P[:, J.K_INVDR], P[:, J.K_G0], P[:, J.K_DG0] = (kt.smax, kt.dr, kt.inv_dr,
                                                                                 kt.G0, kt.dG0)
    P[:, C_OFF] = kt.off
    P[:, C_TOLY] = extra["tol_y"]
    P[:, C_SLOW] = extra["slow"]
    P[:, C_TAUS] = extra["tau_s"]
    P[:, C_BLOCKED] = extra["blocked"]
    P[:, C_VROW] = np.arange(n)
    P[:, C_EQ:C_EQ + 4 * N_EQ:4] = np.nan
    P[:, C_NY] = np.where(P[:, _TERMS] != 0.0, NY, NY_EFFECTS)
    return P


def settle_block(P: np.ndarray, eq: dict) -> None:
    """Switch the runs of P (in place) to the equilibrium settle test and, optionally, the prescribed current.

    Parameters
    ----------
    P : (N, NPAR) parameter blocks (:func:`param_block`).
    eq : dict
        (N,) arrays ``x_scale`` [m] (> 0), ``rtol``, ``linear_tol`` (relative tolerance of the linear tail,
        0: none), ``contact_stable`` (bool), ``k_quiet`` (first output column checked), ``exact_current``
        (bool); (N, q) arrays of the stable free equilibria at the final current (q <= N_EQ, NaN for none):
        ``x_e`` [m], ``k_e`` [N/m] (tangent stiffness), ``h2`` [N/m^2], ``h3`` [N/m^3] (second and third
        derivatives of the net restoring force there).
    """
    P[:, C_XSC] = eq["x_scale"]
    P[:, C_RTOL] = eq["rtol"]
    P[:, C_LTOL] = eq["linear_tol"]
    P[:, C_CSTAB] = eq["contact_stable"]
    P[:, C_KQ] = eq["k_quiet"]
    P[:, C_EXACT] = eq["exact_current"]
    cols = [np.atleast_2d(eq[k]) for k in ("x_e", "k_e", "h2", "h3")]
    if cols[0].shape[1] > N_EQ:
        raise ValueError(f"at most {N_EQ} stable equilibria per run, got {cols[0].shape[1]}")
    for q in range(cols[0].shape[1]):
        for j in range(4):
            P[:, C_EQ + 4 * q + j] = cols[j][:, q]


def new_state(P: np.ndarray) -> np.ndarray:
    """(N, NSTATE) states at rest: every state 0, free runs movable (fm = 1), active, no contact."""
    S = np.zeros((P.shape[0], NSTATE))
    S[:, _FM] = 1.0 - P[:, C_BLOCKED]
    S[:, _ACT] = 1.0
    return S


@_jit_inline
def _kernel(P, coef, r):
    return _kernel_value(r, coef, np.intp(P[C_OFF]), P[J.K_SMAX], P[J.K_DR], P[J.K_INVDR], P[J.K_G0], P[J.K_DG0])


@_jit_inline
def _force_at(P, coef, I, x):
    """Magnetic force [N] at current I [A] and displacement x [m] (``fmu_src.effects.force``)."""
    return _force(P, I, _kernel(P, coef, P[_R0] - x))


@_jit
def _net(P, y):
    """Net force [N] toward the coil on the coil face at the state y (``fmu_src.effects.contact_force``)."""
    return _contact_force(P, y, _force(P, y[_I], P[J.K_G0]))


@_jit
def _net_between(P, a, b, s, scr):
    """``_net`` at the state a + s*(b - a) (scr: scratch row)."""
    for i in range(int(P[C_NY])):
        scr[i] = a[i] + s * (b[i] - a[i])
    return _net(P, scr)


@_jit_inline
def _rhs(P, coef, y, V, fm, F, out):
    """dy/dt of y (``Y_STATES``) into out under V [V] (``fmu_src.effects.rates``; the states of effects
    that are off keep rate 0); fm 1.0 free, 0.0 held; F the magnetic force [N] at y if known (NaN: computed
    where needed). Returns F."""
    free = fm > 0.0
    if (free or P[_TERMS] != 0.0) and F != F:
        F = _force_at(P, coef, y[_I], y[_X])
    for i in range(len(BASE_STATES), int(P[C_NY])):
        out[i] = 0.0
    _rates(P, y, V, y[_X], y[_V], F, free, out)
    return F


@_jit
def _rk4(P, coef, W, h, Vs, fm, F0):
    """Classic RK4 over h [s] from W[_W_Y0] into W[_W_YN] (stages in W[_W_K:_W_K + 4]); Vs = (start, middle,
    end) voltages [V]; F0 the force at the start if known (NaN: computed). Returns the force at the start."""
    y, t, yn = W[_W_Y0], W[_W_TMP], W[_W_YN]
    k1, k2, k3, k4 = W[_W_K], W[_W_K + 1], W[_W_K + 2], W[_W_K + 3]
    h2, h6 = 0.5 * h, h / 6.0
    ny = int(P[C_NY])
    exact = P[C_EXACT] != 0.0
    I_mid, I_end = 0.0, 0.0
    if exact:
        # the current prescribed: exact RL solution under the held voltage Vs[0] at h/2 and h
        Vr = Vs[0] / P[_R]
        E = math.exp(-h2 * P[_R] / P[_L])
        I_mid = Vr + (y[_I] - Vr) * E
        I_end = Vr + (y[_I] - Vr) * (E * E)
    F1 = _rhs(P, coef, y, Vs[0], fm, F0, k1)
    for i in range(ny):
        t[i] = y[i] + h2 * k1[i]
    if exact:
        t[_I] = I_mid
    _rhs(P, coef, t, Vs[1], fm, math.nan, k2)
    for i in range(ny):
        t[i] = y[i] + h2 * k2[i]
    if exact:
        t[_I] = I_mid
    _rhs(P, coef, t, Vs[1], fm, math.nan, k3)
    for i in range(ny):
        t[i] = y[i] + h * k3[i]
    if exact:
        t[_I] = I_end
    _rhs(P, coef, t, Vs[2], fm, math.nan, k4)
    for i in range(ny):
        yn[i] = y[i] + h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])
    if exact:
        yn[_I] = I_end
    return F1


@_jit
def _midpoint(W, h, i):
    """State i at the middle of the RK4 step: y + h*(5/24 k1 + 1/6 (k2 + k3) - 1/24 k4)."""
    k = W[_W_K:_W_K + 4, i]
    return W[_W_Y0, i] + h * ((5.0 / 24.0) * k[0] + (k[1] + k[2]) / 6.0 - k[3] / 24.0)


@_jit
def _lag(ys, u0, u1, h, tau):
    """Exact first-order lag over h [s] for u linear from u0 to u1 (tau 0: ys = u1)."""
    if not tau > 0.0:
        return u1
    E = math.exp(-h / tau)
    cE = tau * (1.0 - E) / h if h > 0.0 else 1.0
    return u1 + (ys - u0) * E - (u1 - u0) * cE


@_jit
def _lag_quadratic(ys, u, h, tau, E):
    """Exact first-order lag over h [s] for u quadratic through u = (u0, u_mid, u1) at 0, h/2, h."""
    u0, um, u1 = u
    b2 = 4.0 * (u1 - 2.0 * um + u0) / (h * h)
    a = (4.0 * um - 3.0 * u0 - u1) / h
    tt = tau * tau * b2
    return u1 - tau * (a + b2 * h) + tt + (ys - u0 + tau * a - tt) * E


@_jit
def _release(P, coef, W, s, hV):
    """The rest of a step (fraction s on, step h = hV[0], voltages hV[1], hV[2] at its ends) integrated
    free from (r0, 0), the other states interpolated at s from W[_W_OLD] to W[_W_END] (a prescribed current:
    exact at s); returns (x, v)."""
    h, Va, Vb = hV
    old, new, y0 = W[_W_OLD], W[_W_END], W[_W_Y0]
    for i in range(int(P[C_NY])):
        y0[i] = old[i] + s * (new[i] - old[i])
    y0[_X] = P[_R0]
    y0[_V] = 0.0
    if P[C_EXACT] != 0.0:
        Vr = Va / P[_R]
        y0[_I] = Vr + (old[_I] - Vr) * math.exp(-s * h * P[_R] / P[_L])
    Vs = Va + s * (Vb - Va)
    _rk4(P, coef, W, (1.0 - s) * h, (Vs, 0.5 * (Vs + Vb), Vb), 1.0, math.nan)
    return W[_W_YN, _X], W[_W_YN, _V]


@_jit
def _exact_release(P, W, hV, s0):
    """Fraction s in [s0, 1] of the step (h, held voltage V = hV) where the net contact force turns negative,
    on the prescribed (exact) current I(s h) = V/R + (I0 - V/R) exp(-s h R/L) (bisection to 1e-12; the other
    states linear in the step); s0 if it is negative there already."""
    h, V = hV
    old, end, scr = W[_W_OLD], W[_W_END], W[_W_SCR]
    Vr = V / P[_R]
    k = h * P[_R] / P[_L]
    lo, hi = s0, 1.0
    for it in range(41):
        s = lo if it == 0 else 0.5 * (lo + hi)
        for i in range(int(P[C_NY])):
            scr[i] = old[i] + s * (end[i] - old[i])
        scr[_I] = Vr + (old[_I] - Vr) * math.exp(-s * k)
        if _net(P, scr) < 0.0:
            if it == 0:
                return s0
            hi = s
        else:
            lo = s
    return hi


@_jit
def _step(P, coef, S, W, h, Vab):
    """One RK4 step of size h [s] of the run (P, S), voltages Vab = (start, end, linear) [V]."""
    Va, Vb, linear = Vab
    r0 = P[_R0]
    ny = int(P[C_NY])
    Vm = 0.5 * (Va + Vb) if linear else Va
    old, y0, end = W[_W_OLD], W[_W_Y0], W[_W_END]
    for i in range(ny):
        old[i] = S[i]
        y0[i] = S[i]
    fm = S[_FM]
    F_old = _rk4(P, coef, W, h, (Va, Vm, Vb), fm, S[_F])
    for i in range(ny):
        end[i] = W[_W_YN, i]
    I, x, v = end[_I], end[_X], end[_V]
    tau = P[C_TAUS]
    lag = tau > 0.0
    mid_I, mid_x = 0.0, 0.0
    if lag:
        mid_I, mid_x = _midpoint(W, h, _I), min(_midpoint(W, h, _X), r0)
    contact = S[_CT] != 0.0
    s_evt = -1.0
    stuck, net_imp, s_imp = False, 0.0, 0.0
    scr = W[_W_SCR]
    if fm > 0.0 and x >= r0:
        # impact located on the step's Hermite interpolant; the state there: x = r0, v = 0
        s_imp = hermite_crossing(old[_X], old[_V], x, v, h, r0)
        x, v = r0, 0.0
        s_evt = s_imp
        net_imp = _net_between(P, old, end, s_imp, scr)
        if net_imp >= 0.0:
            contact, fm, stuck = True, 0.0, True
    if contact:
        net_end = _net(P, end)
        if net_end < 0.0:
            g0, s0 = (net_imp, s_imp) if stuck else (_net(P, old), 0.0)
            if P[C_EXACT] != 0.0:
                s = _exact_release(P, W, (h, Va), s0)
            else:
                s = max(sign_change_fraction(g0, net_end), s0)
            s_evt = s
            x, v = _release(P, coef, W, s, (h, Va, Vb))
            contact, fm = False, 1.0
            if x >= r0:
                # pulled back onto the face within the same step: rests again if the net force pulls
                x, v = r0, 0.0
                if _net(P, end) >= 0.0:
                    contact, fm = True, 0.0
    F = _force_at(P, coef, I, x)
    if lag:
        E = P[C_LAGE]
        xs = _lag_quadratic(S[_XS], (old[_X], mid_x, x), h, tau, E)
        if s_evt >= 0.0:
            # x is r0 from the event on: the exact lag of the two linear pieces
            mid = _lag(S[_XS], old[_X], r0, s_evt * h, tau)
            xs = _lag(mid, r0, x, (1.0 - s_evt) * h, tau)
        S[_XS] = xs
        S[_FS] = _lag_quadratic(S[_FS], (F_old, _force_at(P, coef, mid_I, mid_x), F), h, tau, E)
    for i in range(ny):
        S[i] = end[i]
    S[_X], S[_V] = x, v
    S[_FM], S[_CT], S[_F] = fm, 1.0 if contact else 0.0, F


@_jit
def _record(P, S, out, r, col):
    """Outputs of run r at column col: out[0] I [A], out[1] x_sensor [m], out[2] F_sensor [N], out[3]
    contact (runs with the equilibrium settle test: out[1] = x only); returns the reading (F_sensor
    blocked, x_sensor free)."""
    if P[C_XSC] > 0.0:
        # the population runs (equilibrium settle test): the displacement only
        out[1, r, col] = S[_X]
        return S[_X]
    lag = P[C_TAUS] > 0.0
    xs = S[_XS] if lag else S[_X]
    Fs = S[_FS] if lag else S[_F]
    if P[_TERMS] != 0.0:
        # the reading terms of the term set (fmu_src.effects.sensor_readings: the core's lag switch is 0, so
        # it adds them to the readings passed in)
        xs, Fs = _readings(P, S, xs, Fs)
    out[0, r, col] = S[_I]
    out[1, r, col] = xs
    out[2, r, col] = Fs
    out[3, r, col] = S[_CT]
    return Fs if P[C_BLOCKED] != 0.0 else xs


@_jit
def _equilibrium_test(P, S):
    """The equilibrium settle test (see the module docstring): (fill, q, linear): fill the fill value [m]
    of a settled run (x_e, or r0 resting stably on the coil face), NaN if it is not settled; q the nearest
    stable equilibrium (-1: none); linear: not settled, but so close to x_e that the linearized motion is
    exact to C_LTOL * max(|x_e|, C_XSC): |h2| d^2/(2 k_e) + |h3| d^3/(6 k_e) below it, d the energy distance."""
    if S[_CT] != 0.0:
        return (P[_R0] if P[C_CSTAB] != 0.0 else math.nan), -1, False
    x, v = S[_X], S[_V]
    q_best, d_best = -1, math.inf
    for q in range(N_EQ):
        xe = P[C_EQ + 4 * q]
        if xe == xe and abs(x - xe) < d_best:
            q_best, d_best = q, abs(x - xe)
    if q_best < 0:
        return math.nan, -1, False
    e = C_EQ + 4 * q_best
    xe, ke = P[e], P[e + 1]
    dist2 = (x - xe) ** 2 + P[_M] * v * v / ke
    scale = max(abs(xe), P[C_XSC])
    tol = P[C_RTOL] * scale
    if dist2 <= tol * tol:
        return xe, q_best, False
    d = math.sqrt(dist2)
    lin = (abs(P[e + 2]) * dist2 / (2.0 * ke) + abs(P[e + 3]) * d * dist2 / (6.0 * ke)) <= P[C_LTOL] * scale
    return math.nan, q_best, lin and P[C_LTOL] > 0.0


@_jit
def _linear_tail(P, S, x_out, q, dt):
    """Write the exact solution of the linearized motion about equilibrium q into x_out[1:] (one entry per
    output, spacing dt [s]) until an upper bound of |x - x_e| falls below the settle tolerance or x_out
    ends: m d'' + C d' + k_e d = 0, d = x - x_e, from the state S. Returns (entries written, reached)."""
    e = C_EQ + 4 * q
    xe, ke = P[e], P[e + 1]
    m, C = P[_M], P[_C]
    d0, v0 = S[_X] - xe, S[_V]
    sig = C / (2.0 * m)
    disc = sig * sig - ke / m
    mu = math.sqrt(abs(disc))
    crit = mu < 1e-3 * sig
    c1, c2 = abs(d0), abs(v0 + sig * d0)
    if crit:
        rate, c_exp, A, B = sig, math.inf, 0.0, 0.0
    elif disc > 0.0:                     # overdamped: A e^(l1 t) + B e^(l2 t)
        l1, l2 = -sig + mu, -sig - mu
        A = (v0 - l2 * d0) / (l1 - l2)
        B = d0 - A
        rate, c_exp = -l1, abs(A) + abs(B)
    else:                                # underdamped: e^(-sig t) (d0 cos(w t) + (v0 + sig d0)/w sin(w t))
        A, B = d0, (v0 + sig * d0) / mu
        rate, c_exp = sig, math.sqrt(A * A + B * B)
    tol = P[C_RTOL] * max(abs(xe), P[C_XSC])
    t_peak = 1.0 / rate - c1 / c2 if c2 > 0.0 else 0.0
    n = x_out.size - 1
    # the exponentials on the output grid by recurrence (powers of their one-output factors)
    q_re, q_im = math.exp(-sig * dt) * math.cos(mu * dt), math.exp(-sig * dt) * math.sin(mu * dt)
    e1, e2 = math.exp((-sig + mu) * dt), math.exp((-sig - mu) * dt)
    eb, er = math.exp(-sig * dt), math.exp(-rate * dt)
    z_re, z_im, p1, p2, pb, pr = 1.0, 0.0, 1.0, 1.0, 1.0, 1.0
    for j in range(1, n + 1):
        tau = j * dt
        pb *= eb
        pr *= er
        if crit:
            d = (d0 + (v0 + sig * d0) * tau) * pb
        elif disc > 0.0:
            p1 *= e1
            p2 *= e2
            d = A * p1 + B * p2
        else:
            z_re, z_im = z_re * q_re - z_im * q_im, z_re * q_im + z_im * q_re
            d = A * z_re + B * z_im
        x_out[j] = xe + d
        if tau >= t_peak and pr * min(c_exp, c1 + c2 * tau) <= tol:
            return j, True
    return n, False


@_jit
def run_part(P, coef, S, V, out, plan, check, last):
    """Integrate every active run through one part of the schedule, in place.

    Parameters
    ----------
    P : (N, NPAR) parameter blocks (the part's step [s] and steps per output in columns C_H, C_PER);
    coef : stacked kernel coefficients (4, segments);  S : (N, NSTATE) states;  V : (rows, n_v) voltages [V]
    (column 0 for a constant input), run r reads row P[r, C_VROW];  out : (4, N, n_out) outputs (see ``_record``);  plan : (outputs,
    first column, input mode 0 constant / 1 zero-order hold / 2 linear, tol_I [A]);  check : (outputs,)
    bool, settle check after that output (settled runs get active = 0; the equilibrium test also sets
    their fill value);  last : (N,) int, the last column written per run.
    """
    n_int, col0, mode, tol_I = int(plan[0]), int(plan[1]), int(plan[2]), plan[3]
    W, back = np.zeros((_W_ROWS, NY)), np.zeros(NSTATE)
    for r in range(P.shape[0]):
        if S[r, _ACT] == 0.0:
            continue
        Pr, Sr = P[r], S[r]
        h, per, vr = Pr[C_H], int(Pr[C_PER]), int(Pr[C_VROW])
        span, per0, own_k = h * per, per, Pr[C_OWNK]
        for k in range(n_int):
            back[:] = Sr      # a lag of its own rate (Dahl's |v|/x_c): sub-steps from the speeds reached (C_OWNK)
            while True:
                if own_k > 0.0:
                    Pr[C_LAGE] = math.exp(-h / Pr[C_TAUS]) if Pr[C_TAUS] > 0.0 else 0.0
                worst = abs(Sr[_V])
                for j in range(per):
                    if mode == 0:
                        Va = Vb = V[vr, 0]
                    elif mode == 1:
                        Va = Vb = V[vr, k]
                    else:
                        Va = V[vr, k] + (V[vr, k + 1] - V[vr, k]) * (j / per)
                        Vb = V[vr, k] + (V[vr, k + 1] - V[vr, k]) * ((j + 1) / per)
                    _step(Pr, coef, Sr, W, h, (Va, Vb, mode == 2))
                    worst = max(worst, abs(Sr[_V]))
                if not h * worst * own_k > OWN_H_RATE or per >= OWN_MAX_PER:
                    break
                Sr[:] = back
                per *= 2
                h = span / per
            per, h = (max(per0, per // 2), span / max(per0, per // 2)) if per > per0 else (per, h)
            y = _record(Pr, Sr, out, r, col0 + k)
            last[r] = col0 + k
            if not check[k]:
                continue
            if Pr[C_XSC] > 0.0:
                if col0 + k >= Pr[C_KQ]:
                    fill, q, lin = _equilibrium_test(Pr, Sr)
                    if fill == fill:
                        Sr[_FILL] = fill
                        Sr[_ACT] = 0.0
                        break
                    if lin and k + 1 < n_int:
                        # the rest is the linearized motion: written in closed form (x only), then x_e
                        c = col0 + k
                        n_w, reached = _linear_tail(Pr, Sr, out[1, r, c:col0 + n_int], q, span)
                        last[r] = c + n_w
                        Sr[_FILL] = Pr[C_EQ + 4 * q] if reached else math.nan
                        Sr[_ACT] = 0.0
                        break
                continue
            done = (Pr[C_SLOW] == 0.0 and abs(y - Sr[_CHY]) <= Pr[C_TOLY] and abs(Sr[_I] - Sr[_CHI]) <= tol_I
                    and abs(Sr[_V]) * 0.05 <= Pr[C_TOLY])
            Sr[_CHY], Sr[_CHI] = y, Sr[_I]
            if done:
                Sr[_ACT] = 0.0
                break


@_jit
def time_major(x, last, fill, H, cols):
    """The compact block of population runs: H[k, cols[j]] = x[j, k] (run j's recorded outputs, run-major as
    ``run_part`` writes them) for k <= last[j], fill[j] after (in tiles of 32 rows: contiguous writes)."""
    R = H.shape[0]
    for k0 in range(0, R, 32):
        k1 = min(k0 + 32, R)
        for j in range(x.shape[0]):
            c, L, f = cols[j], last[j], fill[j]
            for k in range(k0, k1):
                H[k, c] = x[j, k] if k <= L else f


@_jit
def _rhs_rows(P, coef, Y, V, out):
    for r in range(P.shape[0]):
        _rhs(P[r], coef, Y[r], V[r], Y[r, NY], math.nan, out[r])
        out[r, NY] = _force_at(P[r], coef, Y[r, _I], Y[r, _X])
        out[r, NY + 1] = _net(P[r], Y[r])


def rhs(P: np.ndarray, coef: np.ndarray, Y: np.ndarray, V: np.ndarray) -> np.ndarray:
    """The core's right-hand side per run (for tests): Y (N, NY + 1) = the state y (``Y_STATES``) and fm,
    V (N,) [V]; returns (N, NY + 2): y', the magnetic force [N] at the state and the net contact force [N]
    on the coil face at the state's current and effect states."""
    out = np.zeros((Y.shape[0], NY + 2))
    _rhs_rows(np.ascontiguousarray(P), coef, np.ascontiguousarray(Y, dtype=float),
              np.ascontiguousarray(V, dtype=float), out)
    return out
