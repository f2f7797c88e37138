"""Equations of the candidate effects that the paper's model leaves out, and the model's combined terms.

The effects' specs (parameters, units, states, rules) are ``fmu_src.specs.EFFECTS``; every effect
parameter is 0 (= off) by default, and with every effect off the model is the paper's.

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

Rules: tau_th > 0 when Rth > 0, tau_c > 0 when Kc > 0 (``fmu_src.specs.validate``).
A time constant alone does not switch an effect on.

The net contact force (on the coil face, x = r0) includes every force term:
Em*I^2*G(0)*s(I) - (K1*r0^2 + K2)*r0 - K5*r0^5 - Kc*(r0 - xc), with s the
saturation factor; while in contact (and in blocked mode) the thermal, creep
and sensor states keep evolving.

Term by term (functions on Python floats and numpy arrays alike: plain arithmetic, no branches on
values; an effect whose parameter is passed as None is off and costs nothing):

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
``restoring_force_of``,    the two above with every effect's term from a parameter mapping (name ->
``tangent_stiffness_of``   value; effects off at 0): the harness's bounds need no effect's name
``thermal_rate``           dT' [K/s];  ``creep_rate`` xc' [m/s];  ``sensor_rate`` lag of a reading
=========================  =====================================================================

The whole model (paper's terms from ``fmu_src.diaphragm``, plus every effect that is on), on a
parameter block ``P`` laid out by ``fmu_src.specs.BLOCK`` (parameter values, effect switches, effect
state indices; ``P[i]`` a float, or for the parameters a numpy array of one value per run):

=========================  =====================================================================
``force``                  magnetic force [N] for current I and kernel value G
``force_drives_states``    whether the state rates use the force outside free flight
``rates``                  dy/dt of the whole state y (coil, diaphragm, effect states)
``contact_force``          net force [N] toward the coil with the diaphragm on the coil face
``sensor_readings``        (x_sensor [m], F_sensor [N]) outputs
``stability_step``         largest stable DP5 step [s] for the parameters (floats or arrays)
=========================  =====================================================================

The FMU's scalar DP5 integrator (``fmu_src.integrator``, numba-compiled) calls these combined functions
compiled (``register_jitable``: numba compiles these same function objects); the vectorized simulators of
``harness.sim`` call them (and the term functions) uncompiled with arrays.
"""
from __future__ import annotations

import numpy as np
# the functions below stay plain Python (floats and numpy arrays); register_jitable lets the FMU's
# numba-compiled integrator (fmu_src.integrator) call the very same functions
from numba.extending import register_jitable

from .diaphragm import acceleration, spring_force
from .diaphragm import tangent_stiffness as tangent_stiffness_duffing
from .specs import BLOCK
from .termsum import lag_rates, term_sum_F_reading, term_sum_coil, term_sum_force, term_sum_x_reading
from .terms import LAGS, TERMS

ALPHA_CU = 0.0039   # temperature coefficient of the resistance of copper [1/K]
DT_STABILITY_K = 200.0  # temperature rise [K] the stability step bound of coil_heating allows for

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
def diaphragm_acceleration(x, v, F, K1, K2, C, m, F_effects=None):
    """x'' [m/s^2] in free flight: (F - C*v - restoring_force(x))/m.

    F [N] the magnetic force, v [m/s], C [N.s/m], m [kg]; the paper's part is
    ``fmu_src.diaphragm.acceleration`` (Eq. 4); ``F_effects`` [N] is the effects' extra spring force,
    ``effect_spring_force(x, K5, Kc, xc)`` (None: no effect adds one).
    """
    if F_effects is None:
        return acceleration(x, v, F, K1, K2, C, m)
    return acceleration(x, v, F - F_effects, K1, K2, C, m)


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


def restoring_force_of(x, p):
    """``restoring_force`` [N] at x [m] with every effect's spring term, the parameters from the mapping p
    (name -> float or array, effect parameters 0 = off; e.g. ``Params.as_dict()`` or per-run arrays), the
    creep branch relaxed (xc = x). For step-size and reach bounds (``harness.sim.physics``)."""
    return restoring_force(x, p["K1"], p["K2"], p["K5"], p["Kc"], x)


def tangent_stiffness_of(x, p):
    """``tangent_stiffness`` [N/m] at x [m] with every effect's term, parameters from the mapping p as in
    ``restoring_force_of`` (effect parameters 0 = off)."""
    return tangent_stiffness(x, p["K1"], p["K2"], p["K5"], p["Kc"])


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




# ------------------------------------------------------------------------------ the whole model
# positions in the parameter block P (fmu_src.specs.BLOCK): parameters, effect switches, effect states
_R, _L, _EM, _R0, _K1, _K2, _C, _M, _A, _KB = (BLOCK.param[n] for n in ("R", "L", "Em", "r0", "K1", "K2", "C",
                                                                        "m", "a", "kB"))
_RTH, _TAUTH, _KSAT, _KC, _TAUC, _K5, _LAM, _TAUS = (BLOCK.param[n] for n in ("Rth", "tau_th", "ksat", "Kc",
                                                                              "tau_c", "K5", "lam", "tau_s"))
_HEAT, _SAT, _CREEP, _EDGE, _EMF, _LAG = (BLOCK.switch[n] for n in (
    "coil_heating", "filler_saturation", "viscoelastic_creep", "edge_stiffening", "motional_emf", "sensor_lag"))
_IT, _IXC, _IXS, _IFS = (BLOCK.state[n] for n in ("dT", "xc", "x_sensor", "F_sensor"))
_TERMS = BLOCK.terms   # the term set's switch (fmu_src.terms, sums in fmu_src.termsum)
_LAG_ON_TAU = tuple((BLOCK.lag_on[g], BLOCK.param[f"tau_{g}"]) for g in BLOCK.lag_on if LAGS[g].first_order)


@register_jitable
def force(P, I, G):
    """Magnetic force [N] at current I [A] where the force kernel is G [T^2/(A^2.m)]: ``magnetic_force``
    with filler_saturation when it is on."""
    if P[_SAT] != 0.0:
        return magnetic_force(P[_EM], I, G, P[_KSAT], P[_KB])
    return magnetic_force(P[_EM], I, G)


@register_jitable
def force_drives_states(P):
    """True if the state rates need the magnetic force also outside free flight (sensor_lag: the force
    reading lags the force in contact and blocked mode too; the term set: its lags and coil terms may use it)."""
    return P[_LAG] != 0.0 or P[_TERMS] != 0.0


@register_jitable
def _acceleration(P, y, x, v, F):
    """x'' [m/s^2] in free flight with the effects' spring terms that are on."""
    K1, K2, C, m = P[_K1], P[_K2], P[_C], P[_M]
    if P[_EDGE] != 0.0:
        if P[_CREEP] != 0.0:
            return diaphragm_acceleration(x, v, F, K1, K2, C, m, effect_spring_force(x, P[_K5], P[_KC], y[int(P[_IXC])]))
        return diaphragm_acceleration(x, v, F, K1, K2, C, m, effect_spring_force(x, P[_K5], None, None))
    if P[_CREEP] != 0.0:
        return diaphragm_acceleration(x, v, F, K1, K2, C, m, effect_spring_force(x, None, P[_KC], y[int(P[_IXC])]))
    return acceleration(x, v, F, K1, K2, C, m)


@register_jitable
def rates(P, y, V, x, v, F, free, out):
    """dy/dt into out[:n] for the state y = [I, x, v, effect states] under the coil voltage V [V].

    x [m], v [m/s]: the diaphragm's position and velocity in the current mode (y[1], y[2] in free
    flight; r0, 0 in contact; 0, 0 blocked); F [N] the magnetic force at x (``force``; needed in free
    flight and when ``force_drives_states``); free: the diaphragm moves (else x' = v' = 0). Works on
    floats (compiled) and on arrays (y, out of shape (n, runs); then free must be a single bool).
    With the term set on (``P[BLOCK.terms]``): the coil terms add to V, the force terms to F in the force
    balance, and the lag states get their rates (``fmu_src.termsum``).
    """
    I = y[0]
    r = P[_R0] - x
    heat = P[_HEAT] != 0.0
    iT = int(P[_IT])
    Rc = resistance(P[_R], y[iT]) if heat else P[_R]
    terms = P[_TERMS] != 0.0
    if terms:
        lag_rates(P, y, x, v, I, F, Rc, out)
        V = V + term_sum_coil(P, y, x, v, I, F)
    if P[_EMF] != 0.0:
        out[0] = current_rate(V, I, Rc, P[_L], P[_LAM], P[_A], r, v)
    else:
        out[0] = current_rate(V, I, Rc, P[_L])
    if free:
        out[1] = v
        out[2] = _acceleration(P, y, x, v, F + term_sum_force(P, y, x, v, I, F) if terms else F)
    else:
        out[1] = 0.0
        out[2] = 0.0
    if heat:
        out[iT] = thermal_rate(y[iT], I, Rc, P[_RTH], P[_TAUTH])
    if P[_CREEP] != 0.0:
        ixc = int(P[_IXC])
        out[ixc] = creep_rate(x, y[ixc], P[_TAUC])
    if P[_LAG] != 0.0:
        ixs, iFs = int(P[_IXS]), int(P[_IFS])
        out[ixs] = sensor_rate(x, y[ixs], P[_TAUS])
        out[iFs] = sensor_rate(F, y[iFs], P[_TAUS])


@register_jitable
def contact_force(P, y, F_face):
    """Net force [N] toward the coil with the diaphragm on the coil face: ``net_contact_force`` with the
    effects' spring terms that are on and the term set's force terms at x = r0, v = 0; F_face [N] the magnetic
    force there (``force`` with G(0))."""
    if P[_TERMS] != 0.0:
        return _contact_force(P, y, F_face) + term_sum_force(P, y, P[_R0], 0.0, y[0], F_face)
    return _contact_force(P, y, F_face)


@register_jitable
def _contact_force(P, y, F_face):
    r0, K1, K2 = P[_R0], P[_K1], P[_K2]
    if P[_EDGE] != 0.0:
        if P[_CREEP] != 0.0:
            return net_contact_force(F_face, r0, K1, K2, P[_K5], P[_KC], y[int(P[_IXC])])
        return net_contact_force(F_face, r0, K1, K2, P[_K5], None, None)
    if P[_CREEP] != 0.0:
        return net_contact_force(F_face, r0, K1, K2, None, P[_KC], y[int(P[_IXC])])
    return net_contact_force(F_face, r0, K1, K2)


@register_jitable
def sensor_readings(P, y, x, F):
    """(x_sensor [m], F_sensor [N]): the lagged readings with sensor_lag on, else x [m] and F [N]; with the
    term set on, plus the reading terms (functions of those readings, ``fmu_src.termsum``)."""
    if P[_LAG] != 0.0:
        xb, Fb = y[int(P[_IXS])], y[int(P[_IFS])]
    else:
        xb, Fb = x, F
    if P[_TERMS] != 0.0:
        return (xb + term_sum_x_reading(P, y, xb, 0.0, y[0], Fb), Fb + term_sum_F_reading(P, y, xb, 0.0, y[0], Fb))
    return xb, Fb


def presliding_stiffness(P):
    """Bound [N/m] of the stiffness that the force terms on a lag with its own rate (``LagSpec.rate``, e.g.
    Dahl's presliding state) add at rest: sum over those terms of 2*|c|*|dphi/dz|*|dz'/dv| at v = 0, z = 0
    (central differences of the table's functions; the 2 bounds the (1 + |z|) of a Dahl-type rate). Such a
    lag's own rate |dz'/dz| vanishes at rest, where the step bound matters."""
    k = 0.0 * P[_R0]
    for t in TERMS.values():
        g = LAGS[t.lag] if t.lag is not None else None
        if g is None or g.first_order or t.equation != "force":
            continue
        on, c, tau = P[BLOCK.lag_on[g.name]], P[BLOCK.param[t.coef.name]], P[BLOCK.param[g.tau.name]]
        tau = tau + (1.0 - on)
        h = 1e-9
        dz_dv = (g.rate(0.0, h, 0.0, 0.0, 0.0, 0.0, tau) - g.rate(0.0, -h, 0.0, 0.0, 0.0, 0.0, tau)) / (2 * h)
        dphi_dz = (t.function(0.0, 0.0, 0.0, 0.0, 1e-6) - t.function(0.0, 0.0, 0.0, 0.0, -1e-6)) / 2e-6
        k = k + on * 2.0 * np.abs(c) * np.abs(dphi_dz) * np.abs(dz_dv)
    return k


def stability_step(P, blocked):
    """Largest step [s] inside DP5's real-axis stability region (about -3.3) for every mode: 2.5 over the
    fastest rate of the linearized model (coil R/L with the resistance up to ``DT_STABILITY_K`` of
    heating, the effect states' 1/tau, and unless ``blocked`` the diaphragm's sqrt(k_t/m) and C/m at the
    coil face, k_t with ``presliding_stiffness``). Floats or arrays of parameters.

    Near a steady state the error estimate vanishes, so without this bound the step grows until the
    method becomes unstable and oscillates at the tolerance.
    """
    heat = P[_HEAT] != 0.0
    rate = (resistance(P[_R], DT_STABILITY_K) if heat else P[_R]) / P[_L]   # L(x) >= L
    if heat:
        rate = np.maximum(rate, 1.0 / P[_TAUTH])
    if P[_CREEP] != 0.0:
        rate = np.maximum(rate, 1.0 / P[_TAUC])
    if P[_LAG] != 0.0:
        rate = np.maximum(rate, 1.0 / P[_TAUS])
    if P[_TERMS] != 0.0:
        for on, tau in _LAG_ON_TAU:
            rate = np.maximum(rate, P[on] / (P[tau] + (1.0 - P[on])))
    if not blocked:
        k_t = tangent_stiffness(P[_R0], P[_K1], P[_K2], P[_K5] if P[_EDGE] != 0.0 else None,
                                P[_KC] if P[_CREEP] != 0.0 else None)
        if P[_TERMS] != 0.0:
            k_t = k_t + presliding_stiffness(P)
        rate = np.maximum(rate, np.maximum(np.sqrt(k_t / P[_M]), P[_C] / P[_M]))
    return 2.5 / rate
