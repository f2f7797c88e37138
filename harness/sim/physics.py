"""The physics of the vectorized simulator: per-run constants and the right-hand side, every formula a
call of an array function of ``fmu_src.effects`` (``current_rate``, ``magnetic_force``,
``diaphragm_acceleration``, ``net_contact_force``, ``thermal_rate``, ``creep_rate``, ``resistance``,
``restoring_force``, ``tangent_stiffness``; the sensor lag's ``sensor_rate`` is solved exactly in
:mod:`harness.sim.stepper`), the force kernel from :mod:`harness.sim.kernels`.

The constants of a batch are a dict ``c`` of (N,) arrays (the names of ``PARAM_FIELDS``, ``blocked``,
``V``, ``tol_y``, ``slow``), the stacked kernel table ``kt``, the effect flags ``flags`` (an effect on in
any run of the batch) and the input hold ``hold``. Units: SI.
"""
from __future__ import annotations

import numpy as np

from fmu_src import effects as fx

from .kernels import KernelTable, kernel

__all__ = ["PARAM_FIELDS", "FLAG_NAMES", "constants", "subset", "effect_args", "effect_tau", "rhs", "forces",
           "substeps", "coarse_rate", "readings", "reading", "settled"]

PARAM_FIELDS = ("a", "r0", "D", "kB", "R", "L", "Em", "K1", "K2", "C", "m",
                "Rth", "tau_th", "ksat", "Kc", "tau_c", "K5", "lam", "tau_s")
# the effect switches, in fmu_src.effects.EFFECTS order: heat, sat, creep, edge, emf, lag
FLAG_NAMES = ("Rth", "ksat", "Kc", "K5", "lam", "tau_s")


def constants(runs) -> dict:
    """The per-run constants of ``runs`` (a :class:`harness.sim.simulator.Runs`) as the stepper takes them."""
    f = {k: np.asarray(runs.params[k], dtype=float) for k in PARAM_FIELDS}
    N = runs.n
    blocked = np.asarray(runs.blocked, dtype=bool)
    c = dict(f)
    c["kt"] = KernelTable([kernel(a, D, kB, g) for a, D, kB, g in zip(f["a"], f["D"], f["kB"], f["r0"])])
    c["blocked"] = blocked
    c["V"] = np.asarray(runs.V, dtype=float)
    tol_y = runs.tol_y if runs.tol_y is not None else np.where(blocked, 1e-7, 1e-10)
    c["tol_y"] = np.broadcast_to(np.asarray(tol_y, dtype=float), (N,)).copy()
    c["slow"] = (f["Rth"] > 0) | (f["Kc"] > 0)
    c["flags"] = tuple(bool(np.any(f[k] > 0)) for k in FLAG_NAMES)
    c["hold"] = runs.hold
    return c


def subset(c: dict, idx) -> dict:
    """The runs idx (index or mask) of the constants c."""
    n = len(c["R"])
    out = {}
    for k, v in c.items():
        if k == "kt":
            out[k] = v.subset(idx)
        elif isinstance(v, np.ndarray) and v.shape[:1] == (n,):
            out[k] = v[idx]
        else:
            out[k] = v
    return out


def effect_args(c: dict) -> dict:
    """Effect parameters of the runs in c as ``fmu_src.effects`` takes them: (N,) arrays, None for an
    effect that is off in every run (its terms are then skipped)."""
    heat, sat, creep, edge, emf, lag = c["flags"]
    return {"ksat": c["ksat"] if sat else None, "K5": c["K5"] if edge else None,
            "Kc": c["Kc"] if creep else None, "lam": c["lam"] if emf else None}


def effect_tau(strength, tau):
    """Time constant [s] per run of an effect's state: tau where the effect is on (strength > 0; 1 s
    should tau be missing), inf where it is off (rate 0: its state stays 0)."""
    return np.where(strength > 0, np.where(tau > 0, tau, 1.0), np.inf)


def rhs(c: dict):
    """Right-hand side of the runs in c.

    Returns f(I, x, v, dT, xc, V, fm, F=None) -> (I', x', v', dT', xc', F) on (N,) arrays (SI; dT' and
    xc' are 0.0 when coil heating / creep are off in every run); fm is 1.0 for a moving diaphragm and 0.0
    for a held one (blocked or in contact: x' = v' = 0). F is the magnetic force [N] (computed unless
    given: the caller may pass the force it already has for this state).
    """
    heat, sat, creep, edge, emf, lag = c["flags"]
    e = effect_args(c)
    ksat, K5, Kc, lam = e["ksat"], e["K5"], e["Kc"], e["lam"]
    kt = c["kt"]
    r0, R, L, Em, K1, K2, C, m, a, kB = (c[k] for k in ("r0", "R", "L", "Em", "K1", "K2", "C", "m", "a", "kB"))
    Rth = c["Rth"]
    tau_th = effect_tau(Rth, c["tau_th"]) if heat else None
    tau_c = effect_tau(c["Kc"], c["tau_c"]) if creep else None
    f_res, f_dI, f_F, f_acc = fx.resistance, fx.current_rate, fx.magnetic_force, fx.diaphragm_acceleration
    f_spr = fx.effect_spring_force
    f_th, f_cr = fx.thermal_rate, fx.creep_rate

    def f(I, x, v, dT, xc, V, fm, F=None):
        r = r0 - x
        if F is None:
            F = f_F(Em, I, kt(r), ksat, kB)
        Rc = f_res(R, dT) if heat else R
        dI = f_dI(V, I, Rc, L, lam, a, r, v)
        acc = f_acc(x, v, F, K1, K2, C, m, None if K5 is None and Kc is None else f_spr(x, K5, Kc, xc)) * fm
        ddT = f_th(dT, I, Rc, Rth, tau_th) if heat else 0.0
        dxc = f_cr(x, xc, tau_c) if creep else 0.0
        return dI, v * fm, acc, ddT, dxc, F
    return f


def forces(c: dict):
    """(force(I, x), net_contact(I, xc)) of the runs in c: the magnetic force [N] at displacement x [m],
    and the net force [N] toward the coil on the coil face (x = r0; dashpot at xc [m])."""
    kt = c["kt"]
    r0, Em, K1, K2, kB = c["r0"], c["Em"], c["K1"], c["K2"], c["kB"]
    e = effect_args(c)
    ksat, K5, Kc = e["ksat"], e["K5"], e["Kc"]
    f_F, f_net = fx.magnetic_force, fx.net_contact_force

    def force(I, x):
        return f_F(Em, I, kt(r0 - x), ksat, kB)

    def net_contact(I, xc):
        return f_net(f_F(Em, I, kt.G0, ksat, kB), r0, K1, K2, K5, Kc, xc)
    return force, net_contact


def _rates(c: dict):
    """(omega, C/m, R/L, 1/tau_c, 1/tau_th) [1/s] per run: the fastest rates the run can reach."""
    free0 = ~c["blocked"]
    V = c["V"]
    Vm = np.abs(V).max(axis=-1) if V.ndim > 1 else np.abs(V)
    F0 = fx.magnetic_force(c["Em"], Vm / c["R"], c["kt"].G0)   # largest magnetic force (at the coil face)
    r0 = c["r0"]
    reach = F0 >= fx.restoring_force(r0, c["K1"], c["K2"], c["K5"])   # may be pulled in
    # deflection bound: the gap if pull-in is possible, else twice the static deflection under F0
    x_hi = np.where(c["blocked"], 0.0, np.where(reach, r0, np.minimum(r0, 2.0 * F0 / c["K2"])))
    k_t = fx.tangent_stiffness(x_hi, c["K1"], c["K2"], c["K5"], c["Kc"])
    k_mag = F0 * 3.0 / np.maximum(c["a"], 1e-9)       # bound on the magnetic force's gradient
    omega = np.where(free0, np.sqrt((k_t + k_mag) / c["m"]), 0.0)
    damp = np.where(free0, c["C"] / c["m"], 0.0)
    inv_tc = 1.0 / effect_tau(c["Kc"], c["tau_c"])
    inv_tth = 1.0 / effect_tau(c["Rth"], c["tau_th"])
    return omega, damp, c["R"] / c["L"], inv_tc, inv_tth


def substeps(c: dict, dt: float) -> np.ndarray:
    """RK4 sub-steps per sample period dt [s] per run (a power of two, at most 64)."""
    om, dp, rl, itc, itth = _rates(c)
    n = len(c["R"])
    fast_r = np.nan_to_num(np.maximum.reduce([om / 0.5, dp / 1.5, rl / 0.5, itc / 0.3, itth / 0.3,
                                              np.full(n, 1.0 / dt)]), nan=1e9, posinf=1e9)
    return np.minimum(64, 2 ** np.ceil(np.log2(np.maximum(1.0, fast_r * dt)))).astype(int)


def coarse_rate(c: dict) -> float:
    """Largest rate [1/s] the coarse steps of the quasi-static remainder must resolve (stability of the
    decayed fast modes: omega/2.4, (C/m)/2.4, (R/L)/2; accuracy of the slow states: 1/(0.3 tau))."""
    om, dp, rl, itc, itth = _rates(c)
    return max(np.max(om / 2.4, initial=0), np.max(dp / 2.4, initial=0), np.max(rl / 2.0, initial=0),
               np.max(itc / 0.3, initial=0), np.max(itth / 0.3, initial=0), 1e-9)


def readings(S: dict, c: dict) -> tuple:
    """(x_sensor [m], F_sensor [N]) per run (x and the magnetic force without sensor_lag)."""
    if c["flags"][5]:
        return S["xs"], S["Fs"]
    return S["x"], S["F"]


def reading(S: dict, c: dict) -> np.ndarray:
    """The reading of each run's test: F_sensor [N] (blocked) or x_sensor [m] (free)."""
    xs, Fs = readings(S, c)
    return np.where(c["blocked"], Fs, xs)


def settled(S: dict, c: dict, change, tol_I: float) -> np.ndarray:
    """Runs without slow states whose reading and current changed (change = (dy, dI) over the last
    check interval) by less than tol_y and tol_I, and whose velocity is small."""
    dy, dI = change
    return (~c["slow"] & (np.abs(dy) <= c["tol_y"]) & (np.abs(dI) <= tol_I)
            & (np.abs(S["v"]) * 0.05 <= c["tol_y"]))
