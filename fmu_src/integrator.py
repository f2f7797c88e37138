"""The FMU's scalar integrator, compiled with numba: DP5(4) with dense output, contact/release events.

``fmu_src.model`` (``Dynamics``, ``EffectDynamics``, ``Integrator``, ``ActuatorModel``) is the Python API;
it keeps parameters and state in preallocated float64 arrays (layout below) and calls the compiled
functions of this module: one call per communication step (``advance``) and one when the outputs are
read (``outputs``).

One implementation of the physics: every formula is a function of ``fmu_src.effects`` (the whole model:
``rates``, ``force``, ``contact_force``, ``sensor_readings``, built from the term functions there and in
``fmu_src.diaphragm``) or ``fmu_src.field`` (the force kernel), plain arithmetic on floats and numpy arrays
that the vectorized simulators of ``harness.sim`` call uncompiled; the compiled versions below are made
from those very function objects (``numba.njit(fx.rates)``, ...; their ``py_func`` is the original, tested
in tests/fmu/test_jit.py). Here are only the integration scheme (tableau, error norm, step control, dense
output), the contact logic and the state bookkeeping; nothing here depends on which effects exist: the
head of the parameter block is laid out by ``fmu_src.specs.BLOCK``.

Caching: every compiled function is cached (``cache=True``) in ``fmu_src/__pycache__``. numba keys
a cache entry to the source of the file that defines the function only; this module's locator
(``_PhysicsCacheLocator``) keys it to the contents of every module whose code or constants are compiled
in (``PHYSICS_SOURCES``), so that an edit of a physics function or of the specs invalidates the cache.
The key is a content hash (no mtimes), so a freshly extracted FMU whose resources ship the cache
(``build_fmu.py`` builds it) loads it without compiling.
"""
from __future__ import annotations

import hashlib
import math
import os

import numba
import numpy as np
from numba.core import caching as _nb_caching

from . import effects as _fx
from . import field as _field
from .specs import BLOCK

_HERE = os.path.dirname(os.path.abspath(__file__))
# every module whose functions (or constants: the block layout) are compiled into this module's functions
PHYSICS_SOURCES = ("integrator.py", "specs.py", "diaphragm.py", "effects.py", "field.py", "paramspec.py", "terms.py",
                   "termsum.py")


class _PhysicsCacheLocator(_nb_caching.InTreeCacheLocator):
    """numba's in-tree cache (__pycache__ next to the defining file), keyed to the contents of
    PHYSICS_SOURCES (and of the files a module registered with :func:`register_compiled_module`)."""

    _stamps: dict = {}
    modules: dict = {__name__: ()}    # module name -> its own source files (absolute paths)

    def get_source_stamp(self):
        files = tuple(os.path.join(_HERE, name) for name in PHYSICS_SOURCES) + self.modules.get(self._module, ())
        stamps = tuple((f, os.stat(f).st_mtime_ns, os.stat(f).st_size) for f in files)
        cached = _PhysicsCacheLocator._stamps.get(files)
        if cached is None or cached[0] != stamps:
            h = hashlib.sha256()
            for f in files:
                with open(f, "rb") as fh:
                    h.update(os.path.basename(f).encode() + b"\0" + fh.read() + b"\0")
            cached = _PhysicsCacheLocator._stamps[files] = (stamps, h.digest())
        return cached[1]

    @classmethod
    def from_function(cls, py_func, py_file):
        module = getattr(py_func, "__module__", None)
        if module not in cls.modules:
            return None
        inst = super().from_function(py_func, py_file)
        if inst is not None:
            inst._module = module
        return inst


def register_compiled_module(module: str, source: str) -> None:
    """Key the numba cache of the functions of ``module`` (defined in the file ``source``) that call the
    compiled physics (``COMPILED_PHYSICS``) to the contents of PHYSICS_SOURCES and of ``source``: an edit
    of the physics then invalidates their cache too (numba alone keys it to ``source`` only)."""
    _PhysicsCacheLocator.modules[module] = (os.path.abspath(source),)


if not any(c.__name__ == "_PhysicsCacheLocator" and c.__module__ == __name__
           for c in _nb_caching.CacheImpl._locator_classes):
    _nb_caching.CacheImpl._locator_classes.insert(0, _PhysicsCacheLocator)

_jit = numba.njit(cache=True, error_model="numpy")

# compiled versions of the physics functions: made from the same function objects the vectorized paths call
_rates = numba.njit(_fx.rates)
_force = numba.njit(_fx.force)
_force_drives_states = numba.njit(_fx.force_drives_states)
_contact_force = numba.njit(_fx.contact_force)
_sensor_readings = numba.njit(_fx.sensor_readings)
_kernel_value = numba.njit(_field.kernel_value)
_axial_field = numba.njit(_field.axial_field)
COMPILED_PHYSICS = {"rates": _rates, "force": _force, "force_drives_states": _force_drives_states,
                    "contact_force": _contact_force, "sensor_readings": _sensor_readings,
                    "kernel_value": _kernel_value, "axial_field": _axial_field}

FREE, CONTACT, BLOCKED = 0, 1, 2
NMAX = BLOCK.n_states_max   # states: I, x, v and every effect's states

# ---- parameter block (the head of every state array; ``Dynamics.P``), float64
P_R0, P_A, P_KB = (BLOCK.param[n] for n in ("r0", "a", "kB"))    # parameters, effect switches, effect
NB = BLOCK.size                                                   # state indices: fmu_src.specs.BLOCK
K_SMAX, K_DR, K_INVDR, K_G0, K_DG0 = range(NB, NB + 5)            # force-kernel table (coef passed apart)
P_RTOL, P_MAXSTEP, P_N = NB + 5, NB + 6, NB + 7                   # tolerance, step bound, number of states
P_MAXSTEPS = NB + 8                                               # most internal steps one advance may take
P_ATOL = NB + 9                                                   # absolute tolerances, NMAX entries
NP = P_ATOL + NMAX
# ---- integrator scalars, after the parameter block
S_T = NP          # view time
S_TF = NP + 1     # integration front time (runs ahead of the view while the input is held)
S_MODE = NP + 2   # mode at the front
S_V = NP + 3      # held input (NaN before the first advance)
S_CHANGED = NP + 4
S_K0 = NP + 5     # 1.0: the FSAL derivative at the front is valid (W[W_K])
S_H = NP + 6      # next step size
S_DENSE = NP + 7  # 1.0: the dense record (S_DT0, S_DH, S_DMODE, W[W_DY0], W[W_DQ:]) is valid
S_DT0, S_DH, S_DMODE = NP + 8, NP + 9, NP + 10
S_VMODE = NP + 11  # mode at the view time (state in W[W_VIEW])
NS = NP + 12
# ---- work rows W[slot, :n]
W_Y, W_K, W_YNEW, W_TMP, W_DY0, W_DQ, W_VIEW, W_YC = 0, 1, 8, 9, 10, 11, 15, 16
NW = 17

# Dormand-Prince 5(4) tableau (Hairer & Wanner), as in scipy's RK45.
A21 = 1 / 5
A31, A32 = 3 / 40, 9 / 40
A41, A42, A43 = 44 / 45, -56 / 15, 32 / 9
A51, A52, A53, A54 = 19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729
A61, A62, A63, A64, A65 = 9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656
B1, B3, B4, B5, B6 = 35 / 384, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84
E1, E3, E4, E5, E6, E7 = -71 / 57600, 71 / 16695, -71 / 1920, 17253 / 339200, -22 / 525, 1 / 40
# Dense output: y(t + s*h) = y + h * sum_c Q_c s^(c+1), Q = K^T P (rows of P for k1..k7; k2's row is 0).
DENSE_P = np.array((
    (1.0, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432),
    (0.0, 0.0, 0.0, 0.0),
    (0.0, 131558114200 / 32700410799, -68118460800 / 10900136933, 87487479700 / 32700410799),
    (0.0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072),
    (0.0, 127303824393 / 49829197408, -318862633887 / 49829197408, 701980252875 / 199316789632),
    (0.0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844),
    (0.0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423),
))

OK, UNDERFLOW, TOO_MANY_STEPS = 0, 1, 2
H_MIN = 1e-14   # smallest step size [s] before the integrator gives up (UNDERFLOW)


# ------------------------------------------------------------------------------------------ physics
@_jit
def kernel(P, coef, r):
    """G(r) of the parameter block's force-kernel table."""
    return _kernel_value(r, coef, 0, P[K_SMAX], P[K_DR], P[K_INVDR], P[K_G0], P[K_DG0])


@_jit
def force_at(P, coef, I, r):
    """Magnetic force [N] at current I [A] and distance r [m] (``fmu_src.effects.force``)."""
    return _force(P, I, kernel(P, coef, r))


@_jit
def rhs(P, coef, y, V, mode, out):
    """dy/dt into out[:n] for the state y under voltage V in the given mode (``fmu_src.effects.rates``)."""
    if mode == FREE:
        x, v = y[1], y[2]
    elif mode == CONTACT:
        x, v = P[P_R0], 0.0
    else:
        x, v = 0.0, 0.0
    free = mode == FREE
    F = 0.0
    if free or _force_drives_states(P):
        F = force_at(P, coef, y[0], P[P_R0] - x)
    _rates(P, y, V, x, v, F, free, out)


@_jit
def net_contact_force(P, coef, y):
    """Magnetic minus restoring force [N] with the diaphragm on the coil face (x = r0)."""
    return _contact_force(P, y, force_at(P, coef, y[0], 0.0))


@_jit
def outputs(P, coef, y, mode, out):
    """out[:8] = I, x, v, F, B, contact (1.0/0.0), x_sensor, F_sensor of the state y in the given mode."""
    r = max(P[P_R0] - y[1], 0.0)
    F = force_at(P, coef, y[0], r)
    out[0] = y[0]
    out[1] = y[1]
    out[2] = y[2]
    out[3] = F
    out[4] = _axial_field(y[0], r, P[P_A], P[P_KB])
    out[5] = 1.0 if mode == CONTACT else 0.0
    out[6], out[7] = _sensor_readings(P, y, y[1], F)


# ------------------------------------------------------------------------------------------ integrator
@_jit
def _interp(S, W, t, out):
    """Dense output of the step record at time t into out."""
    n = int(S[P_N])
    t0, h = S[S_DT0], S[S_DH]
    s = (t - t0) / h
    s2 = s * s
    s3 = s2 * s
    s4 = s3 * s
    for i in range(n):
        out[i] = W[W_DY0, i] + h * (W[W_DQ, i] * s + W[W_DQ + 1, i] * s2 + W[W_DQ + 2, i] * s3
                                    + W[W_DQ + 3, i] * s4)


@_jit
def _event_g(S, W, coef, kind, s):
    """Event function at the fraction s of the dense step: kind 0 contact (x - r0), 1 release (-net force)."""
    yc = W[W_YC]
    _interp(S, W, S[S_DT0] + s * S[S_DH], yc)
    if kind == 0:
        return yc[1] - S[P_R0]
    return -net_contact_force(S, coef, yc)


@_jit
def _root(S, W, coef, kind):
    """Smallest s in (0, 1] with g(s) = 0 where g(0) < 0 <= g(1); bisection + secant."""
    tol = 1e-13
    lo, hi = 0.0, 1.0
    glo = _event_g(S, W, coef, kind, lo)
    ghi = _event_g(S, W, coef, kind, hi)
    if glo >= 0.0:
        return 0.0
    for _ in range(80):
        s = hi - ghi * (hi - lo) / (ghi - glo) if ghi != glo else 0.5 * (lo + hi)
        if not (lo < s < hi):
            s = 0.5 * (lo + hi)
        gs = _event_g(S, W, coef, kind, s)
        if gs >= 0.0:
            hi, ghi = s, gs
        else:
            lo, glo = s, gs
        if hi - lo < tol:
            break
    return hi


@_jit
def _truncate(S, W, s):
    """Restrict the dense record to the first fraction s of its step."""
    n = int(S[P_N])
    for i in range(n):
        W[W_DQ + 1, i] = W[W_DQ + 1, i] * s
        W[W_DQ + 2, i] = W[W_DQ + 2, i] * s * s
        W[W_DQ + 3, i] = W[W_DQ + 3, i] * s ** 3
    S[S_DH] = s * S[S_DH]


@_jit
def _stop_at_event(S, W, coef, kind, t0, h):
    """Move the front to the event of the step [t0, t0 + h] (kind 0: impact, 1: release), located on the
    dense output: the state there on the coil face (x = r0, v = 0), the dense record cut at the event."""
    n = int(S[P_N])
    s = _root(S, W, coef, kind)
    yc = W[W_YC]
    _interp(S, W, t0 + s * h, yc)
    yc[1] = S[P_R0]
    yc[2] = 0.0
    if s > 0:
        _truncate(S, W, s)
    else:
        S[S_DENSE] = 0.0
    S[S_TF] = t0 + s * h
    y = W[W_Y]
    for i in range(n):
        y[i] = yc[i]
    S[S_K0] = 0.0


@_jit
def _step(S, W, coef, t_end):
    """One accepted DP5 step from the front (events: contact, release). Returns OK or UNDERFLOW."""
    n = int(S[P_N])
    V = S[S_V]
    mode = int(S[S_MODE])
    y = W[W_Y]
    if S[S_K0] == 0.0:
        rhs(S, coef, y, V, mode, W[W_K])
        S[S_K0] = 1.0
    k1, k2, k3, k4 = W[W_K], W[W_K + 1], W[W_K + 2], W[W_K + 3]
    k5, k6, k7 = W[W_K + 4], W[W_K + 5], W[W_K + 6]
    ynew, tmp = W[W_YNEW], W[W_TMP]
    t = S[S_TF]
    h = min(S[S_H], S[P_MAXSTEP])
    clipped = False
    if S[S_CHANGED] != 0.0 and t + h > t_end:
        # the input has been changing: stop at the communication point instead of
        # integrating ahead a step that the next input change would throw away
        h = t_end - t
        clipped = True
    rtol = S[P_RTOL]
    while True:
        for i in range(n):
            tmp[i] = y[i] + h * A21 * k1[i]
        rhs(S, coef, tmp, V, mode, k2)
        for i in range(n):
            tmp[i] = y[i] + h * (A31 * k1[i] + A32 * k2[i])
        rhs(S, coef, tmp, V, mode, k3)
        for i in range(n):
            tmp[i] = y[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i])
        rhs(S, coef, tmp, V, mode, k4)
        for i in range(n):
            tmp[i] = y[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i])
        rhs(S, coef, tmp, V, mode, k5)
        for i in range(n):
            tmp[i] = y[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i])
        rhs(S, coef, tmp, V, mode, k6)
        for i in range(n):
            ynew[i] = y[i] + h * (B1 * k1[i] + B3 * k3[i] + B4 * k4[i] + B5 * k5[i] + B6 * k6[i])
        rhs(S, coef, ynew, V, mode, k7)
        err = 0.0
        for i in range(n):
            e = h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i])
            sc = S[P_ATOL + i] + rtol * max(abs(y[i]), abs(ynew[i]))
            err += (e / sc) ** 2
        err = math.sqrt(err / n)
        if err <= 1.0:
            fac = 5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** -0.2))
            if not (clipped and fac * h < S[S_H]):
                S[S_H] = h * fac
            break
        if not math.isfinite(err):
            h *= 0.1
        else:
            h *= max(0.1, 0.9 * err ** -0.2)
        clipped = False
        if h < H_MIN:
            return UNDERFLOW
    # dense record of the accepted step: Q = K^T P
    t0 = t
    S[S_DENSE] = 1.0
    S[S_DT0] = t0
    S[S_DH] = h
    S[S_DMODE] = mode
    for i in range(n):
        W[W_DY0, i] = y[i]
        for c in range(4):
            q = 0.0
            for j in (0, 2, 3, 4, 5, 6):
                q += W[W_K + j, i] * DENSE_P[j, c]
            W[W_DQ + c, i] = q
    # events
    r0 = S[P_R0]
    if mode == FREE and ynew[1] > r0:
        _stop_at_event(S, W, coef, 0, t0, h)   # impact on the coil face
        if net_contact_force(S, coef, y) >= 0.0:
            S[S_MODE] = CONTACT
        else:
            S[S_MODE] = FREE
            y[1] = r0 * (1.0 - 1e-12)
        return OK
    if mode == CONTACT and net_contact_force(S, coef, ynew) < 0.0:
        _stop_at_event(S, W, coef, 1, t0, h)   # release: the net force stops pulling toward the coil
        S[S_MODE] = FREE
        return OK
    S[S_TF] = t0 + h
    for i in range(n):
        y[i] = ynew[i]
        k1[i] = k7[i]
    return OK


@_jit
def _update_view(S, W):
    """State and mode at the view time into W[W_VIEW], S[S_VMODE]."""
    n = int(S[P_N])
    t = S[S_T]
    view = W[W_VIEW]
    if S[S_DENSE] != 0.0 and S[S_DT0] <= t < S[S_TF]:
        _interp(S, W, t, view)
        if int(S[S_DMODE]) != FREE:
            view[1] = W[W_DY0, 1]
            view[2] = 0.0
        elif view[1] > S[P_R0]:
            # the dense output may pass the coil face inside a step whose ends are below it: x <= r0 always
            view[1] = S[P_R0]
        S[S_VMODE] = S[S_DMODE]
    else:
        for i in range(n):
            view[i] = W[W_Y, i]
        S[S_VMODE] = S[S_MODE]


@_jit
def advance(S, W, coef, t_end, V):
    """Integrate to t_end with the input V held since the view time S[S_T]; OK, UNDERFLOW, or
    TOO_MANY_STEPS (more than S[P_MAXSTEPS] internal steps; the view stays where it was).

    With V unchanged the front may already be past t_end (run-ahead: the view is interpolated);
    with a new V the integration restarts from the view state and stops at t_end.
    """
    n = int(S[P_N])
    changed = V != S[S_V]
    S[S_CHANGED] = 1.0 if changed else 0.0
    if changed:
        # restart from the current view state with the new input
        S[S_TF] = S[S_T]
        for i in range(n):
            W[W_Y, i] = W[W_VIEW, i]
        S[S_MODE] = S[S_VMODE]
        S[S_K0] = 0.0
        S[S_DENSE] = 0.0
        S[S_V] = V
    n_steps = 0
    while S[S_TF] < t_end:
        if n_steps >= S[P_MAXSTEPS]:
            return TOO_MANY_STEPS
        status = _step(S, W, coef, t_end)
        if status != OK:
            return status
        n_steps += 1
    S[S_T] = t_end
    _update_view(S, W)
    return OK


@_jit
def view_outputs(S, W, coef, out):
    """Outputs at the view time into out[:8] (see ``outputs``)."""
    outputs(S, coef, W[W_VIEW], int(S[S_VMODE]), out)
