"""Catalogue of candidate effects that the paper's model leaves out, as optional model extensions.

Every effect has few parameters, all 0 (= off) by default. With every effect off
the plain 3-state ``fmu_src.model.Dynamics`` runs (the paper's model); when any effect is on, ``EffectDynamics`` runs, the
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

Physics core: the equations above are written once, as functions of this module that work on
Python floats and on numpy arrays alike (plain arithmetic, no branches on values; an effect whose
parameter is passed as None is off and costs nothing):

=========================  =====================================================================
``resistance``             R(T) = R*(1 + 0.0039*dT) [Ohm]
``inductance_terms``       (L(x) [H], dL/dx [H/m]) of motional_emf
``current_rate``           I' [A/s] from L(x)*I' = V - R(T)*I - I*v*dL/dx
``magnetic_force``         Em*I^2*G/(1 + ksat*(kB*I)^2) [N], G = G(r) passed in by value
``effect_spring_force``    K5*x^5 + Kc*(x - xc) [N] (the effects' share of the restoring force)
``restoring_force``        (K1*x^2 + K2)*x + effect_spring_force [N]
``diaphragm_acceleration`` x'' = (F - C*v - restoring_force)/m [m/s^2]
``net_contact_force``      F(G(0)) - restoring_force(r0) [N] on the coil face
``tangent_stiffness``      3*K1*x^2 + K2 + 5*K5*x^4 + Kc [N/m] (for step-size bounds)
``thermal_rate``           dT' [K/s];  ``creep_rate`` xc' [m/s];  ``sensor_rate`` lag of a reading
=========================  =====================================================================

The FMU's scalar DP5 integrator (``fmu_src.integrator``, numba-compiled; run by ``fmu_src.model.Dynamics``
and ``EffectDynamics`` through ``fmu_src.model.ActuatorModel``) calls them compiled (``register_jitable``:
numba compiles these same function objects) and the vectorized RK4 integrator of ``harness.analysis.diagnose``
(hundreds of runs at once) calls them uncompiled with arrays; the paper's terms come from
``fmu_src.diaphragm``. The plain model (all effects off) runs the same compiled right-hand side with
every effect switch off.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

# the core functions below stay plain Python (floats and numpy arrays); register_jitable lets the FMU's
# numba-compiled integrator (fmu_src.integrator) call the very same functions
from numba.extending import register_jitable

from .diaphragm import acceleration, spring_force
from .diaphragm import tangent_stiffness as tangent_stiffness_duffing
from .model import Dynamics
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


# --------------------------------------------------------------------------------- physics core
# (see the module docstring) floats or numpy arrays; u ** 0.5 is the square root for both. SI units:
# x displacement toward the coil [m], r = r0 - x distance to the coil face [m], I coil current [A].

@register_jitable
def resistance(R, dT):
    """Coil resistance R(T) [Ohm] at a winding temperature rise dT [K] (coil_heating):
    R*(1 + 0.0039*dT), R [Ohm] the cold resistance."""
    return R * (1.0 + ALPHA_CU * dT)


@register_jitable
def inductance_terms(L, lam, a, r):
    """(L(x) [H], dL/dx [H/m]) of motional_emf at the distance r [m] from the coil face.

    L(x) = L*(1 + lam*a^3/(a^2 + r^2)^(3/2)), dL/dx = 3*L*lam*a^3*r/(a^2 + r^2)^(5/2) (dr/dx = -1);
    L [H] the inductance without the diaphragm, lam [-], a [m] the coil (loop) radius.
    """
    a2 = a * a
    q = a2 + r * r
    Lq = lam * L * a2 * a / (q * q ** 0.5)      # L*lam*a^3/q^(3/2)
    return L + Lq, 3.0 * Lq * r / q


@register_jitable
def inductance(L, lam, a, r):
    """L(x) [H] = L*(1 + lam*a^3/(a^2 + r^2)^(3/2)) at distance r = r0 - x [m] (``inductance_terms``)."""
    return inductance_terms(L, lam, a, r)[0]


@register_jitable
def inductance_gradient(L, lam, a, r):
    """dL/dx [H/m] = 3*L*lam*a^3*r/(a^2 + r^2)^(5/2) at distance r = r0 - x [m] (``inductance_terms``)."""
    return inductance_terms(L, lam, a, r)[1]


@register_jitable
def current_rate(V, I, R, L, lam=None, a=None, r=None, v=None):
    """dI/dt [A/s] from the coil's voltage balance d(L(x)*I)/dt = V - R*I.

    V [V] coil voltage, I [A] current, R [Ohm] the resistance (``resistance(R, dT)`` with coil_heating),
    L [H] the inductance without the diaphragm. Without motional_emf (lam None): I' = (V - R*I)/L.
    With it (lam [-], a [m], r = r0 - x [m], v = x' [m/s]): L(x)*I' = V - R*I - I*v*dL/dx with L(x),
    dL/dx from ``inductance_terms``.
    """
    if lam is None:
        return (V - R * I) * (1.0 / L)
    Lx, dLdx = inductance_terms(L, lam, a, r)
    return (V - R * I - I * v * dLdx) / Lx


@register_jitable
def magnetic_force(Em, I, G, ksat=None, kB=None):
    """Magnetic force on the diaphragm [N], attraction positive: Em*I^2*G (paper Eq. 3).

    Em [N.m/T^2], I [A], G = G(r) [T^2/(A^2.m)] the force kernel's value at the distance r (the caller
    evaluates its kernel: ``ForceKernel`` or a table). With filler_saturation (ksat = 1/B_sat^2 [1/T^2],
    kB [T/A] the field per ampere at the coil face): Em*I^2*G/(1 + ksat*(kB*I)^2).
    """
    F = Em * I * I * G
    if ksat is None:
        return F
    b = kB * I
    return F / (1.0 + ksat * b * b)


@register_jitable
def effect_spring_force(x, K5=None, Kc=None, xc=None):
    """Restoring force [N] that the effects add to the diaphragm's Duffing spring at x [m].

    K5*x^5 (edge_stiffening, K5 [N/m^5]) plus Kc*(x - xc) (viscoelastic_creep: force of the Maxwell
    branch, Kc [N/m], xc [m] the dashpot position); 0.0 when both are off (None).
    """
    if K5 is None:
        return 0.0 if Kc is None else Kc * (x - xc)
    x2 = x * x
    f = K5 * x2 * x2 * x
    return f if Kc is None else f + Kc * (x - xc)


@register_jitable
def restoring_force(x, K1, K2, K5=None, Kc=None, xc=None):
    """Net restoring force of the diaphragm [N] at x [m]: the paper's Duffing spring (K1*x^2 + K2)*x
    (``fmu_src.diaphragm.spring_force``, K1 [N/m^3], K2 [N/m]) plus ``effect_spring_force``."""
    f = spring_force(x, K1, K2)
    if K5 is None and Kc is None:
        return f
    return f + effect_spring_force(x, K5, Kc, xc)


@register_jitable
def diaphragm_acceleration(x, v, F, K1, K2, C, m, K5=None, Kc=None, xc=None):
    """x'' [m/s^2] in free flight: (F - C*v - restoring_force(x))/m.

    F [N] the magnetic force, v [m/s], C [N.s/m], m [kg]; the paper's part is
    ``fmu_src.diaphragm.acceleration`` (Eq. 4), the effects' spring terms come from ``effect_spring_force``.
    """
    if K5 is None and Kc is None:
        return acceleration(x, v, F, K1, K2, C, m)
    return acceleration(x, v, F - effect_spring_force(x, K5, Kc, xc), K1, K2, C, m)


@register_jitable
def net_contact_force(F_face, r0, K1, K2, K5=None, Kc=None, xc=None):
    """Net force [N] toward the coil with the diaphragm on the coil face (x = r0 [m]).

    F_face [N] the magnetic force there (``magnetic_force`` with G(0), saturation included) minus
    ``restoring_force(r0, ...)``: the Duffing spring, K5*r0^5 and the creep branch Kc*(r0 - xc).
    Contact holds while it is >= 0; the diaphragm is released when it turns negative.
    """
    return F_face - restoring_force(r0, K1, K2, K5, Kc, xc)


@register_jitable
def tangent_stiffness(x, K1, K2, K5=None, Kc=None):
    """d(restoring_force)/dx [N/m] at x [m] for motion fast against the creep (dashpot held):
    3*K1*x^2 + K2 (``fmu_src.diaphragm.tangent_stiffness``) + 5*K5*x^4 + Kc. Used to bound step sizes."""
    k = tangent_stiffness_duffing(x, K1, K2)
    if K5 is not None:
        x2 = x * x
        k = k + 5.0 * K5 * x2 * x2
    if Kc is not None:
        k = k + Kc
    return k


@register_jitable
def thermal_rate(dT, I, R_T, Rth, tau_th):
    """dT/dt [K/s] of the winding temperature rise dT [K] (coil_heating): (Rth*I^2*R_T - dT)/tau_th.

    I [A], R_T [Ohm] the hot resistance ``resistance(R, dT)``, Rth [K/W] thermal resistance to ambient,
    tau_th [s] thermal time constant (> 0).
    """
    return (Rth * I * I * R_T - dT) / tau_th


@register_jitable
def creep_rate(x, xc, tau_c):
    """dxc/dt [m/s] of the dashpot position xc [m] of the Maxwell branch (viscoelastic_creep):
    (x - xc)/tau_c, x [m] the displacement, tau_c [s] the relaxation time (> 0)."""
    return (x - xc) / tau_c


@register_jitable
def sensor_rate(u, u_sensor, tau_s):
    """d(u_sensor)/dt of a first-order sensor lag (sensor_lag): (u - u_sensor)/tau_s, u the true
    quantity (x [m] or F [N]), u_sensor the reading (same unit), tau_s [s] the time constant (> 0)."""
    return (u - u_sensor) / tau_s


class EffectDynamics(Dynamics):
    """The paper's model plus the effects switched on in the parameters (every formula from the core
    functions above, called with None for the effects that are off, compiled by numba in
    ``fmu_src.integrator``, which selects the terms from the switches in the parameter block).

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

    def effect_args(self) -> dict:
        """Effect parameters as the core functions take them: None for an effect that is off."""
        p = self.p
        return {"ksat": p.ksat if self.sat else None, "K5": p.K5 if self.edge else None,
                "Kc": p.Kc if self.creep else None, "lam": p.lam if self.emf else None}

    def stability_step(self) -> float:
        p = self.p
        # L(x) >= L; the resistance up to DT_STABILITY_K of heating
        rates = [(resistance(p.R, DT_STABILITY_K) if self.heat else p.R) / p.L]
        if self.heat:
            rates.append(1.0 / p.tau_th)
        if self.creep:
            rates.append(1.0 / p.tau_c)
        if self.lag:
            rates.append(1.0 / p.tau_s)
        if not p.blocked:
            e = self.effect_args()
            k_t = tangent_stiffness(p.r0, p.K1, p.K2, e["K5"], e["Kc"])
            rates += [math.sqrt(k_t / p.m), p.C / p.m]
        return 2.5 / max(rates)

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

    # rhs, magnetic_force, net_contact_force, outputs: Dynamics' methods, which call the compiled
    # integrator's functions (fmu_src.integrator); with this class's switches and state indices in the
    # parameter block they call the core functions above for every effect that is on.


assert EFFECT_FIELDS == tuple(s.name for s in EFFECT_SPECS), (EFFECT_FIELDS, EFFECT_SPECS)
assert all(getattr(Params, s.name) == s.default == 0.0 for s in EFFECT_SPECS)
assert {n for e in EFFECTS.values() for n in e.params} == set(EFFECT_SPEC_BY_NAME)
