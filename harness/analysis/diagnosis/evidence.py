"""Evidence: residual features of the paper model, each in noise units (z = value / its noise std).

Six features, one function each (``samples``: prepared samples; ``traces``: {sample index: {test: Trace}}
of the paper model on every test), each returning its JSON entry; :func:`features` combines them. Which
effect a feature points to is the catalogue's business (``candidates.EVIDENCE_POINTS_TO``).
"""
from __future__ import annotations

import math

import numpy as np

from fmu_src import effects as fx

from .baseline import fit_tau, steady_resistance, steady_window
from .candidates import EVIDENCE_POINTS_TO
from .prepare import Series, Sweep


def _post(test: Series, t0: float, t1: float) -> np.ndarray:
    """Index mask of the samples t0 <= t - t_step < t1 (seconds after the step instant ``Series.t_step_s``,
    estimated within the sample interval, not the first sample reading the step)."""
    tl = test.t - test.t_step_s
    return (tl >= t0) & (tl < t1)


def _last(test: Series, seconds: float) -> np.ndarray:
    """Index mask of the last ``seconds`` of the record: t >= t[-1] - seconds (the boundary sample included
    despite rounding of the clock's time stamps: tolerance 1e-6 sample periods)."""
    return test.t >= test.t[-1] - seconds - 1e-6 * test.dt


def _rl_step_current(t: Series, R: float, tau: float) -> np.ndarray:
    """The RL coil's current [A] for the constant step voltage ``V_on`` [V] from the step instant ``t_step_s``
    (R [Ohm], tau = L/R [s]; 0 before the instant)."""
    s = np.maximum(t.t - t.t_step_s, 0.0)
    return (t.V_on / R) * -np.expm1(-s / tau)


def combine_z(zs) -> float:
    """Stouffer's combination sum(z)/sqrt(n) of the finite z values (NaN when there is none)."""
    zs = [z for z in zs if math.isfinite(z)]
    return float(sum(zs) / math.sqrt(len(zs))) if zs else float("nan")


def _step(sd, name):
    t = sd.tests.get(name)
    return t if isinstance(t, Series) and t.V_on is not None else None


def current_drift(samples, traces: dict) -> dict:
    """Current droop during the holds of T5/T8 (coil heating: R rises, the current falls)."""
    per, zs = {}, []
    for sd in samples:
        for name in ("T5", "T8"):
            t = _step(sd, name)
            if t is None:
                continue
            e, l_ = _post(t, 0.3, 1.3), _last(t, 1.0)
            Ie, Il = float(np.mean(t.I[e])), float(np.mean(t.I[l_]))
            z = (Il - Ie) / (t.sig_I * math.sqrt(1.0 / e.sum() + 1.0 / l_.sum()))
            per.setdefault(sd.sid, {})[name] = {"early_A": Ie, "late_A": Il, "change_pct": 100 * (Il - Ie) / Ie,
                                                "z": z}
            zs.append(z)
    return {
        "points_to": EVIDENCE_POINTS_TO["current_drift"], "tests": ["T5", "T8"], "signal": "current",
        "description": "measured current in the last second of the hold minus its mean 0.3-1.3 s after the step "
                       "(steady voltage: the paper's RL coil keeps it constant; a heating coil lets it fall)",
        "z": combine_z(zs), "per_sample": per}


def displacement_drift(samples, traces: dict) -> dict:
    """Displacement drift at steady current in T3/T5, measured minus the model's (creep: rises)."""
    per, zs = {}, []
    for i, sd in enumerate(samples):
        for name in ("T3", "T5"):
            t = _step(sd, name)
            tr = traces.get(i, {}).get(name)
            if t is None or tr is None:
                continue
            m, l_ = _post(t, 0.5, 1.5), _last(t, 1.0)
            dm = float(np.mean(t.y[l_]) - np.mean(t.y[m]))
            ds_ = float(np.mean(tr.y_sim[l_]) - np.mean(tr.y_sim[m]))
            z = (dm - ds_) / (t.sig_y * math.sqrt(1.0 / m.sum() + 1.0 / l_.sum()))
            per.setdefault(sd.sid, {})[name] = {"measured_drift_um": dm * 1e6, "model_drift_um": ds_ * 1e6, "z": z}
            zs.append(z)
    return {
        "points_to": EVIDENCE_POINTS_TO["displacement_drift"],
        "tests": ["T3", "T5"], "signal": "displacement",
        "description": "displacement drift from 0.5-1.5 s to the last second after the step, measured minus "
                       "the paper model's (positive: keeps creeping toward the coil at steady current)",
        "z": combine_z(zs), "per_sample": per}


def _force_per_I2(t8: Series):
    """Blocked force per I^2 during the T8 rise (50-90 % of the steady current) vs steady: JSON entry or None."""
    w = steady_window(t8)
    Iss = float(np.mean(t8.I[w]))
    rise = _post(t8, 0.0, 0.5) & (t8.I > 0.5 * Iss) & (t8.I < 0.9 * Iss)
    if rise.sum() < 5:
        return None
    q_r = float(np.mean(t8.y[rise] / t8.I[rise] ** 2))
    q_s = float(np.mean(t8.y[w]) / Iss ** 2)
    se = t8.sig_y / math.sqrt(rise.sum()) / float(np.mean(t8.I[rise] ** 2))
    return {"rise_N_per_A2": q_r, "steady_N_per_A2": q_s, "change_pct": 100 * (q_r - q_s) / q_s,
            "z": (q_r - q_s) / se}


def field_dependence(samples, traces: dict) -> dict:
    """Steady residual across T2-T5 vs field, and the blocked force per I^2 during the T8 rise."""
    per, zs, zq = {}, [], []
    for i, sd in enumerate(samples):
        row = {}
        for name in ("T2", "T3", "T4", "T5"):
            t = sd.tests.get(name)
            tr = traces.get(i, {}).get(name)
            if not isinstance(t, Series) or tr is None:
                continue
            w = steady_window(t)
            r = float(np.mean(t.y[w] - tr.y_sim[w]))
            z = r / (t.sig_y / math.sqrt(t.y[w].size))
            row[name] = {"steady_residual_um": r * 1e6,
                         "relative_pct": 100 * r / max(abs(float(np.mean(tr.y_sim[w]))), 1e-12),
                         "current_A": float(np.mean(t.I[w])), "z": z}
            if name in ("T2", "T4"):
                zs.append(z)
        t8 = _step(sd, "T8")
        q = _force_per_I2(t8) if t8 is not None else None
        if q is not None:
            row["T8_force_per_I2"] = q
            zq.append(q["z"])
        per[sd.sid] = row
    return {
        "points_to": EVIDENCE_POINTS_TO["field_dependence"],
        "tests": ["T2", "T3", "T4", "T5", "T8"], "signal": "displacement, blocked force",
        "description": "steady displacement residual of T2-T5 (the paper model is fitted at T3 and T5: T2 and "
                       "T4 show a wrong field law) and the blocked force per I^2 during the T8 current rise "
                       "(50-90 % of steady) relative to its steady value (saturation: higher while I is low; "
                       "a lagging sensor: lower)",
        "z": math.sqrt(float(np.mean(np.square(zs)))) if zs else float("nan"),
        "z_note": "root mean square of the T2/T4 steady-residual z values (about 1 for noise)",
        "z_force_per_I2": combine_z(zq), "per_sample": per}


def deflection_dependence(samples, traces: dict) -> dict:
    """T1 residual at the largest free deflections minus at the smaller half."""
    per, zs = {}, []
    for i, sd in enumerate(samples):
        t = sd.tests.get("T1")
        tr = traces.get(i, {}).get("T1")
        if not isinstance(t, Sweep) or tr is None:
            continue
        free = (t.y < 0.95 * t.gaps) & (t.gaps > 0)
        sim_free = (tr.y_sim < 0.95 * t.gaps) & (t.gaps > 0)
        both = free & sim_free
        if both.sum() < 4:
            continue
        order = np.argsort(t.y[both])
        r = (t.y - tr.y_sim)[both]
        big, small = r[order[-3:]], r[order[: max(1, len(order) // 2)]]
        val = float(np.mean(big) - np.mean(small))
        z = val / (t.sig_y * math.sqrt(1.0 / big.size + 1.0 / small.size))
        per[sd.sid] = {"residual_at_max_deflection_um": float(np.mean(big)) * 1e6,
                       "residual_at_small_deflection_um": float(np.mean(small)) * 1e6,
                       "contact_mismatch_gaps_mm": [float(g) for g in t.gaps[free != sim_free] * 1e3], "z": z}
        zs.append(z)
    return {
        "points_to": EVIDENCE_POINTS_TO["deflection_dependence"],
        "tests": ["T1"], "signal": "displacement",
        "description": "T1 residual at the three largest free deflections minus at the smaller half "
                       "(in units of the noise of a sweep reading), and gaps where measured and simulated "
                       "pull-in disagree",
        "z": combine_z(zs), "per_sample": per}


def _inductance_by_gap(sd) -> dict:
    """Inductance fitted to the T5 and T8 currents (different gaps) and its change."""
    t5, t8 = sd.tests.get("T5"), sd.tests.get("T8")
    if not (isinstance(t5, Series) and isinstance(t8, Series) and t5.V_on and t8.V_on):
        return {}
    R5, R8 = steady_resistance(t5), steady_resistance(t8)
    L5 = R5 * fit_tau(t5, R5)
    L8 = R8 * fit_tau(t8, R8)
    return {"L_T5_H": L5, "L_T8_H": L8, "L_change_pct": 100 * (L8 - L5) / L5}


def motion_current(samples, traces: dict) -> dict:
    """Current residual regressed on the back-EMF shape (motional EMF), and the inductance by gap."""
    per, zs = {}, []
    for i, sd in enumerate(samples):
        row = {}
        num = den = 0.0
        sig = None
        for name in ("T2", "T3", "T4", "T5"):
            t = sd.tests.get(name)
            tr = traces.get(i, {}).get(name)
            if not isinstance(t, Series) or tr is None:
                continue
            k = 5
            xs = np.convolve(t.y, np.ones(2 * k + 1) / (2 * k + 1), mode="same")
            v = np.gradient(xs, t.t)
            p = t.I * v * fx.inductance_gradient(1.0, 1.0, sd.a, t.r0 - xs) / 3.0    # I*v*dL/dx / (3*L*lam)
            sel = _post(t, 0.0, 1.0)
            res = (t.I - tr.I_sim)[sel]
            num += float(np.sum(res * p[sel]))
            den += float(np.sum(p[sel] ** 2))
            sig = t.sig_I
        if den > 0:
            b = num / den
            z = b / (sig / math.sqrt(den))
            row["coefficient"] = -b
            row["z"] = -z
            zs.append(-z)
        row.update(_inductance_by_gap(sd))
        per[sd.sid] = row
    return {
        "points_to": EVIDENCE_POINTS_TO["motion_current"], "tests": ["T2", "T3", "T4", "T5", "T8"],
        "signal": "current",
        "description": "regression of the current residual (first second after the step) on "
                       "I*v*a^3*r/(a^2+r^2)^2.5 (the back-EMF shape, v from the measured displacement; positive = "
                       "current dips while the diaphragm moves toward the coil), and the inductance fitted "
                       "to the T8 current (2 mm gap) relative to T5's (a gap-dependent inductance)",
        "z": combine_z(zs), "per_sample": per}


def _delay(t: Series, ref: np.ndarray, y_sim: np.ndarray, what: str):
    """Delay of the reading of t against ``ref`` in the first 0.3 s after the step: JSON entry or None."""
    sel = _post(t, 0.0, 0.3)
    w = steady_window(t)
    yd = np.gradient(ref, t.t)[sel]
    r = (t.y - ref)[sel]
    den = float(np.sum(yd ** 2))
    if den <= 0:
        return None
    tau = -float(np.sum(r * yd)) / den
    return {"delay_ms": tau * 1e3, "z": tau / (t.sig_y / math.sqrt(den)), "reference": what,
            "steady_residual_rel_pct": 100 * float(np.mean(t.y[w] - y_sim[w]))
            / max(abs(float(np.mean(y_sim[w]))), 1e-12)}


def time_shift(samples, traces: dict) -> dict:
    """Delay of the sensor readings with matching steady state (T8 against I^2, T5 against the model)."""
    per, zs = {}, []
    for i, sd in enumerate(samples):
        row = {}
        for name in ("T8", "T5"):
            t = _step(sd, name)
            tr = traces.get(i, {}).get(name)
            if t is None or tr is None:
                continue
            if name == "T8":
                # a blocked force follows I^2 at once (F = Em G(gap) I^2): the reference is the steady force
                # scaled by (I/I_steady)^2 with I the RL response fitted to T8's own current, so a slow
                # current (inductance by gap, motional EMF) does not count as a delay; the response starts at
                # the estimated step instant (a start at the first sample reading the step would lag the
                # force by up to a sample period and show as a negative delay on a coarse grid)
                w = steady_window(t)
                R8 = float(np.mean(t.V[w]) / np.mean(t.I[w]))
                Ifit = _rl_step_current(t, R8, fit_tau(t, R8))
                ref = float(np.mean(t.y[w])) * (Ifit / float(np.mean(Ifit[w]))) ** 2
                what = "steady force x (I/I_steady)^2, I fitted to the T8 current"
            else:
                ref = tr.y_sim
                what = "paper model"
            d = _delay(t, ref, tr.y_sim, what)
            if d is None:
                continue
            row[name] = d
            if name == "T8":
                zs.append(d["z"])
        per[sd.sid] = row
    return {
        "points_to": EVIDENCE_POINTS_TO["time_shift"],
        "tests": ["T8", "T5"], "signal": "blocked force, displacement",
        "description": "delay of the reading in the first 0.3 s after the step, by least squares "
                       "(residual = -delay * d(reference)/dt): T8 against its steady force scaled by (I/I_steady)^2 "
                       "of the RL response fitted to its own current (a blocked force needs no mechanics, so a "
                       "delay there is the sensor's; z is T8's), T5 against the paper model",
        "z": combine_z(zs), "per_sample": per}


FEATURES = {
    "current_drift": current_drift,
    "displacement_drift": displacement_drift,
    "field_dependence": field_dependence,
    "deflection_dependence": deflection_dependence,
    "motion_current": motion_current,
    "time_shift": time_shift,
}


def features(samples, traces: dict) -> dict:
    """Every residual feature {name: JSON entry} of the paper model's ``traces`` {sample index: {test: Trace}}."""
    return {name: f(samples, traces) for name, f in FEATURES.items()}


def pointing_to(feats: dict, effect: str) -> list:
    """Names of the features whose ``points_to`` names ``effect``."""
    return [k for k, v in feats.items() if effect in v["points_to"]]
