"""Per-run constants of the vectorized simulator and its step-size rules: the parameter blocks of the
compiled core (:mod:`harness.sim.core`, whose right-hand side is ``fmu_src.effects.rates``), the force
kernels (:mod:`harness.sim.kernels`), the sub-steps per sample period and the coarse step of the
quasi-static remainder (bounds from ``fmu_src.effects``' ``magnetic_force``, ``restoring_force``,
``tangent_stiffness``).

The constants of a batch are a dict ``c`` of (N,) arrays (the names of ``PARAM_FIELDS``, ``blocked``,
``V``, ``tol_y``, ``slow``), the stacked kernel table ``kt`` and the input hold ``hold``. Units: SI.

Nothing here names an effect: the parameters, switches and states come from ``fmu_src.specs`` (``BLOCK``,
``EFFECTS``; the core's state layout ``harness.sim.core.Y_STATES``), an effect's time constants are its
parameters in seconds (``TIME_CONSTANTS``), its spring terms come from ``fmu_src.effects``'
``restoring_force_of`` and ``tangent_stiffness_of``.
"""
from __future__ import annotations

import numpy as np

from fmu_src import effects as fx

from fmu_src.specs import BASE_STATES, BLOCK, EFFECTS, TERM_FIELDS
from fmu_src.terms import LAGS, TERMS

from . import core
from .kernels import KernelTable, kernel

__all__ = ["PARAM_FIELDS", "TERM_FIELDS", "FLAG_NAMES", "TIME_CONSTANTS", "SLOW_EFFECTS", "EXACT_TAU", "STATE_POSITION",
           "constants", "effect_tau", "param_blocks", "substeps", "coarse_rate", "own_rate_per_speed"]

# every parameter, in the order of the parameter block (fmu_src.specs.BLOCK: the paper's, then the effects')
PARAM_FIELDS = tuple(BLOCK.param)
# the effect switches, in catalogue order (fmu_src.specs.EFFECTS)
FLAG_NAMES = tuple(e.switch for e in EFFECTS.values())
# an effect's time constants: its parameters in seconds (the time constants of its states)
TIME_CONSTANTS = {name: tuple(s.name for s in e.param_specs if s.unit == "s") for name, e in EFFECTS.items()}
# effects whose states the core integrates (slow states: a run with one on is never frozen by the change test)
SLOW_EFFECTS = tuple(name for name, e in EFFECTS.items() if any(s in core.Y_STATES for s in e.states))
# the time constant of the effect the core solves exactly (the sensor lag's)
EXACT_TAU = TIME_CONSTANTS[core.EXACT_EFFECT][0]
# position of every effect state in the core's RK4 state y (-1: solved outside it, the sensor lag's)
STATE_POSITION = {name: (core.Y_STATES.index(name) if name in core.Y_STATES else -1) for name in BLOCK.state}
assert core.Y_STATES[:len(BASE_STATES)] == BASE_STATES


def constants(runs) -> dict:
    """The per-run constants of ``runs`` (a :class:`harness.sim.simulator.Runs`) as the compiled core takes them."""
    f = {k: np.asarray(runs.params[k], dtype=float) for k in PARAM_FIELDS}
    N = runs.n
    blocked = np.asarray(runs.blocked, dtype=bool)
    c = dict(f)
    keys, inverse = np.unique(np.column_stack([f["a"], f["D"], f["kB"], f["r0"]]), axis=0, return_inverse=True)
    kernels = [kernel(*k) for k in keys]       # one look-up per distinct coil geometry and gap
    c["kt"] = KernelTable(kernels, inverse.ravel())
    c["blocked"] = blocked
    c["V"] = np.asarray(runs.V, dtype=float)
    tol_y = runs.tol_y if runs.tol_y is not None else np.where(blocked, 1e-7, 1e-10)
    c["tol_y"] = np.broadcast_to(np.asarray(tol_y, dtype=float), (N,)).copy()
    c["slow"] = np.zeros(N, dtype=bool)
    for name in SLOW_EFFECTS:
        c["slow"] |= f[EFFECTS[name].switch] > 0
    c["terms"], c["lag_on"] = term_switches(f)
    for on in c["lag_on"].values():
        c["slow"] |= on       # a lag state in use: a slow state
    c["hold"] = runs.hold
    return c


def term_switches(f: dict) -> tuple:
    """Per run, from the parameter arrays f: the term set's switch (any coefficient c_<term> nonzero) and
    {lag: in use (a term with a nonzero coefficient uses it)} (``fmu_src.terms``), (N,) bool arrays."""
    n = np.asarray(f["R"]).size
    on = {name: np.broadcast_to(np.asarray(f[t.coef.name], dtype=float) != 0.0, (n,)) for name, t in TERMS.items()}
    lag_on = {g: np.zeros(n, dtype=bool) for g in LAGS}
    for name, t in TERMS.items():
        if t.lag is not None:
            lag_on[t.lag] = lag_on[t.lag] | on[name]
    return np.logical_or.reduce(list(on.values())), lag_on


def effect_tau(strength, tau):
    """Time constant [s] per run of an effect's state: tau where the effect is on (strength > 0; 1 s
    should tau be missing), inf where it is off (rate 0: its state stays 0)."""
    return np.where(strength > 0, np.where(tau > 0, tau, 1.0), np.inf)


def _slow_time_constants(c: dict) -> dict:
    """{time-constant parameter: (N,) array [s]} of the slow effects' states per run (:func:`effect_tau`:
    inf where the effect is off)."""
    return {tau: effect_tau(c[EFFECTS[name].switch], c[tau]) for name in SLOW_EFFECTS for tau in TIME_CONSTANTS[name]}


def param_blocks(c: dict) -> np.ndarray:
    """The parameter blocks of the compiled core (:func:`harness.sim.core.param_block`) of the runs in c:
    every parameter, the effect switches per run (its switch parameter > 0; the sensor lag's 0: the core
    solves the lag exactly, outside the RK4 state), the effect states at their positions in the core's y
    (``STATE_POSITION``), the slow effects' time constants from :func:`effect_tau`."""
    head = [0.0] * BLOCK.size
    for name, i in BLOCK.param.items():
        head[i] = c[name]
    for tau, value in _slow_time_constants(c).items():
        head[BLOCK.param[tau]] = value
    for name, i in BLOCK.switch.items():
        head[i] = 0.0 if name == core.EXACT_EFFECT else (c[EFFECTS[name].switch] > 0).astype(float)
    for name, i in BLOCK.state.items():
        head[i] = float(STATE_POSITION[name])
    head[BLOCK.terms] = c["terms"].astype(float)
    for name, i in BLOCK.lag_on.items():
        head[i] = c["lag_on"][name].astype(float)
    for name, i in BLOCK.lag_state.items():
        head[i] = float(core.Y_STATES.index(name))
    P = core.param_block(head, c["kt"], {"tol_y": c["tol_y"], "slow": c["slow"], "tau_s": c[EXACT_TAU],
                                         "blocked": c["blocked"]})
    P[:, core.C_OWNK] = own_rate_per_speed(c)
    return P


def _rates(c: dict):
    """(omega, C/m, R/L, 1/tau) [1/s] per run: the fastest rates the run can reach (1/tau: the fastest time constant
    of the slow effects and first-order lags that are on, 0 if none). A lag with its own rate (Dahl's |v|/x_c) is
    not among them: its rate follows the speed the run reaches, which the core checks step by step
    (:func:`own_rate_per_speed`, ``harness.sim.core.C_OWNK``)."""
    free0 = ~c["blocked"]
    V = c["V"]
    Vm = np.abs(V).max(axis=-1) if V.ndim > 1 else np.abs(V)
    F0 = fx.magnetic_force(c["Em"], Vm / c["R"], c["kt"].G0)   # largest magnetic force (at the coil face)
    r0 = c["r0"]
    reach = F0 >= fx.restoring_force_of(r0, c)         # may be pulled in (creep's branch relaxed)
    # deflection bound: the gap if pull-in is possible, else twice the static deflection under F0
    x_hi = np.where(c["blocked"], 0.0, np.where(reach, r0, np.minimum(r0, 2.0 * F0 / c["K2"])))
    k_t = fx.tangent_stiffness_of(x_hi, c)
    k_mag = F0 * 3.0 / np.maximum(c["a"], 1e-9)       # bound on the magnetic force's gradient
    omega = np.where(free0, np.sqrt((k_t + k_mag) / c["m"]), 0.0)
    damp = np.where(free0, c["C"] / c["m"], 0.0)
    inv_tau = np.zeros(len(c["R"]))
    for value in _slow_time_constants(c).values():
        inv_tau = np.maximum(inv_tau, 1.0 / value)
    rl = c["R"] / c["L"]
    if c["terms"].any():
        v_hi = omega * x_hi + 1e-3
        for g, on in c["lag_on"].items():
            if LAGS[g].first_order:
                tau = np.where(on, c[f"tau_{g}"], 1.0)
                inv_tau = np.maximum(inv_tau, np.where(on, 1.0 / tau, 0.0))
        k_x, k_v, k_I = _term_gradients(c, x_hi, v_hi, Vm / c["R"], F0)
        omega = np.where(free0, np.sqrt((k_t + k_mag + k_x) / c["m"]), 0.0)
        damp = np.where(free0, (c["C"] + k_v) / c["m"], 0.0)
        rl = (c["R"] + k_I) / c["L"]
    return omega, damp, rl, inv_tau


def own_rate_per_speed(c: dict) -> np.ndarray:
    """Per run, the rate |dz'/dz| [1/s] of its lags with their own rate (``LagSpec.rate``: Dahl's, (v - |v| z)/x_c)
    per unit speed [1/m] (at 1 m/s, a central difference in z; the largest over such lags that are on; 0 if none):
    such a rate grows with the speed (|v|/x_c), so the core sizes these runs' sub-steps from the speeds they reach
    (``harness.sim.core.run_part``) rather than from an a-priori bound of the speed, which for a stiff presliding
    length (um) asked for 20 to 3000 times the steps the motion needs."""
    n = len(c["R"])
    out = np.zeros(n)
    if not c["terms"].any():
        return out
    for g, on in c["lag_on"].items():
        spec = LAGS[g]
        if spec.first_order or not on.any():
            continue
        tau = np.where(on, c[f"tau_{g}"], 1.0)
        zero = np.zeros(n)
        h = 1e-3
        r = np.abs(spec.rate(zero, 1.0 + zero, zero, zero, c["R"], h, tau)
                   - spec.rate(zero, 1.0 + zero, zero, zero, c["R"], -h, tau)) / (2 * h)
        out = np.maximum(out, np.where(on, r, 0.0))
    return out


def _presliding_stiffness(t, coef, c: dict) -> np.ndarray:
    """Bound [N/m] per run of the spring that a force term on a lag with its own rate (Dahl) adds at rest:
    2*|c|*|dphi/dz|*|dz'/dv| at v = 0, z = 0 (central differences; 2 bounds a Dahl rate's (1 + |z|))."""
    g = LAGS[t.lag]
    tau = np.where(coef > 0, c[g.tau.name], 1.0)
    h = 1e-9
    dz_dv = (g.rate(0.0, h, 0.0, 0.0, 0.0, 0.0, tau) - g.rate(0.0, -h, 0.0, 0.0, 0.0, 0.0, tau)) / (2 * h)
    dphi_dz = (t.function(0.0, 0.0, 0.0, 0.0, 1e-6) - t.function(0.0, 0.0, 0.0, 0.0, -1e-6)) / 2e-6
    return 2.0 * coef * np.abs(dphi_dz) * np.abs(dz_dv)


def _term_gradients(c: dict, x, v, I, F) -> tuple:
    """Bounds per run of the term set's gradients for the step sizes: (|d/dx| [N/m] and |d/dv| [N.s/m] of the
    force terms, |d/dI| [Ohm] of the coil terms), by central differences of the basis functions
    (``fmu_src.terms``) at the largest displacement x [m], speed v [m/s], current I [A] and force F [N] the
    run reaches (and at rest: v = 0, where a smooth sign is steepest), a lag state at its input's value there,
    summed as absolute values over the terms."""
    k = {"x": 0.0, "v": 0.0, "I": 0.0}
    Rc = c["R"]
    for t in TERMS.values():
        coef = np.abs(c[t.coef.name])
        if t.equation not in ("force", "coil") or not np.any(coef):
            continue
        z = LAGS[t.lag].input(x, v, I, F, Rc) if t.lag else 0.0
        for var in (("x", "v") if t.equation == "force" else ("I",)):
            steepest = 0.0
            for args in ({"x": x, "v": v, "I": I}, {"x": x, "v": 0.0 * v, "I": I}):
                h = 1e-6 * np.maximum(np.abs(args[var]), 1e-6)
                lo, hi = dict(args), dict(args)
                lo[var], hi[var] = args[var] - h, args[var] + h
                d = (t.function(hi["x"], hi["v"], hi["I"], F, z) - t.function(lo["x"], lo["v"], lo["I"], F, z)) / (2 * h)
                steepest = np.maximum(steepest, np.abs(d))
            k[var] = k[var] + coef * steepest
        if t.equation == "force" and t.lag is not None and LAGS[t.lag].first_order:
            # a term of a lagged input (z - F): its direct part moves with the force's gradient k_mag
            k["x"] = k["x"] + coef * F * 3.0 / np.maximum(c["a"], 1e-9)
        elif t.equation == "force" and t.lag is not None:
            k["x"] = k["x"] + _presliding_stiffness(t, coef, c)
    return k["x"], k["v"], k["I"]


def substeps(c: dict, dt: float) -> np.ndarray:
    """RK4 sub-steps per sample period dt [s] per run (a power of two, at most 64)."""
    om, dp, rl, itau = _rates(c)
    n = len(c["R"])
    fast_r = np.nan_to_num(np.maximum.reduce([om / 0.5, dp / 1.5, rl / 0.5, itau / 0.3,
                                              np.full(n, 1.0 / dt)]), nan=1e9, posinf=1e9)
    return np.minimum(64, 2 ** np.ceil(np.log2(np.maximum(1.0, fast_r * dt)))).astype(int)


def coarse_rate(c: dict) -> np.ndarray:
    """Per run, the largest rate [1/s] its coarse steps of the quasi-static remainder must resolve (stability of
    the decayed fast modes: omega/2.4, (C/m)/2.4, (R/L)/2; accuracy of the slow states: 1/(0.3 tau); a lag with its
    own rate sizes its steps in the core). Per run,
    not per batch: a run's steps, and so its result, must not depend on the other runs of its batch."""
    om, dp, rl, itau = (np.broadcast_to(np.asarray(v, dtype=float), (c["blocked"].size,)) for v in _rates(c))
    return np.maximum.reduce([om / 2.4, dp / 2.4, rl / 2.0, itau / 0.3, np.full(om.shape, 1e-9)])
