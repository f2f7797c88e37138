"""The diagnosis's parametrization of the effect catalogue (``fmu_src.effects``): everything effect-specific.

This is the one module of the diagnosis that names effects. A new effect (after its spec and equations in
``fmu_src`` and its simulation in ``harness.sim``) is added here: its shared parameters in
:data:`SHARED_DEFS`, their mapping to FMU parameters in :func:`make_params`, and, optionally, whether it has
slow states (:data:`SLOW_EFFECTS`: balances the worker processes) and which residual features point to it
(:data:`EVIDENCE_POINTS_TO`).

Base parameters are fitted as logarithms: the paper's R, L, Em, K1, K2, C, m with C replaced by the
small-signal damping ratio zeta = C/(2 sqrt(K2 m)) (``fmu_src.diaphragm.damping_ratio``; bounded: an
overdamped fast corner would only emulate missing slow physics).
"""
from __future__ import annotations

import math

import numpy as np

from fmu_src.diaphragm import damping_coefficient, damping_ratio
from fmu_src.specs import Params
from harness.analysis.core.lsq import SharedParam
from harness.analysis.discovery.library import default_library

BASE_KEYS = ("R", "L", "Em", "K1", "K2", "zeta", "m")


_LN = math.log
SHARED_DEFS: dict = {
    "coil_heating": (
        SharedParam("Rth", "coil_heating", "K/W", False, 0.0, 500.0, 1e-3, 2.0,
                    "thermal resistance of the winding (shared: one coil)"),
        SharedParam("tau_th", "coil_heating", "s", True, _LN(0.3), _LN(300.0), 1e-4, _LN(5.0),
                    "thermal time constant of the winding (shared)"),
    ),
    "filler_saturation": (
        SharedParam("ksat", "filler_saturation", "1/T2", False, 0.0, 500.0, 1e-4, 0.5,
                    "1/B_sat^2 of the filler (shared: one material)"),
    ),
    "viscoelastic_creep": (
        SharedParam("creep_ratio", "viscoelastic_creep", "1", False, 0.0, 20.0, 1e-5, 0.05,
                    "Kc/K2: Maxwell-branch spring relative to the linear spring (shared: one matrix material)"),
        SharedParam("tau_c", "viscoelastic_creep", "s", True, _LN(0.03), _LN(300.0), 1e-4, _LN(1.0),
                    "relaxation time of the Maxwell branch (shared)"),
    ),
    "edge_stiffening": (
        SharedParam("edge_ratio", "edge_stiffening", "1", False, 0.0, 1e5, 1e-3, 20.0,
                    "K5*D^2/K1: quintic spring relative to the Duffing term, the two are equal at a deflection of "
                    "D/sqrt(edge_ratio) (shared; plate scaling K5/K1 ~ 1/D^2)"),
    ),
    "motional_emf": (
        SharedParam("lam", "motional_emf", "1", False, 0.0, 20.0, 1e-5, 0.05,
                    "relative inductance increase by the diaphragm at the coil face (shared)"),
    ),
    "sensor_lag": (
        SharedParam("tau_s", "sensor_lag", "s", False, 0.0, 0.5, 1e-6, 1e-3,
                    "time constant of the displacement and force sensors (shared: one rig)"),
    ),
}
CANDIDATES = tuple(SHARED_DEFS)

#: effects with slow states (a fit costs about twice as much: the worker groups are balanced with it)
SLOW_EFFECTS = frozenset({"coil_heating", "viscoelastic_creep"})

#: residual feature (``harness.analysis.diagnosis.evidence``) -> the effect(s) it points to; a cause lists
#: the features whose text names it
EVIDENCE_POINTS_TO = {
    "current_drift": "coil_heating",
    "displacement_drift": "viscoelastic_creep (rising) or coil_heating (falling, with the current)",
    "field_dependence": "filler_saturation (force per I^2 higher at low current)",
    "deflection_dependence": "edge_stiffening (negative: too little deflection at large deflection)",
    "motion_current": "motional_emf",
    "time_shift": "sensor_lag (positive delay of the reading; the current is not delayed)",
}


#: key of the coil-radius nuisance parameter: ln(a / a_derived), fitted with every model (shared: one coil) when
#: the dataset's loop radius a was derived from the data (``coil_radius_def``), not stated in the manifest
COIL_RADIUS_KEY = "ln_a_ratio"
#: the fitted keys of the catalogue and the nuisance parameter (any other key is a discovery term's)
_CATALOGUE_KEYS = frozenset(d.key for ds in SHARED_DEFS.values() for d in ds) | {COIL_RADIUS_KEY}


def coil_radius_def(rel_sd: float) -> SharedParam:
    """The coil-radius nuisance parameter for a radius derived with relative standard uncertainty ``rel_sd``:
    ln(a / a_derived) within +-4 standard uncertainties (at least +-1 %, at most +-30 %), starting at 0, with the
    derivation as its Gaussian prior (sd ``rel_sd``): the fit tests see the radius only through the shape of the
    T1 sweep, weakly, so without the prior a few noisy T1 readings pulled a radius T7 had pinned to 0.09 % by 1 %
    (to its bound), and the held-out T7 forces then showed structure (z 24) on clean data."""
    w = min(max(4.0 * float(rel_sd), 0.01), 0.3)
    return SharedParam(COIL_RADIUS_KEY, "coil", "1", False, -w, w, 1e-5, 0.0,
                       "ln(a / a derived from T7): the loop radius refined with every model (shared: one coil), "
                       "with the derivation's standard uncertainty as a Gaussian prior", prior_sd=float(rel_sd))


def shared_defs(effects, library=None) -> list:
    """The shared parameters of the effects ``effects`` (catalogue names and discovery terms, names of
    ``fmu_src.terms.TERMS``), in order; a parameter two terms share (a lag's time constant) once. library: the
    discovery terms' (default ``default_library()``; the fits use the data's, ``FitContext.library``)."""
    lib = default_library() if library is None else library
    out, seen = [], set()
    for e in effects:
        for d in (SHARED_DEFS[e] if e in SHARED_DEFS else lib.params(e)):
            if d.key not in seen:
                seen.add(d.key)
                out.append(d)
    return out


def off_init(effects, library=None) -> dict:
    """Start values {key: fitted value} with the effects switched off (strengths 0; time constants at their
    defaults): a candidate starts at the optimum of the model it extends and can only improve on it."""
    return {d.key: (d.init if d.log else 0.0) for d in shared_defs(effects, library)}


def free_mask(effects) -> np.ndarray:
    """Which base parameters (:data:`BASE_KEYS`) are re-fitted with the effects: all of them."""
    return np.ones(len(BASE_KEYS), dtype=bool)


def base_vector(p: Params) -> np.ndarray:
    """The fitted base vector (logarithms of R, L, Em, K1 (>= 1), K2, zeta (>= 1e-6), m) of Params ``p``."""
    zeta = damping_ratio(p.C, p.K2, p.m)
    return np.log(np.array([p.R, p.L, p.Em, max(p.K1, 1.0), p.K2, max(zeta, 1e-6), p.m], dtype=float))


#: a displacement scale [m] of a diaphragm of diameter D: D/20 (1 mm for D = 20 mm): the Duffing term K1 x^3 is
#: compared with the linear one K2 x there (:func:`k1_scale`)
K1_REF_DEFLECTION_PER_D = 1.0 / 20.0
#: below this fraction of :func:`k1_scale` an analytic K1 says "the static balance of T3/T5 does not determine
#: K1" (their deflections are too small, or the noise made it non-positive): the refit then starts K1 at
#: :data:`K1_UNDETERMINED_START` x the scale, where K1 x^3 is visible in the data (from log K1 = 0, the start the
#: paper's steps give for a non-positive K1, a fit cannot move: d residual / d log K1 = K1 d residual / d K1 = 0)
K1_UNDETERMINED_FRACTION = 1e-3
K1_UNDETERMINED_START = 0.1


def k1_scale(K2_N_per_m: float, D_m: float) -> float:
    """K2 / (D/20)^2 [N/m^3]: the Duffing coefficient whose cubic force equals the linear one at a deflection
    of D/20 (the independent generator's samples have K1 of 0.05-0.3 of it)."""
    return float(K2_N_per_m) / (K1_REF_DEFLECTION_PER_D * float(D_m)) ** 2


def refit_start(p: Params) -> tuple:
    """The refit's start from the paper identification ``p``: ``p`` itself, or ``p`` with K1 at
    :data:`K1_UNDETERMINED_START` x :func:`k1_scale` when the analytic K1 is below
    :data:`K1_UNDETERMINED_FRACTION` of it. Returns (Params, note or None)."""
    scale = k1_scale(p.K2, p.D)
    if p.K1 >= K1_UNDETERMINED_FRACTION * scale:
        return p, None
    K1 = K1_UNDETERMINED_START * scale
    return p.with_(K1=K1), (f"the analytic K1 ({p.K1:.3g} N/m^3) is below {K1_UNDETERMINED_FRACTION:g} x K2/(D/20)^2 "
                            f"(T3/T5 do not determine it); the refit starts it at {K1:.3g} N/m^3")


def base_bounds(b0, D_m: float | None = None) -> tuple:
    """Box bounds (lo, hi) of the log base parameters around a start b0: coil +-0.7, Em and K2 +-2, K1 +-3
    (and, given the diameter ``D_m`` [m], at least up to 100 x :func:`k1_scale`: a K1 the analytic steps could not
    determine may lie far above its start); m for a small-signal natural frequency of 1-100 Hz (at the start
    K2), zeta in 0.02-2."""
    b0 = np.asarray(b0, dtype=float)
    lo = b0 + np.array([-0.7, -0.7, -2.0, -3.0, -2.0, 0.0, 0.0])
    hi = b0 + np.array([0.7, 0.7, 2.0, 3.0, 2.0, 0.0, 0.0])
    K2 = math.exp(b0[4])
    if D_m is not None:
        hi[3] = max(hi[3], math.log(100.0 * k1_scale(K2, D_m)))
    lo[6], hi[6] = math.log(K2 / (2 * math.pi * 100.0) ** 2), math.log(K2 / (2 * math.pi * 1.0) ** 2)
    lo[5], hi[5] = math.log(0.02), math.log(2.0)
    b0c = np.clip(b0, lo, hi)
    return np.minimum(lo, b0c), np.maximum(hi, b0c)


#: edge-stiffening ratios (K5 D^2 / K1) of the extra starts of that candidate (:func:`extra_starts`): three decades
#: (the quintic term equals the Duffing one at D/4.5, D/14, D/45)
EDGE_RATIO_STARTS = (20.0, 200.0, 2000.0)
#: filler-saturation coefficients ksat = 1/B_sat^2 [1/T^2] of the extra starts of that candidate: B_sat 1, 0.58, 0.32 T
SATURATION_STARTS = (1.0, 3.0, 10.0)
#: thermal resistances Rth [K/W] of the extra starts of coil_heating (:func:`extra_starts`; tau_th at its start value)
HEATING_STARTS = (4.0, 16.0)
#: effects whose extra starts are fitted only when they fit the data better than the reference's optimum does: a
#: coil_heating start keeps the records' mean resistance, so it beats the reference exactly where the currents
#: follow a heating course; elsewhere its fit (slow states) would cost a fifth more CPU per diagnosis for nothing
#: (measured on three datasets, session 16)
STARTS_ONLY_WHEN_BETTER = frozenset({"coil_heating"})
#: the last fraction of a step record whose mean is its static point (:func:`static_point`)
STATIC_TAIL_FRACTION = 0.25


def _tail(series) -> slice | None:
    n = series.y.size - int(series.k_on)
    return None if n < 8 else slice(series.y.size - max(int(n * STATIC_TAIL_FRACTION), 4), None)


def static_point(series) -> tuple | None:
    """(x [m], I [A]) of a displacement step record: the means of its last :data:`STATIC_TAIL_FRACTION` (None for
    a blocked test or a record too short to have one)."""
    tail = None if series is None or series.blocked else _tail(series)
    if tail is None:
        return None
    return float(np.mean(series.y[tail])), float(np.mean(series.I[tail]))


def _static_base(sd, b, sh: dict, ratio: float = 0.0, ksat: float = 0.0):
    """The log base vector ``b`` of sample ``sd`` with K1, K2 re-solved so that the springs with an edge ratio
    ``ratio`` (K5 = ratio K1 / D^2) balance the magnetic force Em I^2 G(r0 - x) / (1 + ksat (kB I)^2) at T3's and
    T5's static points, as the paper's analytic step does for its Duffing spring; with ``ksat`` > 0 Em is first
    raised so that T8's steady blocked force (else T5's) stays what ``b`` gives (the coil and the kernel at ``b``,
    ``sh``). None when T3 or T5 lacks a static point or the balance needs a non-positive K1 or K2."""
    from harness.sim.kernels import kernel      # the simulator's per-process cache of the same tables
    p = make_params(sd, b, sh)
    Em = p.Em
    ref = sd.tests.get("T8") if hasattr(sd.tests.get("T8"), "k_on") else sd.tests.get("T5")
    tail = None if ref is None or ksat <= 0 else _tail(ref)
    if tail is not None:
        Em *= 1.0 + ksat * (p.kB * float(np.mean(ref.I[tail]))) ** 2
    pts = []
    for name in ("T3", "T5"):
        t = sd.tests.get(name)
        sp = static_point(t) if t is not None and hasattr(t, "k_on") else None
        if sp is None or not (0.0 < sp[0] < t.r0):
            return None
        x, I = sp
        G = float(kernel(p.a, p.D, p.kB, t.r0)(t.r0 - x))
        pts.append((x, Em * I * I * G / (1.0 + ksat * (p.kB * I) ** 2)))
    A = np.array([[x ** 3 + ratio * x ** 5 / sd.D ** 2, x] for x, _ in pts])
    try:
        K1, K2 = np.linalg.solve(A, np.array([F for _, F in pts]))
    except np.linalg.LinAlgError:
        return None
    if not (K1 > 0 and K2 > 0 and math.isfinite(K1) and math.isfinite(K2)):
        return None
    zeta = damping_ratio(p.C, K2, p.m)          # the same damping coefficient C
    out = np.asarray(b, dtype=float).copy()
    out[2], out[3], out[4], out[5] = math.log(Em), math.log(K1), math.log(K2), math.log(max(zeta, 1e-6))
    return out


def extra_starts(effect: str, samples, base: dict, shared: dict) -> list:
    """Further starts [(base {i: log vector}, shared_init)] of a catalogue candidate beside the reference's optimum
    with the effect off (:func:`off_init`), for an effect that changes what the reference's parameters mean.

    ``edge_stiffening``: a reference (Duffing) model fitted to data of a stiffening edge has K1 too high by the
    missing quintic term; where it holds a large deflection only at the edge of pull-in, adding K5 alone moves
    the model away from the data (the fit cannot leave that optimum: deep profile, session 13). So at each ratio of
    :data:`EDGE_RATIO_STARTS`, K1 and K2 are re-solved from T3's and T5's static balance (:func:`_static_base`).
    ``filler_saturation``: at each ksat of :data:`SATURATION_STARTS`, Em raised to keep T8's force and K1, K2
    re-solved likewise (a saturating filler's reference has Em too low at large currents, and its sweep points at a
    pull-in boundary cannot be crossed by adding ksat alone). A sample without static points keeps its base.
    ``coil_heating``: a reference fitted to a heating coil has R near the records' mean hot resistance; heating
    added to it from there makes every current too low, so its fit cannot leave the reference's optimum (deep
    profile, session 16: a heating of 23 noise floors, every step of the screening rejected, "unexplained"). At
    each Rth of :data:`HEATING_STARTS` the cold R is the reference's divided by the mean heating over the fit
    tests' step records (:func:`_cold_base`). Other effects: none."""
    # effect -> (the shared key set at each start, its values, the sample's moved base vector or None)
    grid = {"edge_stiffening": ("edge_ratio", EDGE_RATIO_STARTS,
                                lambda sd, b, sh: _static_base(sd, b, sh, ratio=sh["edge_ratio"])),
            "filler_saturation": ("ksat", SATURATION_STARTS,
                                  lambda sd, b, sh: _static_base(sd, b, sh, ksat=sh["ksat"])),
            "coil_heating": ("Rth", HEATING_STARTS,
                             lambda sd, b, sh: _cold_base(sd, b, sh["Rth"], math.exp(sh["tau_th"])))}
    if effect not in grid:
        return []
    key, values, moved_base = grid[effect]
    out = []
    for v in values:
        sh = dict(off_init((effect,)), **shared)
        sh[key] = v
        nb, moved = {}, False
        for i, b in base.items():
            eb = moved_base(samples[i], b, sh)
            moved = moved or eb is not None
            nb[i] = b.copy() if eb is None else eb
        if moved:
            out.append((nb, sh))
    return out


def _cold_base(sd, b, Rth: float, tau_th: float):
    """The log base vector ``b`` of sample ``sd`` with R lowered to the cold resistance whose mean heating over the
    sample's step records (T3, T5, T8: dT' = (Rth V^2 / R - dT) / tau_th from the step on, V the step voltage)
    gives the reference's R: R / (1 + ALPHA_CU dT_mean), dT_mean = Rth V^2 / R (1 - tau/T (1 - e^-T/tau)) averaged
    over the records (T: a record's time after its step). None when the sample has no step record."""
    from fmu_src.effects import ALPHA_CU
    R = math.exp(float(b[0]))
    rises = []
    for name in ("T3", "T5", "T8"):
        t = sd.tests.get(name)
        if t is None or not hasattr(t, "k_on") or getattr(t, "V_on", None) is None:
            continue
        T = float(t.t[-1] - t.t[int(t.k_on)])
        if not T > 0:
            continue
        f = 1.0 - tau_th / T * (1.0 - math.exp(-T / tau_th))
        rises.append(Rth * float(t.V_on) ** 2 / R * f)
    if not rises:
        return None
    out = np.asarray(b, dtype=float).copy()
    out[0] = math.log(R / (1.0 + ALPHA_CU * float(np.mean(rises))))
    return out


def make_params(geometry, b, sh: dict) -> Params:
    """FMU parameters of a sample from its log base vector ``b`` and the shared values ``sh`` {key: fitted value}.

    ``geometry`` has ``a`` (coil radius [m]), ``D`` (diameter [m]) and ``kB`` (field per ampere [T/A]); a derived
    radius is refined by ``sh[COIL_RADIUS_KEY]`` (:func:`coil_radius_def`). Strength-type effect parameters are
    clamped at 0.
    """
    R, L, Em, K1, K2, zeta, m = (float(v) for v in np.exp(b))
    C = float(damping_coefficient(zeta, K2, m))
    a = geometry.a * math.exp(float(sh.get(COIL_RADIUS_KEY, 0.0)))
    kw = dict(a=a, D=geometry.D, kB=geometry.kB, R=R, L=L, Em=Em, K1=K1, K2=K2, C=C, m=m)
    if "Rth" in sh:
        kw["Rth"] = max(float(sh["Rth"]), 0.0)
        kw["tau_th"] = math.exp(sh["tau_th"])
    if "ksat" in sh:
        kw["ksat"] = max(float(sh["ksat"]), 0.0)
    if "creep_ratio" in sh:
        kw["Kc"] = max(float(sh["creep_ratio"]), 0.0) * K2
        kw["tau_c"] = math.exp(sh["tau_c"])
    if "edge_ratio" in sh:
        kw["K5"] = max(float(sh["edge_ratio"]), 0.0) * K1 / geometry.D ** 2
    if "lam" in sh:
        kw["lam"] = max(float(sh["lam"]), 0.0)
    if "tau_s" in sh:
        kw["tau_s"] = max(float(sh["tau_s"]), 0.0)
    p = Params(**kw)
    # discovery terms (coefficients relative to their natural scale at this sample's parameters)
    return default_library().apply(p, sh) if any(k not in _CATALOGUE_KEYS for k in sh) else p
