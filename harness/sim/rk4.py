"""Vectorized RK4 simulator of the diagnosis: hundreds of runs (samples x tests x gaps x parameter sets)
at once, every effect, the physics from ``fmu_src.effects`` (moved out of ``harness.analysis.diagnose``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fmu_src import effects as fx
from fmu_src.field import kernel_value, make_kernel

# ============================================================================ kernel tables
_KERNELS: dict = {}


def kernel(a: float, D: float, kB: float, r0: float):
    """``make_kernel(a, D, kB, r0)``, cached per process (the same table the exact model builds)."""
    key = (float(a), float(D), float(kB), float(r0))
    k = _KERNELS.get(key)
    if k is None:
        if len(_KERNELS) > 4000:
            _KERNELS.clear()
        k = make_kernel(*key)
        _KERNELS[key] = k
    return k


class KernelTable:
    """Spline coefficients of several force kernels stacked in one array (rows c3, c2, c1, c0)."""

    def __init__(self, kernels):
        uniq, index = [], {}
        for k in kernels:
            if id(k) not in index:
                index[id(k)] = len(uniq)
                uniq.append(k)
        offs = np.cumsum([0] + [k._nseg for k in uniq])[:-1]
        # rows c3, c2, c1, c0 of the cubic pieces (ForceKernel's spline), one column per segment
        self.coef = np.ascontiguousarray(np.hstack([k._c for k in uniq]))   # (4, total segments)
        ki = np.array([index[id(k)] for k in kernels], dtype=np.intp)
        self.off = offs[ki].astype(np.intp)
        self.dr = np.array([uniq[i]._dr for i in ki])
        self.inv_dr = 1.0 / self.dr
        self.smax = np.array([uniq[i]._nseg - 1 for i in ki], dtype=float)
        self.G0 = np.array([uniq[i].G0 for i in ki])
        self.dG0 = np.array([uniq[i].dG0 for i in ki])

    def subset(self, idx) -> "KernelTable":
        out = object.__new__(KernelTable)
        out.coef = self.coef
        for k in ("off", "dr", "inv_dr", "smax", "G0", "dG0"):
            setattr(out, k, getattr(self, k)[idx])
        return out

    def __call__(self, r):
        """G(r) [T^2/(A^2.m)] per row (linear continuation below r = 0, as ForceKernel): the kernel's one
        evaluation function, ``fmu_src.field.kernel_value``, with one table per row."""
        return kernel_value(r, self.coef, self.off, self.smax, self.dr, self.inv_dr, self.G0, self.dG0)


# ============================================================================ batched simulator
COARSE_OUT = 4          # output spacing [samples] of the coarse part of a step schedule
PARAM_FIELDS = ("a", "r0", "D", "kB", "R", "L", "Em", "K1", "K2", "C", "m",
                "Rth", "tau_th", "ksat", "Kc", "tau_c", "K5", "lam", "tau_s")


@dataclass
class _Sim:
    """Outputs of a batched simulation on its output grid (local time from the input onset)."""
    t: np.ndarray          # (n_out,) local times [s]
    I: np.ndarray          # (N, n_out) current [A]
    y: np.ndarray          # (N, n_out) sensor reading: x_sensor [m] (free) or F_sensor [N] (blocked)


def simulate_batch(P: dict, blocked, V, dt: float = 1e-3, t_end: float = 2.8, fine_s: float | None = 0.5,
                   tol_y=None, tol_I: float = 1e-7) -> _Sim:
    """Integrate N runs of the (effect) model at once: classic RK4 on a shared step schedule.

    P: {field: (N,) array} with every name of ``PARAM_FIELDS`` (SI, 0 = effect off);
    blocked: (N,) bool; V: (N,) constant voltage [V] switched on at local time 0, or (N, n)
    voltages held over the intervals [k dt, (k+1) dt) (zero-order hold). Every run starts at
    rest at local time 0. The physics of ``fmu_src.effects.EffectDynamics``, from the same core
    functions of ``fmu_src.effects`` (contact: perfectly
    inelastic impact on the coil face, release when the net force changes sign; the sensor lag is
    integrated exactly for a piecewise-linear input). Step size dt/n_sub, n_sub (a power of two)
    from the stiffest run; runs that need a different n_sub are integrated in their own batch.
    With a constant V: runs without slow states (coil heating, creep) whose outputs have stopped
    changing (by less than tol_y [m or N] and tol_I [A] over 50 ms) are frozen; after ``fine_s``
    seconds the remaining runs step by COARSE_OUT*dt/per with per = 1, 2, 4, ... (RK4 stability for
    the decayed fast modes, accuracy for the slow states). Outputs: every dt while stepping finely,
    then every COARSE_OUT*dt: a grid that depends only on dt, t_end and fine_s, never on the
    parameters (so residual vectors keep their length during a fit).
    """
    with np.errstate(all="ignore"):
        return _simulate_batch(P, blocked, V, dt, t_end, fine_s, tol_y, tol_I)


def _simulate_batch(P, blocked, V, dt, t_end, fine_s, tol_y, tol_I):
    N = int(np.asarray(blocked).size)
    f = {k: np.asarray(P[k], dtype=float) for k in PARAM_FIELDS}
    blocked = np.asarray(blocked, dtype=bool)
    V = np.asarray(V, dtype=float)
    const_v = V.ndim == 1
    kt_full = KernelTable([kernel(a, D, kB, g) for a, D, kB, g in zip(f["a"], f["D"], f["kB"], f["r0"])])
    if tol_y is None:
        tol_y = np.where(blocked, 1e-7, 1e-10)
    tol_y = np.broadcast_to(np.asarray(tol_y, dtype=float), (N,))
    c_full = dict(f)
    c_full["blocked"] = blocked
    c_full["V"] = V
    c_full["tol_y"] = tol_y
    c_full["slow"] = (f["Rth"] > 0) | (f["Kc"] > 0)
    flags = tuple(bool(np.any(f[k] > 0)) for k in ("Rth", "ksat", "Kc", "K5", "lam", "tau_s"))

    def rates(c):
        free0 = ~c["blocked"]
        Vm = np.abs(c["V"]).max(axis=-1) if c["V"].ndim > 1 else np.abs(c["V"])
        F0 = fx.magnetic_force(c["Em"], Vm / c["R"], c["kt"].G0)   # largest magnetic force (at the coil face)
        r0 = c["r0"]
        reach = F0 >= fx.restoring_force(r0, c["K1"], c["K2"], c["K5"])   # may be pulled in
        # deflection bound: the gap if pull-in is possible, else twice the static deflection under F0
        x_hi = np.where(c["blocked"], 0.0, np.where(reach, r0, np.minimum(r0, 2.0 * F0 / c["K2"])))
        k_t = fx.tangent_stiffness(x_hi, c["K1"], c["K2"], c["K5"], c["Kc"])
        k_mag = F0 * 3.0 / np.maximum(c["a"], 1e-9)       # bound on the magnetic force's gradient
        omega = np.where(free0, np.sqrt((k_t + k_mag) / c["m"]), 0.0)
        damp = np.where(free0, c["C"] / c["m"], 0.0)
        inv_tc = 1.0 / _effect_tau(c["Kc"], c["tau_c"])
        inv_tth = 1.0 / _effect_tau(c["Rth"], c["tau_th"])
        return omega, damp, c["R"] / c["L"], inv_tc, inv_tth

    c_full["kt"] = kt_full
    om, dp, rl, itc, itth = rates(c_full)
    fast_r = np.nan_to_num(np.maximum.reduce([om / 0.5, dp / 1.5, rl / 0.5, itc / 0.3, itth / 0.3,
                                              np.full(N, 1.0 / dt)]), nan=1e9, posinf=1e9)
    need = np.minimum(64, 2 ** np.ceil(np.log2(np.maximum(1.0, fast_r * dt)))).astype(int)
    if N > 1 and np.unique(need).size > 1:
        # runs that need finer steps are integrated apart, so they do not slow the others down
        parts = [(np.flatnonzero(need == k), k) for k in np.unique(need)]
        sims = [(idx, _simulate_batch({k: f[k][idx] for k in PARAM_FIELDS}, blocked[idx], V[idx], dt, t_end,
                                      fine_s, tol_y[idx], tol_I)) for idx, _ in parts]
        t_out = sims[0][1].t
        I_out = np.empty((N, t_out.size))
        y_out = np.empty((N, t_out.size))
        for idx, sm in sims:
            I_out[idx] = sm.I
            y_out[idx] = sm.y
        return _Sim(t=t_out, I=I_out, y=y_out)
    n_sub = int(need.max())
    h = dt / n_sub
    if const_v:
        n_all = int(round(t_end / dt))
        n_fine = min(n_all, int(round((fine_s if fine_s is not None else t_end) / dt)))
        n_coarse = (n_all - n_fine) // COARSE_OUT
        tail = n_all - n_fine - n_coarse * COARSE_OUT
        sched = [("fine", n_fine), ("coarse", n_coarse), ("tail", tail)]
    else:
        sched = [("fine", V.shape[1])]
    n_out = 1 + sched[0][1] + (sched[1][1] + sched[2][1] if const_v else 0)
    t_out = np.zeros(n_out)
    I_out = np.zeros((N, n_out))
    y_out = np.zeros((N, n_out))
    last = np.zeros(N, dtype=np.intp)

    def subset(c, idx):
        out = {}
        for k, v in c.items():
            if k == "kt":
                out[k] = v.subset(idx)
            elif isinstance(v, np.ndarray) and v.shape[:1] == (len(c["R"]),):
                out[k] = v[idx]
            else:
                out[k] = v
        return out

    act = np.arange(N)
    c = c_full
    S = {k: np.zeros(N) for k in ("I", "x", "v", "dT", "xc", "xs", "Fs")}
    S["fm"] = (~blocked).astype(float)
    S["contact"] = np.zeros(N, dtype=bool)
    col = 1
    t = 0.0
    chk_y = np.zeros(N)
    chk_I = np.zeros(N)
    for kind, n_int in sched:
        if n_int <= 0 or act.size == 0:
            if kind != "fine" and const_v:
                t_out[col:col + n_int] = t + dt * (np.arange(1, n_int + 1) * (COARSE_OUT if kind == "coarse" else 1))
                t += dt * n_int * (COARSE_OUT if kind == "coarse" else 1)
                col += n_int
            continue
        if kind == "fine":
            hh, per, every_int = h, n_sub, 1
        else:
            # quasi-static remainder: the fast modes have decayed; RK4 stays stable for them while
            # max(omega, C/m) * h <= 2.4 (its stability region reaches 2.6-2.8) and follows the slow
            # states (heating, creep) closely
            every_int = COARSE_OUT if kind == "coarse" else 1
            om, dp, rl, itc, itth = rates(c)
            slow = max(np.max(om / 2.4, initial=0), np.max(dp / 2.4, initial=0), np.max(rl / 2.0, initial=0),
                       np.max(itc / 0.3, initial=0), np.max(itth / 0.3, initial=0), 1e-9)
            per = 1
            while per < 256 and not (every_int * dt / per * slow <= 1.0):
                per *= 2
            hh = every_int * dt / per
        step = _make_stepper(c, flags, hh)
        for k in range(n_int):
            Vk = c["V"] if const_v else c["V"][:, k]
            for _ in range(per):
                step(S, Vk)
            t += dt * every_int
            y_now = np.where(c["blocked"], S["Fs"], S["xs"]) if flags[5] else \
                np.where(c["blocked"], S["F"], S["x"])
            y_out[act, col] = y_now
            I_out[act, col] = S["I"]
            t_out[col] = t
            last[act] = col
            col += 1
            if const_v and kind == "fine" and col % 50 == 1 and t > 0.1:
                done = (~c["slow"] & (np.abs(y_now - chk_y) <= c["tol_y"]) & (np.abs(S["I"] - chk_I) <= tol_I)
                        & (np.abs(S["v"]) * 0.05 <= c["tol_y"]))
                chk_y, chk_I = y_now, S["I"].copy()
                if done.any():
                    keep = ~done
                    act = act[keep]
                    c = subset(c, keep)
                    S = {kk: vv[keep] for kk, vv in S.items()}
                    chk_y, chk_I = chk_y[keep], chk_I[keep]
                    if act.size == 0:
                        break
                    step = _make_stepper(c, flags, hh)
        if act.size == 0 and col < n_out:
            # every run frozen: the remaining output times
            rest = []
            for kind2, n2 in sched[[s[0] for s in sched].index(kind) + 1:] if kind == "fine" else []:
                rest += [COARSE_OUT if kind2 == "coarse" else 1] * n2
            if kind == "fine":
                rest = [1] * (sched[0][1] - (col - 1)) + rest
            tt = t + dt * np.cumsum(rest)
            t_out[col:col + len(tt)] = tt
            col += len(tt)
            break
    # frozen runs keep their last outputs
    for r in np.flatnonzero(last < col - 1):
        y_out[r, last[r] + 1:col] = y_out[r, last[r]]
        I_out[r, last[r] + 1:col] = I_out[r, last[r]]
    return _Sim(t=t_out[:col], I=I_out[:, :col], y=y_out[:, :col])


def _effect_args(c, flags) -> dict:
    """Effect parameters of the runs in c as the core functions (``fmu_src.effects``) take them:
    (N,) arrays, None for an effect that is off in every run (its terms are then skipped)."""
    heat, sat, creep, edge, emf, lag = flags
    return {"ksat": c["ksat"] if sat else None, "K5": c["K5"] if edge else None,
            "Kc": c["Kc"] if creep else None, "lam": c["lam"] if emf else None}


def _effect_tau(strength, tau):
    """Time constant [s] per run of an effect's state for the rate functions: tau where the effect is
    on (strength > 0; 1 s should tau be missing), inf where it is off (rate 0: its state stays 0)."""
    return np.where(strength > 0, np.where(tau > 0, tau, 1.0), np.inf)


def _batch_rhs(c, flags):
    """Right-hand side of the runs in c, free mode, every formula from ``fmu_src.effects``.

    rhs(I, x, v, dT, xc, Vk, fm) -> (I', x', v', dT', xc', F) with (N,) arrays (SI units; dT' and xc'
    are 0.0 when coil heating / creep are off in every run); fm is 1.0 for a moving diaphragm and 0.0
    for a held one (blocked or in contact: x' = v' = 0). F is the magnetic force [N].
    """
    heat, sat, creep, edge, emf, lag = flags
    e = _effect_args(c, flags)
    ksat, K5, Kc, lam = e["ksat"], e["K5"], e["Kc"], e["lam"]
    kt = c["kt"]
    r0, R, L, Em, K1, K2, C, m, a, kB = (c[k] for k in ("r0", "R", "L", "Em", "K1", "K2", "C", "m", "a", "kB"))
    Rth = c["Rth"]
    tau_th = _effect_tau(Rth, c["tau_th"]) if heat else None
    tau_c = _effect_tau(c["Kc"], c["tau_c"]) if creep else None
    f_res, f_dI, f_F, f_acc = fx.resistance, fx.current_rate, fx.magnetic_force, fx.diaphragm_acceleration
    f_th, f_cr = fx.thermal_rate, fx.creep_rate

    def rhs(I, x, v, dT, xc, Vk, fm):
        r = r0 - x
        F = f_F(Em, I, kt(r), ksat, kB)
        Rc = f_res(R, dT) if heat else R
        dI = f_dI(Vk, I, Rc, L, lam, a, r, v)
        acc = f_acc(x, v, F, K1, K2, C, m, K5, Kc, xc) * fm
        ddT = f_th(dT, I, Rc, Rth, tau_th) if heat else 0.0
        dxc = f_cr(x, xc, tau_c) if creep else 0.0
        return dI, v * fm, acc, ddT, dxc, F
    return rhs


def _batch_forces(c, flags):
    """(force(I, x), net_contact(I, xc)) of the runs in c, from ``fmu_src.effects``: the magnetic force [N]
    at displacement x [m], and the net force [N] toward the coil on the coil face (x = r0; dashpot at xc [m])."""
    kt = c["kt"]
    r0, Em, K1, K2, kB = c["r0"], c["Em"], c["K1"], c["K2"], c["kB"]
    e = _effect_args(c, flags)
    ksat, K5, Kc = e["ksat"], e["K5"], e["Kc"]
    f_F, f_net = fx.magnetic_force, fx.net_contact_force

    def force(I, x):
        return f_F(Em, I, kt(r0 - x), ksat, kB)

    def net_contact(I, xc):
        return f_net(f_F(Em, I, kt.G0, ksat, kB), r0, K1, K2, K5, Kc, xc)
    return force, net_contact


def _make_stepper(c, flags, hh):
    """One RK4 step of size hh [s] for the runs in c (updates the state dict S in place).

    The physics (right-hand side, magnetic and net contact force) is ``fmu_src.effects``'s; here: the
    RK4 stages, the contact logic (perfectly inelastic impact on the coil face, release when the net
    contact force turns negative) and the exact update of the sensor lag for a piecewise-linear input.
    """
    heat, sat, creep, edge, emf, lag = flags
    r0 = c["r0"]
    rhs = _batch_rhs(c, flags)
    force, net_contact = _batch_forces(c, flags)
    tau_s = c["tau_s"]
    if lag:
        # y_s' = (u - y_s)/tau_s (fx.sensor_rate) solved exactly over a step for u linear in time
        E = np.where(tau_s > 0, np.exp(-hh / np.where(tau_s > 0, tau_s, 1.0)), 0.0)
        cE = np.where(tau_s > 0, tau_s * (1.0 - E) / hh, 0.0)
    h2, h6 = 0.5 * hh, hh / 6.0

    def step(S, Vk):
        I, x, v, dT, xc, fm = S["I"], S["x"], S["v"], S["dT"], S["xc"], S["fm"]
        k1 = rhs(I, x, v, dT, xc, Vk, fm)
        k2 = rhs(I + h2 * k1[0], x + h2 * k1[1], v + h2 * k1[2], dT + h2 * k1[3], xc + h2 * k1[4], Vk, fm)
        k3 = rhs(I + h2 * k2[0], x + h2 * k2[1], v + h2 * k2[2], dT + h2 * k2[3], xc + h2 * k2[4], Vk, fm)
        k4 = rhs(I + hh * k3[0], x + hh * k3[1], v + hh * k3[2], dT + hh * k3[3], xc + hh * k3[4], Vk, fm)
        x_old, F_old = x, k1[5]
        I = I + h6 * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0])
        x = x + h6 * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1])
        v = v + h6 * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2])
        if heat:
            dT = dT + h6 * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3])
        if creep:
            xc = xc + h6 * (k1[4] + 2.0 * (k2[4] + k3[4]) + k4[4])
        contact = S["contact"]
        if contact.any():
            rel = contact & (net_contact(I, xc) < 0.0)
            if rel.any():
                contact = contact & ~rel
                fm = np.where(rel, 1.0, fm)
        hit = (fm > 0) & (x >= r0)
        if hit.any():
            x = np.where(hit, r0, x)
            v = np.where(hit, 0.0, v)
            stick = hit & (net_contact(I, xc) >= 0.0)
            if stick.any():
                contact = contact | stick
                fm = np.where(stick, 0.0, fm)
        F = force(I, x)
        if lag:
            S["xs"] = x + (S["xs"] - x_old) * E - (x - x_old) * cE
            S["Fs"] = F + (S["Fs"] - F_old) * E - (F - F_old) * cE
        S.update(I=I, x=x, v=v, dT=dT, xc=xc, fm=fm, contact=contact, F=F)

    return step
