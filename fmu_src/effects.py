"""Catalogue of candidate effects that the paper's model leaves out, as optional model extensions.

Every effect has few parameters, all 0 (= off) by default. With every effect off
the plain 3-state ``fmu_src.model.Dynamics`` runs (results bit-identical to the
paper's model, same speed); when any effect is on, ``EffectDynamics`` runs, the
same model plus the effect terms and the extra states they need, integrated by
the same DP5 integrator with the same contact/release events.

=====================  ===================  ==============================================================
effect                 parameters           physics (x toward the coil, r = r0 - x, I coil current)
=====================  ===================  ==============================================================
coil_heating           Rth [K/W],           winding temperature rise dT (state):
                       tau_th [s]           R(T) = R*(1 + alpha*dT), alpha = 0.0039 1/K (copper),
                                            dT' = (Rth*I^2*R(T) - dT)/tau_th; the coil is V = R(T)*I + L*I'.
                                            The current droops during long holds, the displacement with it.
filler_saturation      ksat [1/T^2]         ksat = 1/B_sat^2: F = Em*I^2*G(r) / (1 + ksat*(kB*I)^2);
                                            the force grows more slowly than I^2 at high field.
viscoelastic_creep     Kc [N/m],            standard linear solid: a Maxwell branch (spring Kc in series
                       tau_c [s]            with a dashpot, time constant tau_c) beside the diaphragm
                                            spring; dashpot position xc (state), branch force Kc*(x - xc),
                                            xc' = (x - xc)/tau_c. Instantaneous stiffness K + Kc relaxing
                                            to K: under a held force x creeps toward the coil, and after
                                            switch-off recovers slowly.
edge_stiffening        K5 [N/m^5]           extra stiffening at large deflection: spring force += K5*x^5.
motional_emf           lam [-]              L(x) = L*(1 + lam*(a^2/(a^2 + r^2))^(3/2)); the coil obeys
                                            d(L(x)*I)/dt = V - R*I, i.e. L(x)*I' = V - R*I - I*dL/dx*v:
                                            motion induces a back-EMF seen in the current. (L is then the
                                            inductance without the diaphragm; at rest L(x) > L.)
sensor_lag             tau_s [s]            first-order lag of the displacement and force sensors:
                                            x_sensor' = (x - x_sensor)/tau_s, F_sensor' = (F - F_sensor)/tau_s
                                            (outputs x_sensor, F_sensor; equal to x and F when off).
=====================  ===================  ==============================================================

Rules: tau_th > 0 when Rth > 0, tau_c > 0 when Kc > 0 (checked by ``fmu_src.params.validate``).
A time constant alone does not switch an effect on.

The net contact force (on the coil face, x = r0) includes every force term:
Em*I^2*G(0)*s(I) - (K1*r0^2 + K2)*r0 - K5*r0^5 - Kc*(r0 - xc), with s the
saturation factor; while in contact (and in blocked mode) the thermal, creep
and sensor states keep evolving.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .diaphragm import acceleration
from .model import BLOCKED, CONTACT, FREE, Dynamics
from .params import SPECS, EFFECT_FIELDS, Params, ParamSpec

ALPHA_CU = 0.0039   # temperature coefficient of the resistance of copper [1/K]
DT_STABILITY_K = 200.0  # temperature rise [K] the stability step bound of coil_heating allows for


def _spec(name, unit, description):
    return ParamSpec(name, unit, 0.0, description, positive=False, nonnegative=True)


# Order matters: it is the order of the FMU's effect parameters and of the Params fields after "blocked".
EFFECT_SPECS: tuple[ParamSpec, ...] = (
    _spec("Rth", "K/W", "coil_heating: thermal resistance of the winding to ambient; dT' = (Rth*I^2*R*(1 + "
                        "0.0039*dT) - dT)/tau_th, coil resistance R*(1 + 0.0039*dT) (0 = off)"),
    _spec("tau_th", "s", "coil_heating: thermal time constant of the winding (must be > 0 when Rth > 0)"),
    _spec("ksat", "1/T2", "filler_saturation: 1/B_sat^2; force Em*I^2*G(r0 - x)/(1 + ksat*(kB*I)^2) (0 = off)"),
    _spec("Kc", "N/m", "viscoelastic_creep: spring of the Maxwell branch (spring in series with a dashpot) beside "
                       "the diaphragm spring; branch force Kc*(x - xc), xc' = (x - xc)/tau_c (0 = off)"),
    _spec("tau_c", "s", "viscoelastic_creep: relaxation time of the Maxwell branch (must be > 0 when Kc > 0)"),
    _spec("K5", "N/m5", "edge_stiffening: quintic spring coefficient, spring force += K5*x^5 (0 = off)"),
    _spec("lam", "1", "motional_emf: inductance L(x) = L*(1 + lam*(a^2/(a^2 + (r0 - x)^2))^(3/2)); "
                      "L(x)*I' = V - R*I - I*v*dL/dx (0 = off)"),
    _spec("tau_s", "s", "sensor_lag: first-order time constant of the displacement and force sensors "
                        "(outputs x_sensor, F_sensor) (0 = off)"),
)
EFFECT_SPEC_BY_NAME = {s.name: s for s in EFFECT_SPECS}
ALL_SPECS = SPECS + EFFECT_SPECS


@dataclass(frozen=True)
class Effect:
    name: str
    switch: str              # the parameter that turns the effect on (> 0)
    params: tuple            # all its parameters (names in EFFECT_SPECS)
    states: tuple            # extra states it adds
    summary: str
    signals: str             # where it shows in the rig's tests


EFFECTS: dict[str, Effect] = {e.name: e for e in (
    Effect("coil_heating", "Rth", ("Rth", "tau_th"), ("dT",),
           "coil resistance rises with the winding temperature, R(T) = R*(1 + 0.0039*dT)",
           "current droops during the steady part of the step tests T2-T5 and T8 (largest at T5/T8, "
           "0.23 T); displacement/force droop with it"),
    Effect("filler_saturation", "ksat", ("ksat",), (),
           "magnetization of the filler saturates: F = Em*I^2*G/(1 + (kB*I/B_sat)^2)",
           "steady displacement of T2..T5 grows more slowly than I^2; blocked force T7/T8 lower at 0.23 T "
           "relative to a model fitted at low field"),
    Effect("viscoelastic_creep", "Kc", ("Kc", "tau_c"), ("xc",),
           "viscoelastic matrix: standard linear solid (Maxwell branch Kc, tau_c beside the spring)",
           "T2-T5 displacement keeps rising after the step while the current is steady; T1 sweep values "
           "depend on the hold time"),
    Effect("edge_stiffening", "K5", ("K5",), (),
           "in-plane tension at large deflection: spring force += K5*x^5",
           "T1 displacement at small gaps (large deflection) below the model; T5 steady value lower"),
    Effect("motional_emf", "lam", ("lam",), (),
           "the diaphragm changes the coil's inductance: back-EMF I*v*dL/dx and a gap-dependent L",
           "current dip while the diaphragm moves after the step (T2-T6); slower current rise at small gaps"),
    Effect("sensor_lag", "tau_s", ("tau_s",), ("x_sensor", "F_sensor"),
           "first-order lag of the laser displacement sensor and the force transducer",
           "delay of the measured displacement/force in the step rise (T2-T5, T8) and phase lag in T6; "
           "the current is not affected"),
)}


def check_effect_rules(values: dict) -> None:
    """Rules between effect parameters (called by ``fmu_src.params.validate``)."""
    for strength, tau, effect in (("Rth", "tau_th", "coil_heating"), ("Kc", "tau_c", "viscoelastic_creep")):
        if strength in values and float(values[strength]) > 0.0 and not float(values.get(tau, 0.0)) > 0.0:
            raise ValueError(f"parameter {tau} [s] must be > 0 when {strength} > 0 ({effect} on), "
                             f"got {values.get(tau, 0.0)!r}")


def active_effects(p: Params) -> tuple:
    """Names of the effects switched on in p (in catalogue order)."""
    return tuple(name for name, e in EFFECTS.items() if getattr(p, e.switch) != 0.0)


def effect_values(p: Params) -> dict:
    """The effect parameters of p {name: value}."""
    return {s.name: getattr(p, s.name) for s in EFFECT_SPECS}


def dynamics_class(p: Params):
    """The plain ``Dynamics`` when every effect is off, else ``EffectDynamics``."""
    return EffectDynamics if active_effects(p) else Dynamics


# --------------------------------------------------------------------------------- physics
def resistance(R: float, dT: float) -> float:
    """Coil resistance [Ohm] at a winding temperature rise dT [K]: R*(1 + 0.0039*dT)."""
    return R * (1.0 + ALPHA_CU * dT)


def saturation_factor(ksat: float, kB: float, I: float) -> float:
    """Force reduction 1/(1 + ksat*(kB*I)^2) [-] of filler_saturation (kB*I is the field at the coil face)."""
    b = kB * I
    return 1.0 / (1.0 + ksat * b * b)


def inductance(L: float, lam: float, a: float, r: float) -> float:
    """L(x) [H] = L*(1 + lam*(a^2/(a^2 + r^2))^(3/2)) at distance r = r0 - x [m]."""
    return L * (1.0 + lam * a ** 3 / (a * a + r * r) ** 1.5)


def inductance_gradient(L: float, lam: float, a: float, r: float) -> float:
    """dL/dx [H/m] = 3*L*lam*a^3*r/(a^2 + r^2)^(5/2) (dr/dx = -1)."""
    return 3.0 * L * lam * a ** 3 * r / (a * a + r * r) ** 2.5


class EffectDynamics(Dynamics):
    """The paper's model plus the effects switched on in the parameters.

    State y = [I, x, v] followed by, for the effects that are on and in this order,
    dT [K] (coil_heating), xc [m] (viscoelastic_creep), x_sensor [m] and F_sensor [N]
    (sensor_lag).
    """

    handles_effects = True

    def __init__(self, p: Params):
        p = p.validated()
        on = active_effects(p)
        self.on = on
        self.heat = "coil_heating" in on
        self.sat = "filler_saturation" in on
        self.creep = "viscoelastic_creep" in on
        self.edge = "edge_stiffening" in on
        self.emf = "motional_emf" in on
        self.lag = "sensor_lag" in on
        names = ["I", "x", "v"]
        if self.heat:
            names.append("dT")
        if self.creep:
            names.append("xc")
        if self.lag:
            names += ["x_sensor", "F_sensor"]
        self.state_names = tuple(names)
        self.n_states = len(names)
        idx = {n: i for i, n in enumerate(names)}
        self.iT, self.ixc = idx.get("dT"), idx.get("xc")
        self.ixs, self.iFs = idx.get("x_sensor"), idx.get("F_sensor")
        super().__init__(p)

    def stability_step(self) -> float:
        p = self.p
        rates = [p.R * (1.0 + ALPHA_CU * DT_STABILITY_K if self.heat else 1.0) / p.L]  # L(x) >= L
        if self.heat:
            rates.append(1.0 / p.tau_th)
        if self.creep:
            rates.append(1.0 / p.tau_c)
        if self.lag:
            rates.append(1.0 / p.tau_s)
        if not p.blocked:
            r0 = p.r0
            k_t = 3.0 * p.K1 * r0 * r0 + p.K2 + 5.0 * p.K5 * r0 ** 4 + p.Kc
            rates += [math.sqrt(k_t / p.m), p.C / p.m]
        return 2.5 / max(rates)

    def initial_state(self) -> list:
        return [0.0] * self.n_states

    def scales(self) -> list:
        sc = super().scales()
        sx = sc[1]
        if self.heat:
            sc.append(1.0)       # K
        if self.creep:
            sc.append(sx)
        if self.lag:
            sc += [sx, 1e-3]     # m, N
        return sc

    def magnetic_force(self, y, r: float) -> float:
        p = self.p
        I = y[0]
        F = p.Em * I * I * self.G(r)
        if self.sat:
            b = p.kB * I
            F /= 1.0 + p.ksat * b * b
        return F

    def net_contact_force(self, y) -> float:
        p = self.p
        r0 = p.r0
        spring = (p.K1 * r0 * r0 + p.K2) * r0 + p.K5 * r0 ** 5
        if self.creep:
            spring += p.Kc * (r0 - y[self.ixc])
        return self.magnetic_force(y, 0.0) - spring

    def sensors(self, y, mode: int, F: float):
        if self.lag:
            return y[self.ixs], y[self.iFs]
        return y[1], F

    def _make_rhs(self):
        p, G = self.p, self.G
        R, L, invL, Em, r0, K1, K2, C, m = p.R, p.L, 1.0 / p.L, p.Em, p.r0, p.K1, p.K2, p.C, p.m
        a, kB = p.a, p.kB
        a2, a3 = a * a, a ** 3
        heat, sat, creep, edge, emf, lag = self.heat, self.sat, self.creep, self.edge, self.emf, self.lag
        iT, ixc, ixs, iFs = self.iT, self.ixc, self.ixs, self.iFs
        alpha, Rth = ALPHA_CU, p.Rth
        inv_tth = 1.0 / p.tau_th if heat else 0.0
        ksat_kB2 = p.ksat * kB * kB
        Kc = p.Kc
        inv_tc = 1.0 / p.tau_c if creep else 0.0
        K5 = p.K5
        lamL, lam3L = p.lam * L, 3.0 * p.lam * L * a3
        inv_ts = 1.0 / p.tau_s if lag else 0.0

        def rhs(y, V, mode):
            I = y[0]
            if mode == FREE:
                x, v = y[1], y[2]
            elif mode == CONTACT:
                x, v = r0, 0.0
            else:
                x, v = 0.0, 0.0
            r = r0 - x
            Rc = R * (1.0 + alpha * y[iT]) if heat else R
            if emf:
                q = a2 + r * r
                dI = (V - Rc * I - I * v * lam3L * r / q ** 2.5) / (L + lamL * a3 / q ** 1.5)
            else:
                dI = (V - Rc * I) * invL
            if mode == FREE or lag:
                F = Em * I * I * G(r)
                if sat:
                    F /= 1.0 + ksat_kB2 * I * I
            if mode == FREE:
                Fn = F
                if edge:
                    x2 = x * x
                    Fn -= K5 * x2 * x2 * x
                if creep:
                    Fn -= Kc * (x - y[ixc])
                out = [dI, v, acceleration(x, v, Fn, K1, K2, C, m)]
            else:
                out = [dI, 0.0, 0.0]
            if heat:
                out.append((Rth * I * I * Rc - y[iT]) * inv_tth)
            if creep:
                out.append((x - y[ixc]) * inv_tc)
            if lag:
                out.append((x - y[ixs]) * inv_ts)
                out.append((F - y[iFs]) * inv_ts)
            return out
        return rhs


assert EFFECT_FIELDS == tuple(s.name for s in EFFECT_SPECS), (EFFECT_FIELDS, EFFECT_SPECS)
assert all(getattr(Params, s.name) == s.default == 0.0 for s in EFFECT_SPECS)
assert {n for e in EFFECTS.values() for n in e.params} == set(EFFECT_SPEC_BY_NAME)
