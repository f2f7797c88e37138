"""Model-error diagnosis: which effect that the paper's model leaves out hides in a dataset?

``diagnose(dataset, settings) -> Diagnosis`` runs blind: it reads the measured tests and the rig
description (coil radius, field per ampere, sensor noise), never ``rig.effects``,
``rig.true_parameters`` or ``rig.effect_definitions``. ``write_diagnosis(diag, out_dir)`` writes
``diagnosis.json``, ``diagnosis.md`` (with residual figures), ``extended_params.json`` and
paper-style tables (``harness.report.tables``) of the paper model and of the extended model.

Procedure
---------
1. **Paper model, identified as in the paper** (the "before" model), per sample: R = V/I over the
   steady part of T5, L from the T5 current rise, Em from the steady T8 blocked force, K1 and K2
   from the static balance at the T3 and T5 steady displacements (the analytic steps of
   ``harness.analysis.identify``); C and m by least squares on the T3 and T5 displacement (instead of
   NSGA-II; it also works where ``harness.analysis.identify``'s settling check rejects drifting records).
2. **Refit**: the paper model re-fitted by least squares on the *fit tests* (default T1, T3, T5,
   T8: the identification tests plus the gap sweep T1, the only test that spans the deflection at
   a fixed field, without which field-law and spring-law effects cannot be told apart). Every
   candidate is nested in it, so it is the reference of every comparison.
3. **Candidates** (``fmu_src.effects``): each is the refitted model plus the effect, all base
   parameters (R, L, Em, K1, K2, damping ratio, m) re-fitted per sample and the effect parameters
   *shared* by the samples where physical (``SHARED_DEFS``): one coil (Rth, tau_th), one filler
   (ksat), one matrix material (Kc/K2, tau_c), one plate law (K5 D^2/K1), one coil-diaphragm
   coupling (lam), one rig (tau_s). The shared parameters are fitted jointly with the base
   parameters of up to ``max_shared_samples`` samples spread over the diameters; every other
   sample (the unseen 15/25 wt% ones first) is a *held-out sample*: its base parameters are then
   fitted to its own fit tests with the effect parameters fixed. Fits start from the refit with
   the effect off (strength 0), so a candidate can only improve on the model it extends;
   weighted least squares (residuals / noise), Levenberg-Marquardt with forward-difference
   Jacobians, several problems in lock-step so that one simulation batch serves them all, the
   candidates spread over ``workers`` processes. A candidate that has not paid for its
   parameters (chi-square decrease < k ln n) after ``screen_iter`` iterations is dropped.
   Uncertainties of the shared parameters: s^2 (J^T J)^-1 of the joint fit, s^2 = max(1, chi2/dof).
4. **Decision** on data the fits never used, the *held-out tests* (default T2, T4, T6, T7 of every
   sample), together with BIC on the fit data: a candidate is accepted when its BIC is lower than
   the reference's by more than ``bic_min`` (10) AND its held-out chi-square is lower by more than
   ``heldout_min`` (25). The accepted candidate with the largest score (held-out chi-square
   decrease - BIC change) is the cause; while the selected model's residuals still show structure
   (some test/signal with z > ``z_struct``), each remaining candidate is added to it in turn
   (greedy forward selection, same rule against the selected model) -> ranked ``causes``. No
   candidate accepted: ``none`` when the refit's residuals are noise (every z <= ``z_struct``),
   else ``unexplained``. z = (chi2 - n)/sqrt(2n) per test and signal summed over the samples.
5. **Evidence**: residual features of the paper model, each in noise units (``_features``):
   current drift during the holds (heating), displacement drift at steady current (creep),
   steady residual vs field and blocked force per I^2 during the T8 rise (saturation), T1
   residual at the largest deflections (edge stiffening), current residual vs the back-EMF shape
   and the inductance by gap (motional EMF), delay of the readings with matching steady state
   (sensor lag); plus, per candidate, the tests and signals whose chi-square it lowers most.
6. **Gain**: RMSE before (paper identification), refit and after (extended model) on every
   held-out test and signal, in units and divided by the sensor noise floor; overall = RMS over
   samples, tests and signals of the normalized RMSE; the same for the held-out samples.

Noise model: time series, white noise at the sensor noise floor (manifest rig.sensors, else
estimated from the quiet part before the steps); sweep readings (means over the averaging
window of each hold) floor/sqrt(n), at least ``sweep_sigma_floor`` x floor, passed through
c*asinh(z/c) (a pull-in mismatch at one gap must not outweigh everything else).

Simulation: every fit and evaluation runs ``harness.sim.simulator.simulate``, a numpy RK4 integrator vectorized over
hundreds of runs (samples x tests x gaps x parameter sets). It holds no physics of its own: its
right-hand side (``harness.sim.physics.rhs``), magnetic and net contact forces (``physics.forces``) and the
stiffness used for step sizes call the array-capable core functions of ``fmu_src.effects``
(``current_rate``, ``magnetic_force``, ``diaphragm_acceleration``, ``net_contact_force``,
``thermal_rate``, ``creep_rate``, ``tangent_stiffness``, ...), the same functions that
``fmu_src.effects.EffectDynamics`` (the code the FMU wraps) calls, with the force kernel G(r) of
every run from one stacked spline table (``_KernelTable``). What is its own is numerics: RK4 with
step dt/n_sub chosen from the stiffest run (runs needing finer steps are integrated apart), runs
without slow states frozen once settled, coarse steps for the slow remainder (heating, creep), the
contact logic (perfectly inelastic impact, release when the net contact force turns negative) and
the exact update of the sensor lag for a piecewise-linear input. Against ``fmu_src.model.simulate``
(DP5, rtol 1e-7) its error is below 0.01 of the noise floor (0.3 with a sensor lag at an impact on
the coil face); tests/analysis/test_diagnose.py checks that, that its right-hand side equals EffectDynamics'
at random states for all 64 effect combinations, and that the formulas come from fmu_src.

diagnosis.json (``diagnosis_to_json``)
--------------------------------------
``format`` "mpc-actuator-diagnosis/1", ``synthetic``, ``cause`` (catalogue name | "none" |
"unexplained"), ``causes`` [{rank, name, score, delta_bic, delta_chi2_heldout, reason, shows_in
[{test, signal, delta_chi2}], evidence_features}], ``effects``, ``effect_parameters``
{"<name>_<unit>": {value, std, effect, description}, "per_sample": {id: {"Kc_N_per_m": ...}}},
``gain`` {heldout_tests, per_test {T: {"displacement_rmse_mm" | "blocked_force_rmse_N" |
"current_rmse_A" | "..._rmse_per_noise_floor": {before, refit, after}}}, overall_normalized_rmse
{before, refit, after, after_over_before}, heldout_samples {...}, fit_tests {...}, per_sample,
noise_floors, models}, ``candidates`` {name: {delta_bic, delta_chi2_fit, delta_chi2_heldout, score,
accepted, reason, shared_parameters, shows_in}}, ``evidence`` {features, baseline_structure_z,
final_structure_z, remaining_structure}, ``decision`` {rule, thresholds, fit_tests, heldout_tests,
shared_fit_samples, heldout_samples, rounds}, ``samples``, ``parameters`` {extended,
paper_identification, paper_refit: {id: {unit keys}}}, ``settings``, ``timing_s``.

extended_params.json (``extended_params_json``)
-----------------------------------------------
{"format": "mpc-actuator-params/1", "cause", "effects", "shared_effect_parameters",
"samples": {id: {"wt_pct", "diameter_mm", "role", "parameters": {"a_m", "D_m", "kB_T_per_A",
"R_Ohm", "L_H", "Em_N_m_per_T2", "K1_N_per_m3", "K2_N_per_m", "C_N_s_per_m", "m_kg",
"Rth_K_per_W", "tau_th_s", "ksat_per_T2", "Kc_N_per_m", "tau_c_s", "K5_N_per_m5", "lam_1",
"tau_s_s"}}}}: every FMU parameter except the per-test gap r0 (effects off = 0); the layout of
rig.true_parameters (``harness.data.rig.params_from_json`` and ``harness.cli.load_params_file`` read it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fmu_src import effects as fx
from harness.sim.kernels import kernel as _kernel
from harness.sim.settings import Schedule
from harness.sim.simulator import PARAM_FIELDS, Runs, simulate
from harness.data.paramsjson import params_to_json, unit_key as _ukey

# ============================================================================ data
@dataclass
class _Series:
    """A time-series test prepared for simulation (SI units; y = displacement [m] or force [N])."""
    name: str
    blocked: bool
    r0: float
    field_T: float
    t: np.ndarray
    V: np.ndarray
    I: np.ndarray
    y: np.ndarray
    k_on: int              # first sample with the input on (local time 0)
    V_on: float | None     # constant voltage after the onset (None: replay V on the whole record)
    sig_y: float
    sig_I: float
    frequency_hz: float | None = None

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])


@dataclass
class _Sweep:
    """A gap sweep: one steady reading per gap (mean over the last avg_s of a hold_s hold from rest)."""
    name: str
    blocked: bool
    field_T: float
    gaps: np.ndarray       # [m]
    I: np.ndarray          # [A]
    y: np.ndarray          # [m] or [N]
    V_on: float
    hold_s: float
    avg_s: float
    sig_y: float           # effective noise of a reading (mean of many samples, with a floor)
    sig_I: float
    floor_y: float         # sensor noise floor (per sample)
    floor_I: float
    dt: float = 1e-3       # sample period of the rig [s] (the simulation step grid)
    fit_mask: np.ndarray | None = None   # gaps simulated inside fits (all when None)


@dataclass
class _SampleData:
    sid: str
    wt_pct: float
    diameter_mm: float
    a: float
    D: float
    kB: float
    tests: dict
    unseen: bool = False


def _noise_floors(ds) -> dict:
    """Sensor noise floors {column: value in the column's unit} from the manifest (else estimated)."""
    out = {}
    sensors = (ds.rig or {}).get("sensors") or {}
    for col in ("displacement_mm", "force_N", "current_A"):
        v = None
        try:
            s = sensors[col]
            v = float(s.get("noise_floor", s.get("noise_sigma")))
        except (KeyError, TypeError, ValueError, AttributeError):
            v = None
        if v is None or not (v > 0 and math.isfinite(v)):
            v = _estimate_floor(ds, col)
        out[col] = v
    return out


def _estimate_floor(ds, col: str) -> float:
    """Noise std [column unit] estimated from the pre-step part of the time series (MAD of differences)."""
    vals = []
    for s in ds.samples:
        for t in s.tests.values():
            y = getattr(t, col, None)
            if y is None or not hasattr(t, "time_s"):
                continue
            V = t.voltage_V
            k = int(np.argmax(V > 0.5 * np.max(V))) if np.any(V > 0) else y.size
            seg = y[:max(k, 0)]
            if seg.size >= 20:
                d = np.diff(seg)
                vals.append(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))
    v = float(np.median(vals)) if vals else 0.0
    if not v > 0:
        raise ValueError(f"cannot estimate the noise of {col}: the manifest has no rig.sensors.{col}.noise_floor "
                         f"and no record has a quiet part before the step")
    return v


def _prepare(ds, settings) -> list:
    from harness.data.rig import UNSEEN_SAMPLES
    rig = ds.rig or {}
    floors = _noise_floors(ds)
    fl_x, fl_F, fl_I = floors["displacement_mm"] / 1e3, floors["force_N"], floors["current_A"]
    a_mm = rig.get("coil_radius_mm")
    if a_mm is None:
        raise ValueError("the dataset manifest has no rig.coil_radius_mm (loop radius of the electromagnet)")
    a = float(a_mm) / 1e3
    dt_rig = float(rig.get("sample_period_s", 1e-3))
    hold = float(rig.get("sweep_hold_s", 1.5))
    avg = float(rig.get("sweep_average_s", 0.3))
    n_avg = max(1.0, avg / dt_rig)
    unseen = {(float(w), float(d)) for w, d in UNSEEN_SAMPLES}
    out = []
    for s in ds.samples:
        tests = {}
        kB = rig.get("field_per_amp_T_per_A")
        series_v = {}
        for name, t in s.tests.items():
            if not hasattr(t, "time_s"):
                continue
            blocked = t.force_N is not None and t.displacement_mm is None
            y = t.force_N if blocked else t.displacement_mm / 1e3
            V = t.voltage_V
            k_on = int(np.argmax(V > 0.5 * np.max(V))) if np.any(V > 0) else 0
            while k_on > 0 and V[k_on - 1] != 0.0:
                k_on -= 1
            post = V[k_on:]
            step = (np.all(V[:k_on] == 0.0) and post.size > 1
                    and np.ptp(post) <= 1e-9 * max(abs(float(post[0])), 1e-12))
            dt = float(np.median(np.diff(t.time_s)))
            uniform = np.allclose(np.diff(t.time_s), dt, rtol=1e-6, atol=0.0)
            if not uniform:
                raise ValueError(f"sample {s.id}, test {name}: the diagnosis needs a uniform time grid")
            tests[name] = _Series(name=name, blocked=blocked, r0=float(t.gap_mm) / 1e3, field_T=float(t.field_T),
                                  t=t.time_s, V=V, I=t.current_A, y=y, k_on=k_on if step else 0,
                                  V_on=float(post[0]) if step else None,
                                  sig_y=fl_F if blocked else fl_x, sig_I=fl_I,
                                  frequency_hz=t.frequency_hz)
            if step:
                series_v[name] = (float(t.field_T), float(post[0]))
            if kB is None and name == "T5":
                kB = float(t.field_T) / float(np.mean(t.current_A[-max(10, (t.current_A.size - k_on) // 2):]))
        if kB is None:
            raise ValueError(f"sample {s.id}: no rig.field_per_amp_T_per_A and no T5 to derive it from")
        for name, t in s.tests.items():
            if hasattr(t, "time_s"):
                continue
            blocked = name == "T7" or (t.force_N is not None and t.displacement_mm is None)
            y = t.force_N if blocked else t.displacement_mm / 1e3
            # drive voltage of the sweep: the step voltage of a time series at the same nominal field
            # (the rig sets the voltage for the field); else scaled by field, else from the current
            ref = [v for f, v in series_v.values() if abs(f - float(t.field_T)) < 1e-9]
            if ref:
                Von = float(np.median(ref))
            elif series_v:
                f0, v0 = series_v.get("T5", next(iter(series_v.values())))
                Von = v0 * float(t.field_T) / f0
            else:
                raise ValueError(f"sample {s.id}, test {name}: no time-series test to infer the drive voltage")
            fy = floors["force_N"] if blocked else fl_x
            # inside fits: every gap with a reading of at least 5 % of the largest, every third of the others
            big = np.abs(y) >= 0.05 * np.max(np.abs(y)) if y.size else np.zeros(0, bool)
            fit_mask = big | (np.arange(y.size) % 3 == 0)
            tests[name] = _Sweep(name=name, blocked=blocked, field_T=float(t.field_T), gaps=t.gap_mm / 1e3,
                                 I=t.current_A, y=y, V_on=Von, hold_s=hold, avg_s=avg,
                                 sig_y=max(fy / math.sqrt(n_avg), settings.sweep_sigma_floor * fy),
                                 sig_I=max(fl_I / math.sqrt(n_avg), settings.sweep_sigma_floor * fl_I),
                                 floor_y=fy, floor_I=fl_I, dt=dt_rig, fit_mask=fit_mask)
        out.append(_SampleData(sid=s.id, wt_pct=float(s.wt_pct), diameter_mm=float(s.diameter_mm), a=a,
                               D=float(s.diameter_mm) / 1e3, kB=float(kB), tests=dict(sorted(tests.items())),
                               unseen=(float(s.wt_pct), float(s.diameter_mm)) in unseen))
    return out


# ============================================================================ running jobs
def _run_jobs(jobs, names, full: bool = False, fine_s: float = 0.5, fit_gaps: bool = False) -> list:
    """Simulate jobs [(sample data, Params)] on the tests ``names`` (a list per job, or one list for all).

    Returns per job {test: ("series", t_local, I, y) | ("sweep", I_mean, y_mean)}; series outputs on the
    simulator's grid (every sample while fine, then every coarse step) unless ``full`` (every sample).
    """
    if names and isinstance(names[0], str):
        names = [names] * len(jobs)
    const_rows, const_v, grid_rows = [], [], {}
    pvals, blk = [], []
    gvals = {}
    dt = None
    for j, ((sd, p), nm) in enumerate(zip(jobs, names)):
        base = [getattr(p, k) for k in PARAM_FIELDS]
        ir0 = PARAM_FIELDS.index("r0")
        for name in nm:
            test = sd.tests.get(name)
            if test is None:
                continue
            if isinstance(test, _Sweep):
                for gi, g in enumerate(test.gaps):
                    if fit_gaps and test.fit_mask is not None and not test.fit_mask[gi]:
                        continue
                    row = list(base)
                    row[ir0] = float(g)
                    const_rows.append((j, name, gi))
                    pvals.append(row)
                    blk.append(test.blocked)
                    const_v.append(test.V_on)
                dt = test.dt if dt is None else dt
                continue
            row = list(base)
            row[ir0] = test.r0
            dt = test.dt if dt is None else dt
            if test.V_on is not None:
                const_rows.append((j, name, None))
                pvals.append(row)
                blk.append(test.blocked)
                const_v.append(test.V_on)
            else:
                n = test.t.size - 1
                grid_rows.setdefault(n, []).append((j, name))
                gvals.setdefault(n, ([], [], []))
                gvals[n][0].append(row)
                gvals[n][1].append(test.blocked)
                gvals[n][2].append(test.V[:-1])
    dt = dt or 1e-3
    out = [dict() for _ in jobs]
    # constant-input rows: the series and the sweeps in separate batches when the series need the
    # full grid (a sweep only needs the mean over its averaging window)
    groups = [list(range(len(const_rows)))]
    if full:
        groups = [[r for r, c in enumerate(const_rows) if c[2] is None],
                  [r for r, c in enumerate(const_rows) if c[2] is not None]]
    for rows in groups:
        if not rows:
            continue
        A = np.array([pvals[r] for r in rows], dtype=float)
        P = {k: A[:, i] for i, k in enumerate(PARAM_FIELDS)}
        any_series = any(const_rows[r][2] is None for r in rows)
        te = 0.0
        for r in rows:
            j, name, gi = const_rows[r]
            test = jobs[j][0].tests[name]
            te = max(te, test.hold_s if gi is not None else (test.t.size - 1 - test.k_on) * test.dt)
        te = round(te / dt) * dt
        sim = simulate(Runs(P, np.array([blk[r] for r in rows]), np.array([const_v[r] for r in rows]), dt=dt),
                       Schedule(t_end=te, fine_s=te if (full and any_series) else fine_s))
        sweeps = {}
        for r, (j, name, gi) in enumerate(const_rows[q] for q in rows):
            if gi is None:
                test = jobs[j][0].tests[name]
                n_loc = test.t.size - test.k_on
                keep = sim.t <= (n_loc - 1) * dt + 1e-9
                out[j][name] = ("series", sim.t[keep], sim.I[r, keep], sim.y[r, keep])
            else:
                sweeps.setdefault((j, name), []).append((gi, r))
        for (j, name), lst in sweeps.items():
            test = jobs[j][0].tests[name]
            win = (sim.t > test.hold_s - test.avg_s + 1e-9) & (sim.t <= test.hold_s + 1e-9)
            Im = np.full(test.gaps.size, np.nan)
            ym = np.full(test.gaps.size, np.nan)
            for gi, r in lst:
                Im[gi] = sim.I[r, win].mean()
                ym[gi] = sim.y[r, win].mean()
            out[j][name] = ("sweep", Im, ym)
    for n, rows in grid_rows.items():
        pv, bl, Vs = gvals[n]
        A = np.array(pv, dtype=float)
        P = {k: A[:, i] for i, k in enumerate(PARAM_FIELDS)}
        sim = simulate(Runs(P, np.array(bl), np.array(Vs), dt=dt))
        for r, (j, name) in enumerate(rows):
            out[j][name] = ("series", sim.t, sim.I[r], sim.y[r])
    return out


def _residual_parts(sd: _SampleData, sims: dict, names, robust_c: float | None = None) -> dict:
    """Normalized residuals (measured - simulated) / sigma per (test, channel): {(test, "y"|"I"): z array}."""
    out = {}
    for name in names:
        if name not in sims:
            continue
        test = sd.tests[name]
        s = sims[name]
        if s[0] == "sweep":
            ok = np.isfinite(s[2])            # gaps left out of a fit are NaN
            zy = (test.y[ok] - s[2][ok]) / test.sig_y
            zI = (test.I[ok] - s[1][ok]) / test.sig_I
            if robust_c:
                zy = robust_c * np.arcsinh(zy / robust_c)
                zI = robust_c * np.arcsinh(zI / robust_c)
        else:
            _, tl, Is, ys = s
            idx = test.k_on + np.rint(tl / test.dt).astype(np.intp)
            sel = (tl > 0.0) | (test.V_on is None)
            idx, Is, ys = idx[sel], Is[sel], ys[sel]
            zy = (test.y[idx] - ys) / test.sig_y
            zI = (test.I[idx] - Is) / test.sig_I
        out[(name, "y")] = zy
        out[(name, "I")] = zI
    return out


# ============================================================================ parametrization
# base parameters as fitted (logarithms): the paper's, with C replaced by the small-signal damping ratio
# zeta = C/(2 sqrt(K2 m)) (bounded: an overdamped fast corner would only emulate missing slow physics)
BASE_KEYS = ("R", "L", "Em", "K1", "K2", "zeta", "m")


@dataclass(frozen=True)
class _Shared:
    """A shared effect parameter as the fit sees it (log = fitted as its logarithm)."""
    key: str
    effect: str
    unit: str
    log: bool
    lo: float
    hi: float
    fd: float
    init: float
    description: str


_LN = math.log
SHARED_DEFS: dict = {
    "coil_heating": (
        _Shared("Rth", "coil_heating", "K/W", False, 0.0, 500.0, 1e-3, 2.0,
                "thermal resistance of the winding (shared: one coil)"),
        _Shared("tau_th", "coil_heating", "s", True, _LN(0.3), _LN(300.0), 1e-4, _LN(5.0),
                "thermal time constant of the winding (shared)"),
    ),
    "filler_saturation": (
        _Shared("ksat", "filler_saturation", "1/T2", False, 0.0, 500.0, 1e-4, 0.5,
                "1/B_sat^2 of the filler (shared: one material)"),
    ),
    "viscoelastic_creep": (
        _Shared("creep_ratio", "viscoelastic_creep", "1", False, 0.0, 20.0, 1e-5, 0.05,
                "Kc/K2: Maxwell-branch spring relative to the linear spring (shared: one matrix material)"),
        _Shared("tau_c", "viscoelastic_creep", "s", True, _LN(0.03), _LN(300.0), 1e-4, _LN(1.0),
                "relaxation time of the Maxwell branch (shared)"),
    ),
    "edge_stiffening": (
        _Shared("edge_ratio", "edge_stiffening", "1", False, 0.0, 1e5, 1e-3, 20.0,
                "K5*D^2/K1: quintic spring relative to the Duffing term, the two are equal at a deflection of "
                "D/sqrt(edge_ratio) (shared; plate scaling K5/K1 ~ 1/D^2)"),
    ),
    "motional_emf": (
        _Shared("lam", "motional_emf", "1", False, 0.0, 20.0, 1e-5, 0.05,
                "relative inductance increase by the diaphragm at the coil face (shared)"),
    ),
    "sensor_lag": (
        _Shared("tau_s", "sensor_lag", "s", False, 0.0, 0.5, 1e-6, 1e-3,
                "time constant of the displacement and force sensors (shared: one rig)"),
    ),
}
CANDIDATES = tuple(SHARED_DEFS)


def _off_init(effects) -> dict:
    """Start values with the effects switched off (strengths 0; time constants at their defaults):
    a candidate starts at the optimum of the model it extends and can only improve on it."""
    return {d.key: (d.init if d.log else 0.0) for d in _shared_defs(effects)}


def _shared_defs(effects) -> list:
    return [d for e in effects for d in SHARED_DEFS[e]]


def _base_vector(p) -> np.ndarray:
    zeta = p.C / (2.0 * math.sqrt(p.K2 * p.m))
    return np.log(np.array([p.R, p.L, p.Em, max(p.K1, 1.0), p.K2, max(zeta, 1e-6), p.m], dtype=float))


def _base_bounds(b0) -> tuple:
    """Box bounds (log) of the base parameters around a start b0: coil +-0.7, Em and K2 +-2, K1 +-3;
    m for a small-signal natural frequency of 1-100 Hz (at the start K2), zeta in 0.02-2."""
    b0 = np.asarray(b0, dtype=float)
    lo = b0 + np.array([-0.7, -0.7, -2.0, -3.0, -2.0, 0.0, 0.0])
    hi = b0 + np.array([0.7, 0.7, 2.0, 3.0, 2.0, 0.0, 0.0])
    K2 = math.exp(b0[4])
    lo[6], hi[6] = math.log(K2 / (2 * math.pi * 100.0) ** 2), math.log(K2 / (2 * math.pi * 1.0) ** 2)
    lo[5], hi[5] = math.log(0.02), math.log(2.0)
    b0c = np.clip(b0, lo, hi)
    return np.minimum(lo, b0c), np.maximum(hi, b0c)


def _make_params(sd: _SampleData, b, sh: dict):
    from fmu_src.params import Params
    R, L, Em, K1, K2, zeta, m = (float(v) for v in np.exp(b))
    C = 2.0 * zeta * math.sqrt(K2 * m)
    kw = dict(a=sd.a, D=sd.D, kB=sd.kB, R=R, L=L, Em=Em, K1=K1, K2=K2, C=C, m=m)
    if "Rth" in sh:
        kw["Rth"] = max(float(sh["Rth"]), 0.0)
        kw["tau_th"] = math.exp(sh["tau_th"])
    if "ksat" in sh:
        kw["ksat"] = max(float(sh["ksat"]), 0.0)
    if "creep_ratio" in sh:
        kw["Kc"] = max(float(sh["creep_ratio"]), 0.0) * K2
        kw["tau_c"] = math.exp(sh["tau_c"])
    if "edge_ratio" in sh:
        kw["K5"] = max(float(sh["edge_ratio"]), 0.0) * K1 / sd.D ** 2
    if "lam" in sh:
        kw["lam"] = max(float(sh["lam"]), 0.0)
    if "tau_s" in sh:
        kw["tau_s"] = max(float(sh["tau_s"]), 0.0)
    return Params(**kw)


def _natural(d: _Shared, v: float) -> float:
    return math.exp(v) if d.log else float(v)


# ============================================================================ least squares (batched LM)
@dataclass
class _Problem:
    x0: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    fd: np.ndarray
    jobs: object            # x -> [(sample index, Params)]


class _Evaluator:
    """Residual vectors of many parameter points, simulated together (one batch per call), cached."""

    def __init__(self, samples, names, settings):
        self.samples = samples
        self.names = list(names)
        self.settings = settings
        self.cache = {}
        self.n_sims = 0

    @staticmethod
    def _key(i, p):
        return (i,) + tuple(float(getattr(p, k)) for k in PARAM_FIELDS)

    def parts(self, jobs) -> list:
        """Residual parts {(test, channel): z} for each job (sample index, Params)."""
        keys = [self._key(i, p) for i, p in jobs]
        todo, seen = [], set()
        for k, (i, p) in zip(keys, jobs):
            if k not in self.cache and k not in seen:
                seen.add(k)
                todo.append((k, i, p))
        got = {}
        if todo:
            sims = _run_jobs([(self.samples[i], p) for _, i, p in todo], self.names,
                             fine_s=self.settings.fine_s, fit_gaps=True)
            self.n_sims += len(todo)
            for (k, i, p), s in zip(todo, sims):
                got[k] = _residual_parts(self.samples[i], s, self.names, self.settings.sweep_robust_c)
        out = [got[k] if k in got else self.cache[k] for k in keys]
        if len(self.cache) > 20000:
            self.cache.clear()
        self.cache.update(got)
        return out

    def vectors(self, points) -> list:
        """points: list of job lists; returns the concatenated residual vector of each point."""
        flat = [j for pt in points for j in pt]
        parts = self.parts(flat)
        out, pos = [], 0
        for pt in points:
            vec = [np.concatenate([parts[pos + q][k] for k in sorted(parts[pos + q])]) for q in range(len(pt))]
            out.append(np.concatenate(vec) if vec else np.zeros(0))
            pos += len(pt)
        return out


def _lm(problems, ev: _Evaluator, max_iter: int = 25, ftol: float = 1e-4, atol: float = 2.0):
    """Levenberg-Marquardt for several independent problems in lock-step (shared simulation batches).

    Forward-difference Jacobians; bounds by projection. Each iteration evaluates, in one batch,
    three damped steps (damping x0.1, x1, x10) and the Jacobian at the middle one (used at once
    if that step is taken). Stops when the cost (chi-square) falls by less than ``ftol`` relative
    or ``atol`` absolute. Returns [(x, cost, J, r)] (J at the last linearization point).
    """
    n = len(problems)
    x = [np.clip(p.x0.astype(float), p.lo, p.hi) for p in problems]

    def columns(i, xi):
        p = problems[i]
        out = []
        for j in range(xi.size):
            hstep = p.fd[j] if xi[j] + p.fd[j] <= p.hi[j] else -p.fd[j]
            xp = xi.copy()
            xp[j] += hstep
            out.append((j, hstep, xp))
        return out

    def assemble(r0, cols, vecs):
        Jm = np.empty((r0.size, len(cols)))
        for (j, hstep, _), v in zip(cols, vecs):
            Jm[:, j] = (v - r0) / hstep
        return np.nan_to_num(Jm, nan=0.0, posinf=0.0, neginf=0.0)   # a diverged column carries no information

    cols0 = [columns(i, x[i]) for i in range(n)]
    pts = [problems[i].jobs(x[i]) for i in range(n)]
    for i in range(n):
        pts += [problems[i].jobs(xp) for _, _, xp in cols0[i]]
    vecs = ev.vectors(pts)
    r = [np.nan_to_num(ri, nan=1e6, posinf=1e6, neginf=-1e6) for ri in vecs[:n]]
    cost = [float(ri @ ri) for ri in r]
    J, pos = [], n
    for i in range(n):
        k = len(cols0[i])
        J.append(assemble(r[i], cols0[i], vecs[pos:pos + k]))
        pos += k
    lam = [1e-2] * n
    active = [True] * n
    for _ in range(max_iter):
        act = [i for i in range(n) if active[i]]
        if not act:
            break
        need = [i for i in act if J[i] is None]
        if need:
            cl = {i: columns(i, x[i]) for i in need}
            vv = ev.vectors([problems[i].jobs(xp) for i in need for _, _, xp in cl[i]])
            pos = 0
            for i in need:
                k = len(cl[i])
                J[i] = assemble(r[i], cl[i], vv[pos:pos + k])
                pos += k
        trials, pts = [], []
        for i in act:
            A = J[i].T @ J[i]
            g = J[i].T @ r[i]
            dA = np.maximum(np.diag(A), 1e-12 * max(float(np.max(np.diag(A))), 1e-300))
            for mult in (0.1, 1.0, 10.0):
                M = A + lam[i] * mult * np.diag(dA)
                try:
                    d = -np.linalg.solve(M, g)
                except np.linalg.LinAlgError:
                    d = -np.linalg.lstsq(M, g, rcond=None)[0]
                if not np.all(np.isfinite(d)):
                    continue
                xt = np.clip(x[i] + d, problems[i].lo, problems[i].hi)
                cl = columns(i, xt) if mult == 1.0 else []
                trials.append((i, mult, xt, cl, len(pts)))
                pts.append(problems[i].jobs(xt))
                pts += [problems[i].jobs(xp) for _, _, xp in cl]
        vecs = ev.vectors(pts)
        best = {}
        for i, mult, xt, cl, p0 in trials:
            v = vecs[p0]
            c = float(v @ v) if np.all(np.isfinite(v)) else math.inf
            if math.isfinite(c) and (i not in best or c < best[i][0]):
                best[i] = (c, mult, xt, v, cl, p0)
        for i in act:
            if i in best and best[i][0] < cost[i]:
                c, mult, xt, v, cl, p0 = best[i]
                dec = cost[i] - c
                x[i], r[i] = xt, v
                J[i] = assemble(v, cl, vecs[p0 + 1:p0 + 1 + len(cl)]) if cl else None
                lam[i] = max(lam[i] * mult / 3.0, 1e-8)
                if dec < max(ftol * cost[i], atol):
                    active[i] = False
                cost[i] = c
            else:
                lam[i] *= 100.0
                if lam[i] > 1e8:
                    active[i] = False
    return [(x[i], cost[i], J[i], r[i]) for i in range(n)]


def _jacobian(problem: _Problem, x, ev: _Evaluator):
    r = ev.vectors([problem.jobs(x)])[0]
    pts = []
    for j in range(x.size):
        h = problem.fd[j] if x[j] + problem.fd[j] <= problem.hi[j] else -problem.fd[j]
        xp = x.copy()
        xp[j] += h
        pts.append((j, h, xp))
    vecs = ev.vectors([problem.jobs(xp) for _, _, xp in pts])
    J = np.empty((r.size, x.size))
    for (j, h, _), v in zip(pts, vecs):
        J[:, j] = (v - r) / h
    return J, r


# ============================================================================ fitting models
@dataclass
class _ModelFit:
    """A model (set of effects) fitted to every sample."""
    effects: tuple
    shared: dict                    # key -> internal value
    base: dict                      # sample index -> base vector (log)
    params: dict                    # sample index -> Params
    fit_chi2: dict                  # sample index -> {(test, ch): (chi2, n)}
    heldout: dict | None = None     # sample index -> {(test, ch): (chi2, n)}
    sims: dict | None = None        # sample index -> {test: simulation} (when kept)
    screened: dict | None = None    # set when screened out (see _Context.fit_many)

    def chi2(self, which: str = "fit", samples=None) -> float:
        d = self.fit_chi2 if which == "fit" else self.heldout
        return float(sum(c for i, v in d.items() if samples is None or i in samples for c, _ in v.values()))

    def n(self, which: str = "fit") -> int:
        d = self.fit_chi2 if which == "fit" else self.heldout
        return int(sum(k for v in d.values() for _, k in v.values()))


def _chi2_parts(parts: dict) -> dict:
    return {k: (float(z @ z), int(z.size)) for k, z in parts.items()}


# base parameters re-fitted with each effect (the others keep the baseline's values): the coil
# parameters only move with the effects that change the current
_FREE_BASE = {
    None: BASE_KEYS,
    "coil_heating": BASE_KEYS,
    "motional_emf": BASE_KEYS,
    "filler_saturation": BASE_KEYS,
    "viscoelastic_creep": BASE_KEYS,
    "edge_stiffening": BASE_KEYS,
    "sensor_lag": BASE_KEYS,
}


def _free_mask(effects) -> np.ndarray:
    keys = set(_FREE_BASE[None]) if not effects else set().union(*(_FREE_BASE[e] for e in effects))
    return np.array([k in keys for k in BASE_KEYS])


class _Context:
    def __init__(self, samples, settings):
        self.samples = samples
        self.settings = settings
        self.fit_names = list(settings.fit_tests)
        self.heldout_names = list(settings.heldout_tests)
        self.ev = _Evaluator(samples, self.fit_names, settings)
        idx = [i for i, s in enumerate(samples) if not s.unseen] or list(range(len(samples)))
        k = max(1, min(settings.max_shared_samples, len(idx)))
        if len(samples) >= settings.min_samples_holdout and k == len(samples):
            k = len(samples) - 1          # keep at least one held-out sample
        order = sorted(idx, key=lambda i: (samples[i].diameter_mm, samples[i].wt_pct))
        if k > 1:
            pick = [order[int(round(q * (len(order) - 1) / (k - 1)))] for q in range(k)]
        else:
            pick = [order[len(order) // 2]]
        self.shared_idx = sorted(set(pick))
        self.bounds = {}

    def set_bounds(self, start: dict):
        """Bounds of every sample's base parameters around the paper identification (log vectors)."""
        self.bounds = {i: _base_bounds(b) for i, b in start.items()}

    def shared_problem(self, effects, base: dict, sh: dict):
        """The joint problem of the shared-fit samples: (problem, x) with x = [free base of each, shared]."""
        defs = _shared_defs(effects)
        free = _free_mask(effects)
        nf = int(free.sum())
        S = self.shared_idx
        samples = self.samples
        base = {i: np.asarray(b, dtype=float).copy() for i, b in base.items()}
        x0 = np.concatenate([base[i][free] for i in S] + [np.array([sh[d.key] for d in defs])])
        lo = np.concatenate([self.bounds[i][0][free] for i in S] + [np.array([d.lo for d in defs])])
        hi = np.concatenate([self.bounds[i][1][free] for i in S] + [np.array([d.hi for d in defs])])
        fd = np.concatenate([np.full(nf * len(S), 1e-5), np.array([d.fd for d in defs])])

        def jobs(x):
            shv = {d.key: x[nf * len(S) + k] for k, d in enumerate(defs)}
            out = []
            for j, i in enumerate(S):
                b = base[i].copy()
                b[free] = x[j * nf:(j + 1) * nf]
                out.append((i, _make_params(samples[i], b, shv)))
            return out

        return _Problem(x0, lo, hi, fd, jobs), x0

    def fit_many(self, models, max_iter=None, reference=None) -> list:
        """Fit models [(effects, start_base {i: log base vector}, shared_init {key: value})] in lock-step.

        Shared effect parameters and the samples' free base parameters are fitted jointly on the
        shared-fit samples; then every other sample's free base parameters with the shared ones fixed.
        With a ``reference`` model (the one the candidates extend, started from its optimum with the
        new effects off), a candidate whose fit on the shared-fit samples has not paid for its extra
        parameters (chi-square decrease < k ln n) after ``settings.screen_iter`` iterations is screened
        out: it cannot reach the BIC threshold (its fit is left there and it is not evaluated further).
        """
        st = self.settings
        max_iter = max_iter or st.max_iter
        samples = self.samples
        S = self.shared_idx
        specs = []
        for effects, start_base, shared_init in models:
            defs = _shared_defs(effects)
            free = _free_mask(effects)
            sh0 = {d.key: (shared_init or {}).get(d.key, d.init) for d in defs}
            base = {i: np.asarray(b, dtype=float).copy() for i, b in start_base.items()}
            specs.append(dict(effects=tuple(effects), defs=defs, free=free, nf=int(free.sum()), sh=sh0, base=base,
                              screened=None))
        # 1) shared fits (screening pass first when there is a reference)
        probs, owners = [], []
        for q, sp in enumerate(specs):
            if sp["defs"]:
                prob, _ = self.shared_problem(sp["effects"], sp["base"], sp["sh"])
                probs.append(prob)
                owners.append(q)

        def take(q, x):
            sp = specs[q]
            nf = sp["nf"]
            for j, i in enumerate(S):
                sp["base"][i][sp["free"]] = x[j * nf:(j + 1) * nf]
            sp["sh"] = {d.key: float(x[nf * len(S) + k]) for k, d in enumerate(sp["defs"])}

        if probs and reference is not None and st.screen_iter:
            ref_S = sum(c for i in S for c, _ in reference.fit_chi2[i].values())
            n_all = reference.n("fit")
            res = _lm(probs, self.ev, max_iter=st.screen_iter)
            keep_p, keep_o = [], []
            for q, prob, (x, cost, J, r) in zip(owners, probs, res):
                take(q, x)
                k = len(specs[q]["defs"]) - len(_shared_defs(reference.effects))
                gain = ref_S - cost
                if gain < k * math.log(max(n_all, 2)):
                    specs[q]["screened"] = {"iterations": st.screen_iter, "delta_chi2_shared_samples": gain,
                                            "bic_penalty": k * math.log(max(n_all, 2))}
                else:
                    prob2, _ = self.shared_problem(specs[q]["effects"], specs[q]["base"], specs[q]["sh"])
                    keep_p.append(prob2)
                    keep_o.append(q)
            probs, owners = keep_p, keep_o
        if probs:
            res = _lm(probs, self.ev, max_iter=max_iter)
            for q, (x, cost, J, r) in zip(owners, res):
                take(q, x)
        # 2) per-sample fits of the other samples (of all, for a model without shared parameters)
        probs, owners = [], []
        for q, sp in enumerate(specs):
            if sp["screened"]:
                continue
            for i in range(len(samples)):
                if sp["defs"] and i in S:
                    continue
                free, base, sh = sp["free"], sp["base"], sp["sh"]

                def jobs(x, i=i, free=free, base=base, sh=sh):
                    b = base[i].copy()
                    b[free] = x
                    return [(i, _make_params(samples[i], b, sh))]

                x0 = base[i][free]
                probs.append(_Problem(x0, self.bounds[i][0][free], self.bounds[i][1][free],
                                      np.full(x0.size, 1e-5), jobs))
                owners.append((q, i))
        if probs:
            res = _lm(probs, self.ev, max_iter=max_iter)
            for (q, i), (x, cost, J, r) in zip(owners, res):
                specs[q]["base"][i][specs[q]["free"]] = x
        out, allj = [], []
        n = len(samples)
        for sp in specs:
            sp["params"] = {i: _make_params(samples[i], sp["base"][i], sp["sh"]) for i in range(n)}
            allj += [(i, sp["params"][i]) for i in range(n)]
        parts = self.ev.parts(allj)
        for q, sp in enumerate(specs):
            fit_chi2 = {i: _chi2_parts(parts[q * n + i]) for i in range(n)}
            mf = _ModelFit(effects=sp["effects"], shared=sp["sh"], base=sp["base"], params=sp["params"],
                           fit_chi2=fit_chi2)
            mf.screened = sp["screened"]
            out.append(mf)
        return out

    def shared_uncertainty(self, mf) -> dict:
        """Standard uncertainty of the shared parameters (natural units) from the Jacobian of the shared fit.

        cov = s^2 (J^T J)^-1 over every jointly fitted parameter (the shared-fit samples' base
        parameters included), s^2 = max(1, chi2/dof).
        """
        defs = _shared_defs(mf.effects)
        if not defs:
            return {}
        prob, x = self.shared_problem(mf.effects, mf.base, mf.shared)
        J, r = _jacobian(prob, x, self.ev)
        dof = max(1, r.size - x.size)
        s2 = max(1.0, float(r @ r) / dof)
        cov = s2 * np.linalg.pinv(J.T @ J)
        k0 = x.size - len(defs)
        out = {}
        for k, d in enumerate(defs):
            sd = math.sqrt(max(float(cov[k0 + k, k0 + k]), 0.0))
            out[d.key] = math.exp(mf.shared[d.key]) * sd if d.log else sd
        return out

    def evaluate(self, mfs, names=None, full: bool = True, keep_sims: bool = False):
        """Held-out chi-square of models (lock-step: one simulation batch for all of them).

        Sets ``mf.heldout`` = {sample: {(test, channel): (chi2, n)}} (for ``names`` = the held-out
        tests) and, with ``keep_sims``, ``mf.sims`` = {sample: {test: simulation}}.
        """
        names = list(names or self.heldout_names)
        n = len(self.samples)
        jobs = [(self.samples[i], mf.params[i]) for mf in mfs for i in range(n)]
        sims = _run_jobs(jobs, names, full=full)
        for q, mf in enumerate(mfs):
            held = {}
            for i in range(n):
                parts = _residual_parts(self.samples[i], sims[q * n + i], names, self.settings.sweep_robust_c)
                held[i] = _chi2_parts(parts)
            if names == self.heldout_names:
                mf.heldout = held
            if keep_sims:
                mf.sims = getattr(mf, "sims", None) or {}
                for i in range(n):
                    mf.sims.setdefault(i, {}).update(sims[q * n + i])
        return mfs

    def structure(self, mf) -> dict:
        """Excess chi-square per (test, channel), summed over samples: z = (chi2 - n)/sqrt(2 n)."""
        acc = {}
        for d in (mf.fit_chi2, mf.heldout or {}):
            for i, parts in d.items():
                for k, (c, m) in parts.items():
                    a = acc.setdefault(k, [0.0, 0])
                    a[0] += c
                    a[1] += m
        return {k: (c - m) / math.sqrt(2.0 * m) for k, (c, m) in acc.items() if m > 0}


# ============================================================================ parallel candidate fits
_WORKER_CTX = None


def _fit_and_evaluate(ctx, models, reference=None):
    mfs = ctx.fit_many(models, reference=reference)
    live = [mf for mf in mfs if not getattr(mf, "screened", None)]
    if live:
        ctx.evaluate(live)
    return mfs


def _worker_fit(args):
    models, reference = args
    return _fit_and_evaluate(_WORKER_CTX, models, reference)


def _fit_candidates(ctx, models, workers: int, reference=None):
    """Fit and evaluate models [(effects, start_base, shared_init)], spread over ``workers`` processes."""
    global _WORKER_CTX
    if workers <= 1 or len(models) <= 1:
        return _fit_and_evaluate(ctx, models, reference)
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor
    # two lock-step groups of about equal cost: models with slow states (heating, creep) cost more
    slow = [q for q, m in enumerate(models) if set(m[0]) & {"coil_heating", "viscoelastic_creep"}]
    fast = [q for q in range(len(models)) if q not in slow]
    groups = [[] for _ in range(workers)]
    load = [0.0] * workers
    for q in slow + fast:
        g = int(np.argmin(load))
        groups[g].append(q)
        load[g] += 2.0 if q in slow else 1.0
    groups = [g for g in groups if g]
    _WORKER_CTX = ctx
    ctx_mp = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else mp.get_context()
    try:
        with ProcessPoolExecutor(max_workers=len(groups), mp_context=ctx_mp) as pool:
            futs = [pool.submit(_worker_fit, ([models[q] for q in g], reference)) for g in groups]
            res = [f.result() for f in futs]
    finally:
        _WORKER_CTX = None
    out = [None] * len(models)
    for g, r in zip(groups, res):
        for q, mf in zip(g, r):
            out[q] = mf
    return out


@dataclass(frozen=True)
class DiagnoseSettings:
    """Settings of :func:`diagnose` (see the module docstring for what they mean)."""
    fit_tests: tuple = ("T1", "T3", "T5", "T8")      # tests the fits use
    heldout_tests: tuple = ("T2", "T4", "T6", "T7")  # tests no fit uses: the decision and the gain
    max_shared_samples: int = 4      # samples whose data fit the shared effect parameters
    min_samples_holdout: int = 3     # from this many samples on, at least one is a held-out sample
    max_iter: int = 20               # Levenberg-Marquardt iterations per fit
    fine_s: float = 0.5              # [s] fine steps after each step input, then coarse (fits only)
    sweep_sigma_floor: float = 0.5   # sweep-reading noise at least this x the sensor noise floor
    sweep_robust_c: float = 20.0     # c of the c*asinh(z/c) transform of sweep residuals
    bic_min: float = 10.0            # accept: BIC lower by more than this on the fit data ...
    heldout_min: float = 25.0        # ... and held-out chi-square lower by more than this
    z_struct: float = 5.0            # structure in the residuals: z = (chi2 - n)/sqrt(2n) above this
    workers: int = 2                 # processes for the candidate fits
    max_effects: int = 3             # greedy forward selection stops at this many effects
    screen_iter: int = 3             # iterations before a candidate must have paid for its parameters

    def __post_init__(self):
        for name in ("fit_tests", "heldout_tests"):
            v = tuple(getattr(self, name))
            object.__setattr__(self, name, v)
        both = set(self.fit_tests) & set(self.heldout_tests)
        if both:
            raise ValueError(f"tests {sorted(both)} are both fit and held-out tests")
        for name in ("T3", "T5", "T8"):
            if name not in self.fit_tests:
                raise ValueError(f"fit_tests must contain the identification tests T3, T5, T8 (missing {name})")
        if self.max_shared_samples < 1 or self.max_iter < 1 or self.workers < 1:
            raise ValueError("max_shared_samples, max_iter and workers must be >= 1")


# ============================================================================ paper baseline
def _steady_window(test: _Series, frac: float = 0.5):
    n_post = test.t.size - test.k_on
    k = test.t.size - max(10, int(frac * n_post))
    return slice(k, None)


def _fit_tau(test: _Series, R: float, I0: float = 0.0) -> float:
    """Electrical time constant L/R [s] by least squares of the exact RL response to the measured voltage."""
    from scipy.optimize import least_squares
    from harness.sim.population import zoh_current
    k = test.k_on
    tt, VV, II = test.t[k:], test.V[k:], test.I[k:]

    def res(q):
        return zoh_current(tt, VV, R, R * math.exp(q[0]), I0) - II

    best = min((float(np.sum(res([math.log(t0)]) ** 2)), t0) for t0 in (0.002, 0.005, 0.01, 0.02, 0.05))
    sol = least_squares(res, [math.log(best[1])], method="lm")
    return math.exp(float(sol.x[0]))


def _analytic_baseline(sd: _SampleData):
    """The paper's analytic identification steps (as ``harness.analysis.identify``) for R, L, Em, K1, K2.

    R = V/I over the steady part of T5, L from the T5 current rise, Em from the steady blocked
    force of T8, K1 and K2 from the static balance at the steady displacements of T3 and T5.
    C and m are placeholders here (fitted afterwards). Returns (Params, notes).
    """
    from fmu_src.params import Params
    notes = []
    T3, T5, T8 = (sd.tests.get(n) for n in ("T3", "T5", "T8"))
    if not all(isinstance(t, _Series) for t in (T3, T5, T8)):
        raise ValueError(f"sample {sd.sid}: the diagnosis needs the identification tests T3, T5 and T8")
    w5, w3, w8 = _steady_window(T5), _steady_window(T3), _steady_window(T8)
    R = float(np.mean(T5.V[w5]) / np.mean(T5.I[w5]))
    L = R * _fit_tau(T5, R)
    I3, I5, I8 = (float(np.mean(t.I[w])) for t, w in ((T3, w3), (T5, w5), (T8, w8)))
    x3, x5 = float(np.mean(T3.y[w3])), float(np.mean(T5.y[w5]))
    F8 = float(np.mean(T8.y[w8]))
    G8 = float(_kernel(sd.a, sd.D, sd.kB, T8.r0)(T8.r0))
    Em = F8 / (I8 ** 2 * G8)
    k3 = _kernel(sd.a, sd.D, sd.kB, T3.r0)
    k5 = _kernel(sd.a, sd.D, sd.kB, T5.r0)
    F3 = Em * I3 ** 2 * float(k3(T3.r0 - x3))
    F5 = Em * I5 ** 2 * float(k5(T5.r0 - x5))
    try:
        K1, K2 = np.linalg.solve(np.array([[x3 ** 3, x3], [x5 ** 3, x5]]), [F3, F5])
    except np.linalg.LinAlgError:
        K1, K2 = 0.0, F5 / x5
    if not (K2 > 0):
        notes.append(f"K2 from T3/T5 not positive ({K2:.4g} N/m): linear spring from T5 alone")
        K1, K2 = 0.0, F5 / x5
    if not (K1 >= 0):
        notes.append(f"K1 from T3/T5 negative ({K1:.4g} N/m3): set to 0, K2 from T5")
        K1, K2 = 0.0, F5 / x5
    K1 = max(float(K1), 1.0)
    m = K2 / (2 * math.pi * 15.0) ** 2
    C = 2 * 0.5 * math.sqrt(K2 * m)
    return Params(a=sd.a, D=sd.D, kB=sd.kB, R=R, L=L, Em=Em, K1=K1, K2=float(K2), C=C, m=m), notes


def _paper_baseline(samples, settings) -> tuple:
    """Per sample: analytic R, L, Em, K1, K2 (paper section 3) and C, m by least squares on T3/T5."""
    ev = _Evaluator(samples, ["T3", "T5"], settings)
    start, notes = {}, {}
    for i, sd in enumerate(samples):
        p, nt = _analytic_baseline(sd)
        start[i] = p
        notes[i] = nt
    # coarse grid of (natural frequency, damping ratio), then Levenberg-Marquardt on (log C, log m)
    grid = [(f, z) for f in (4.0, 8.0, 16.0, 32.0, 64.0) for z in (0.25, 0.6, 1.5)]   # f_n [Hz], zeta
    pts = []
    for i, p in start.items():
        for f, z in grid:
            m = p.K2 / (2 * math.pi * f) ** 2
            pts.append((i, p.with_(m=m, C=2 * z * math.sqrt(p.K2 * m))))
    vecs = ev.vectors([[q] for q in pts])
    best = {}
    for (i, p), v in zip(pts, vecs):
        c = float(v @ v)
        if i not in best or c < best[i][0]:
            best[i] = (c, p)
    probs = []
    for i, (c, p) in best.items():
        def jobs(x, p=p, i=i):
            m = math.exp(x[1])
            return [(i, p.with_(C=2.0 * math.exp(x[0]) * math.sqrt(p.K2 * m), m=m))]
        lo, hi = _base_bounds(_base_vector(p))
        x0 = _base_vector(p)[5:]
        probs.append(_Problem(x0, lo[5:], hi[5:], np.full(2, 1e-5), jobs))
    res = _lm(probs, ev, max_iter=settings.max_iter)
    out = {}
    for (i, (c, p)), (x, cost, J, r) in zip(best.items(), res):
        m = math.exp(x[1])
        out[i] = p.with_(C=2.0 * math.exp(x[0]) * math.sqrt(p.K2 * m), m=m)
    return out, notes


# ============================================================================ decision
@dataclass
class _Comparison:
    name: str
    effects: tuple
    k: int                   # extra (shared) parameters
    d_fit: float             # chi2 decrease on the fit data
    d_bic: float             # BIC(candidate) - BIC(reference) on the fit data
    d_heldout: float         # chi2 decrease on the held-out tests
    score: float             # d_heldout - d_bic
    accepted: bool
    reason: str
    shared: dict = field(default_factory=dict)      # natural values of the shared parameters
    shows_in: list = field(default_factory=list)    # [(test, channel, chi2 decrease)] largest first


def _compare(ref: _ModelFit, cand: _ModelFit, settings, n_fit: int, name: str) -> _Comparison:
    k = len(_shared_defs(cand.effects)) - len(_shared_defs(ref.effects))
    if cand.screened:
        sc = cand.screened
        shared = {d.key: _natural(d, cand.shared[d.key]) for d in _shared_defs(cand.effects)}
        return _Comparison(name=name, effects=cand.effects, k=k, d_fit=float("nan"),
                           d_bic=k * math.log(max(n_fit, 2)) - sc["delta_chi2_shared_samples"],
                           d_heldout=float("nan"), score=float("-inf"), accepted=False,
                           reason=(f"screened out after {sc['iterations']} iterations: on the shared-fit samples "
                                   f"the chi-square fell by {sc['delta_chi2_shared_samples']:.4g}, less than the BIC "
                                   f"penalty {sc['bic_penalty']:.4g} of its {k} parameter(s)"),
                           shared=shared, shows_in=[])
    d_fit = ref.chi2("fit") - cand.chi2("fit")
    d_bic = -d_fit + k * math.log(max(n_fit, 2))
    d_ho = ref.chi2("heldout") - cand.chi2("heldout")
    ok_bic = d_bic < -settings.bic_min
    ok_ho = d_ho > settings.heldout_min
    if ok_bic and ok_ho:
        reason = (f"BIC falls by {-d_bic:.4g} (> {settings.bic_min:g}) on the fit data and the held-out "
                  f"chi-square by {d_ho:.4g} (> {settings.heldout_min:g})")
    elif not ok_bic:
        reason = (f"no support on the fit data: BIC changes by {d_bic:+.4g} (needs < -{settings.bic_min:g})")
    else:
        reason = (f"the fit improves (BIC {d_bic:+.4g}) but the held-out tests do not confirm it "
                  f"(held-out chi-square falls by {d_ho:.4g}, needs > {settings.heldout_min:g})")
    shared = {d.key: _natural(d, cand.shared[d.key]) for d in _shared_defs(cand.effects)}
    drop = {}
    for a, b in ((ref.fit_chi2, cand.fit_chi2), (ref.heldout or {}, cand.heldout or {})):
        for i in a:
            for key, (c, _) in a[i].items():
                if i in b and key in b[i]:
                    drop[key] = drop.get(key, 0.0) + c - b[i][key][0]
    shows = sorted(((t, ch, float(v)) for (t, ch), v in drop.items() if v > settings.heldout_min),
                   key=lambda q: -q[2])
    return _Comparison(name=name, effects=cand.effects, k=k, d_fit=d_fit, d_bic=d_bic, d_heldout=d_ho,
                       score=d_ho - d_bic, accepted=ok_bic and ok_ho, reason=reason, shared=shared, shows_in=shows)


# ============================================================================ result
@dataclass
class Diagnosis:
    """Result of :func:`diagnose` (see :func:`diagnosis_to_json` for the JSON layout)."""
    cause: str
    causes: list
    candidates: dict
    rounds: list
    effect_parameters: dict
    gain: dict
    evidence: dict
    decision: dict
    synthetic: bool
    samples: list                       # [{"id", "wt_pct", "diameter_mm", "role"}]
    extended_params: dict               # sample id -> Params (final model)
    baseline_params: dict               # sample id -> Params (paper identification)
    refit_params: dict                  # sample id -> Params (paper model, least squares on the fit tests)
    effects: tuple
    timing_s: dict
    traces: dict = field(default_factory=dict, repr=False)   # sample id -> test -> arrays (figures)
    records_before: list = field(default_factory=list, repr=False)
    records_after: list = field(default_factory=list, repr=False)
    settings: "DiagnoseSettings | None" = None


def _full_traces(sd: _SampleData, sims: dict) -> dict:
    """Simulated signals on the measured grids: {test: {"x": t or gap, "y_meas", "y_sim", "I_meas", "I_sim"}}."""
    out = {}
    for name, s in sims.items():
        test = sd.tests[name]
        if s[0] == "sweep":
            out[name] = dict(kind="sweep", x=test.gaps * 1e3, y_meas=test.y, y_sim=s[2], I_meas=test.I, I_sim=s[1],
                             blocked=test.blocked)
            continue
        _, tl, Is, ys = s
        idx = test.k_on + np.rint(tl / test.dt).astype(np.intp)
        ok = idx < test.t.size
        yf = np.zeros(test.t.size)
        If = np.zeros(test.t.size)
        yf[idx[ok]] = ys[ok]
        If[idx[ok]] = Is[ok]
        # points the output grid skipped (coarse part) are interpolated
        have = np.zeros(test.t.size, dtype=bool)
        have[idx[ok]] = True
        have[:test.k_on] = True
        if not have.all():
            k = np.flatnonzero(have)
            miss = np.flatnonzero(~have)
            yf[miss] = np.interp(miss, k, yf[k])
            If[miss] = np.interp(miss, k, If[k])
        out[name] = dict(kind="series", x=test.t, y_meas=test.y, y_sim=yf, I_meas=test.I, I_sim=If,
                         blocked=test.blocked)
    return out


def _rmse_parts(sd: _SampleData, traces: dict, names) -> dict:
    """{test: {"y": RMSE [mm or N], "I": RMSE [A], "y_norm": RMSE / sensor floor, "I_norm": ...}}."""
    out = {}
    for name in names:
        if name not in traces:
            continue
        tr = traces[name]
        test = sd.tests[name]
        ry = float(np.sqrt(np.mean((tr["y_meas"] - tr["y_sim"]) ** 2)))
        rI = float(np.sqrt(np.mean((tr["I_meas"] - tr["I_sim"]) ** 2)))
        fy = test.floor_y if tr["kind"] == "sweep" else test.sig_y
        fI = test.floor_I if tr["kind"] == "sweep" else test.sig_I
        scale = 1.0 if tr["blocked"] else 1e3
        out[name] = {"y": ry * scale, "I": rI, "y_norm": ry / fy, "I_norm": rI / fI,
                     "y_unit": "N" if tr["blocked"] else "mm"}
    return out


# ============================================================================ evidence features
def _post(test: _Series, t0: float, t1: float):
    """Index mask of the samples t0 <= t - t_on < t1 (seconds after the input onset)."""
    tl = test.t - test.t[test.k_on]
    return (tl >= t0) & (tl < t1)


def _combine_z(zs) -> float:
    zs = [z for z in zs if math.isfinite(z)]
    return float(sum(zs) / math.sqrt(len(zs))) if zs else float("nan")


def _features(samples, traces: dict) -> dict:
    """Residual features of the paper model, each normalized by the sensor noise (z = value / its noise std).

    traces: {sample index: {test: trace}} of the paper baseline on every test.
    """
    feats = {}

    # 1) current droop during the holds (coil heating: R rises, the current falls)
    per, zs = {}, []
    for i, sd in enumerate(samples):
        for name in ("T5", "T8"):
            t = sd.tests.get(name)
            if not isinstance(t, _Series) or t.V_on is None:
                continue
            e, l_ = _post(t, 0.3, 1.3), _post(t, t.t[-1] - t.t[t.k_on] - 1.0, 1e9)
            Ie, Il = float(np.mean(t.I[e])), float(np.mean(t.I[l_]))
            z = (Il - Ie) / (t.sig_I * math.sqrt(1.0 / e.sum() + 1.0 / l_.sum()))
            per.setdefault(sd.sid, {})[name] = {"early_A": Ie, "late_A": Il, "change_pct": 100 * (Il - Ie) / Ie,
                                                "z": z}
            zs.append(z)
    feats["current_drift"] = {
        "points_to": "coil_heating", "tests": ["T5", "T8"], "signal": "current",
        "description": "measured current in the last second of the hold minus its mean 0.3-1.3 s after the step "
                       "(steady voltage: the paper's RL coil keeps it constant; a heating coil lets it fall)",
        "z": _combine_z(zs), "per_sample": per}

    # 2) displacement drift at steady current (creep: rises; heating: falls with the current)
    per, zs = {}, []
    for i, sd in enumerate(samples):
        for name in ("T3", "T5"):
            t = sd.tests.get(name)
            tr = traces.get(i, {}).get(name)
            if not isinstance(t, _Series) or tr is None or t.V_on is None:
                continue
            m, l_ = _post(t, 0.5, 1.5), _post(t, t.t[-1] - t.t[t.k_on] - 1.0, 1e9)
            dm = float(np.mean(t.y[l_]) - np.mean(t.y[m]))
            ds_ = float(np.mean(tr["y_sim"][l_]) - np.mean(tr["y_sim"][m]))
            z = (dm - ds_) / (t.sig_y * math.sqrt(1.0 / m.sum() + 1.0 / l_.sum()))
            per.setdefault(sd.sid, {})[name] = {"measured_drift_um": dm * 1e6, "model_drift_um": ds_ * 1e6, "z": z}
            zs.append(z)
    feats["displacement_drift"] = {
        "points_to": "viscoelastic_creep (rising) or coil_heating (falling, with the current)",
        "tests": ["T3", "T5"], "signal": "displacement",
        "description": "displacement drift from 0.5-1.5 s to the last second after the step, measured minus "
                       "the paper model's (positive: keeps creeping toward the coil at steady current)",
        "z": _combine_z(zs), "per_sample": per}

    # 3) field dependence: steady residual across T2-T5 vs I^2, and the blocked force per I^2 during the rise
    per, zs, zq = {}, [], []
    for i, sd in enumerate(samples):
        row = {}
        for name in ("T2", "T3", "T4", "T5"):
            t = sd.tests.get(name)
            tr = traces.get(i, {}).get(name)
            if not isinstance(t, _Series) or tr is None:
                continue
            w = _steady_window(t)
            r = float(np.mean(t.y[w] - tr["y_sim"][w]))
            z = r / (t.sig_y / math.sqrt(t.y[w].size))
            row[name] = {"steady_residual_um": r * 1e6, "relative_pct": 100 * r / max(abs(float(np.mean(tr["y_sim"][w]))), 1e-12),
                         "current_A": float(np.mean(t.I[w])), "z": z}
            if name in ("T2", "T4"):
                zs.append(z)
        t8 = sd.tests.get("T8")
        if isinstance(t8, _Series) and t8.V_on is not None:
            w = _steady_window(t8)
            Iss = float(np.mean(t8.I[w]))
            rise = _post(t8, 0.0, 0.5) & (t8.I > 0.5 * Iss) & (t8.I < 0.9 * Iss)
            if rise.sum() >= 5:
                q_r = float(np.mean(t8.y[rise] / t8.I[rise] ** 2))
                q_s = float(np.mean(t8.y[w]) / Iss ** 2)
                se = t8.sig_y / math.sqrt(rise.sum()) / float(np.mean(t8.I[rise] ** 2))
                row["T8_force_per_I2"] = {"rise_N_per_A2": q_r, "steady_N_per_A2": q_s,
                                          "change_pct": 100 * (q_r - q_s) / q_s, "z": (q_r - q_s) / se}
                zq.append((q_r - q_s) / se)
        per[sd.sid] = row
    feats["field_dependence"] = {
        "points_to": "filler_saturation (force per I^2 higher at low current)",
        "tests": ["T2", "T3", "T4", "T5", "T8"], "signal": "displacement, blocked force",
        "description": "steady displacement residual of T2-T5 (the paper model is fitted at T3 and T5: T2 and "
                       "T4 show a wrong field law) and the blocked force per I^2 during the T8 current rise "
                       "(50-90 % of steady) relative to its steady value (saturation: higher while I is low; "
                       "a lagging sensor: lower)",
        "z": math.sqrt(float(np.mean(np.square(zs)))) if zs else float("nan"),
        "z_note": "root mean square of the T2/T4 steady-residual z values (about 1 for noise)",
        "z_force_per_I2": _combine_z(zq), "per_sample": per}

    # 4) deflection dependence: T1 residual at the largest free deflections
    per, zs = {}, []
    for i, sd in enumerate(samples):
        t = sd.tests.get("T1")
        tr = traces.get(i, {}).get("T1")
        if not isinstance(t, _Sweep) or tr is None:
            continue
        free = (t.y < 0.95 * t.gaps) & (t.gaps > 0)
        sim_free = (tr["y_sim"] < 0.95 * t.gaps) & (t.gaps > 0)
        both = free & sim_free
        if both.sum() < 4:
            continue
        order = np.argsort(t.y[both])
        r = (t.y - tr["y_sim"])[both]
        big, small = r[order[-3:]], r[order[: max(1, len(order) // 2)]]
        val = float(np.mean(big) - np.mean(small))
        z = val / (t.sig_y * math.sqrt(1.0 / big.size + 1.0 / small.size))
        per[sd.sid] = {"residual_at_max_deflection_um": float(np.mean(big)) * 1e6,
                       "residual_at_small_deflection_um": float(np.mean(small)) * 1e6,
                       "contact_mismatch_gaps_mm": [float(g) for g in t.gaps[free != sim_free] * 1e3], "z": z}
        zs.append(z)
    feats["deflection_dependence"] = {
        "points_to": "edge_stiffening (negative: too little deflection at large deflection)",
        "tests": ["T1"], "signal": "displacement",
        "description": "T1 residual at the three largest free deflections minus at the smaller half "
                       "(in units of the noise of a sweep reading), and gaps where measured and simulated "
                       "pull-in disagree",
        "z": _combine_z(zs), "per_sample": per}

    # 5) current residual correlated with the motion (motional EMF), inductance by gap
    per, zs = {}, []
    for i, sd in enumerate(samples):
        row = {}
        num = den = 0.0
        sig = None
        for name in ("T2", "T3", "T4", "T5"):
            t = sd.tests.get(name)
            tr = traces.get(i, {}).get(name)
            if not isinstance(t, _Series) or tr is None:
                continue
            k = 5
            xs = np.convolve(t.y, np.ones(2 * k + 1) / (2 * k + 1), mode="same")
            v = np.gradient(xs, t.t)
            r = t.r0 - xs
            a = sd.a
            p = t.I * v * fx.inductance_gradient(1.0, 1.0, a, r) / 3.0    # I*v*dL/dx / (3*L*lam)
            sel = _post(t, 0.0, 1.0)
            res = (t.I - tr["I_sim"])[sel]
            num += float(np.sum(res * p[sel]))
            den += float(np.sum(p[sel] ** 2))
            sig = t.sig_I
        if den > 0:
            b = num / den
            z = b / (sig / math.sqrt(den))
            row["coefficient"] = -b
            row["z"] = -z
            zs.append(-z)
        t5, t8 = sd.tests.get("T5"), sd.tests.get("T8")
        if isinstance(t5, _Series) and isinstance(t8, _Series) and t5.V_on and t8.V_on:
            R5 = float(np.mean(t5.V[_steady_window(t5)]) / np.mean(t5.I[_steady_window(t5)]))
            R8 = float(np.mean(t8.V[_steady_window(t8)]) / np.mean(t8.I[_steady_window(t8)]))
            L5 = R5 * _fit_tau(t5, R5)
            L8 = R8 * _fit_tau(t8, R8)
            row["L_T5_H"], row["L_T8_H"] = L5, L8
            row["L_change_pct"] = 100 * (L8 - L5) / L5
        per[sd.sid] = row
    feats["motion_current"] = {
        "points_to": "motional_emf", "tests": ["T2", "T3", "T4", "T5", "T8"], "signal": "current",
        "description": "regression of the current residual (first second after the step) on "
                       "I*v*a^3*r/(a^2+r^2)^2.5 (the back-EMF shape, v from the measured displacement; positive = "
                       "current dips while the diaphragm moves toward the coil), and the inductance fitted "
                       "to the T8 current (2 mm gap) relative to T5's (a gap-dependent inductance)",
        "z": _combine_z(zs), "per_sample": per}

    # 6) time shift of the sensor readings
    per, zs = {}, []
    for i, sd in enumerate(samples):
        row = {}
        for name in ("T8", "T5"):
            t = sd.tests.get(name)
            tr = traces.get(i, {}).get(name)
            if not isinstance(t, _Series) or tr is None or t.V_on is None:
                continue
            sel = _post(t, 0.0, 0.3)
            w = _steady_window(t)
            if name == "T8":
                # a blocked force follows I^2 at once (F = Em G(gap) I^2): the reference is the steady force
                # scaled by (I/I_steady)^2 with I the RL response fitted to T8's own current, so a slow
                # current (inductance by gap, motional EMF) does not count as a delay
                from harness.sim.population import zoh_current
                R8 = float(np.mean(t.V[w]) / np.mean(t.I[w]))
                Ifit = zoh_current(t.t, t.V, R8, R8 * _fit_tau(t, R8))
                ref = float(np.mean(t.y[w])) * (Ifit / float(np.mean(Ifit[w]))) ** 2
                what = "steady force x (I/I_steady)^2, I fitted to the T8 current"
            else:
                ref = tr["y_sim"]
                what = "paper model"
            yd = np.gradient(ref, t.t)[sel]
            r = (t.y - ref)[sel]
            den = float(np.sum(yd ** 2))
            if den <= 0:
                continue
            tau = -float(np.sum(r * yd)) / den
            z = tau / (t.sig_y / math.sqrt(den))
            row[name] = {"delay_ms": tau * 1e3, "z": z, "reference": what,
                         "steady_residual_rel_pct": 100 * float(np.mean(t.y[w] - tr["y_sim"][w]))
                         / max(abs(float(np.mean(tr["y_sim"][w]))), 1e-12)}
            if name == "T8":
                zs.append(z)
        per[sd.sid] = row
    feats["time_shift"] = {
        "points_to": "sensor_lag (positive delay of the reading; the current is not delayed)",
        "tests": ["T8", "T5"], "signal": "blocked force, displacement",
        "description": "delay of the reading in the first 0.3 s after the step, by least squares "
                       "(residual = -delay * d(reference)/dt): T8 against its steady force scaled by (I/I_steady)^2 "
                       "of the RL response fitted to its own current (a blocked force needs no mechanics, so a "
                       "delay there is the sensor's; z is T8's), T5 against the paper model",
        "z": _combine_z(zs), "per_sample": per}
    return feats


# ============================================================================ main entry
def diagnose(dataset, settings: "DiagnoseSettings | None" = None, progress: bool = False) -> Diagnosis:
    """Diagnose which catalogued effect (if any) the paper's model misses in ``dataset``.

    Runs blind: it reads the measured tests and the rig description (coil radius, field per
    ampere, sensor noise), never ``rig.effects`` or ``rig.true_parameters``. See the module
    docstring for the procedure and the decision rule.
    """
    import time
    st = settings or DiagnoseSettings()
    T0 = time.perf_counter()
    timing = {}

    def lap(name, t=[T0]):
        now = time.perf_counter()
        timing[name] = round(now - t[0], 3)
        t[0] = now
        if progress:
            print(f"[diagnose] {name}: {timing[name]:.1f} s", flush=True)

    samples = _prepare(dataset, st)
    n = len(samples)
    if n == 0:
        raise ValueError("the dataset has no samples")
    paper, notes = _paper_baseline(samples, st)
    lap("paper_identification")
    ctx = _Context(samples, st)
    paper_mf = _ModelFit(effects=(), shared={}, base={i: _base_vector(p) for i, p in paper.items()},
                         params=dict(paper), fit_chi2={})
    paper_mf.fit_chi2 = {i: _chi2_parts(pp) for i, pp in
                         enumerate(ctx.ev.parts([(i, paper[i]) for i in range(n)]))}
    ctx.set_bounds(paper_mf.base)
    base = ctx.fit_many([((), paper_mf.base, None)])[0]
    ctx.evaluate([paper_mf, base])
    lap("baseline_refit")
    n_fit = base.n("fit")
    # round 1: every candidate on its own, against the refitted paper model
    fits = _fit_candidates(ctx, [((c,), base.base, _off_init((c,))) for c in CANDIDATES], st.workers,
                           reference=base)
    comps = [_compare(base, mf, st, n_fit, c) for c, mf in zip(CANDIDATES, fits)]
    lap("candidates")
    rounds = [{"reference": [], "comparisons": comps}]
    current, chosen = base, []
    acc = sorted([q for q, c in enumerate(comps) if c.accepted], key=lambda q: -comps[q].score)
    if acc:
        current = fits[acc[0]]
        chosen.append(comps[acc[0]])
        # greedy forward selection while the selected model still leaves structure
        while len(chosen) < st.max_effects and max(ctx.structure(current).values()) > st.z_struct:
            others = [c for c in CANDIDATES if c not in current.effects]
            if not others:
                break
            f2 = _fit_candidates(ctx, [(current.effects + (c,), current.base,
                                        dict(_off_init((c,)), **current.shared)) for c in others],
                                 st.workers, reference=current)
            c2 = [_compare(current, mf, st, n_fit, c) for c, mf in zip(others, f2)]
            rounds.append({"reference": list(current.effects), "comparisons": c2})
            a2 = sorted([q for q, c in enumerate(c2) if c.accepted], key=lambda q: -c2[q].score)
            if not a2:
                break
            current = f2[a2[0]]
            chosen.append(c2[a2[0]])
        lap("greedy")
    z_base = ctx.structure(base)
    z_final = ctx.structure(current)
    if chosen:
        cause = chosen[0].name
    else:
        cause = "unexplained" if max(z_base.values()) > st.z_struct else "none"
    unc = ctx.shared_uncertainty(current) if current.effects else {}
    lap("uncertainty")
    # simulations of every test for the figures, tables, features and gains
    all_names = sorted({nm for sd in samples for nm in sd.tests})
    ctx.evaluate([paper_mf, base, current] if current is not base else [paper_mf, base], names=all_names,
                 full=True, keep_sims=True)
    traces = {m: {i: _full_traces(samples[i], mf.sims[i]) for i in range(n)}
              for m, mf in (("paper", paper_mf), ("refit", base), ("final", current))}
    feats = _features(samples, traces["paper"])
    lap("evidence")
    return _assemble(dataset, st, samples, ctx, paper_mf, base, current, comps, rounds, chosen, cause, unc,
                     z_base, z_final, traces, feats, notes, timing, T0)


_CHANNEL = {"y": "reading", "I": "current"}


def _f(x):
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _signal_name(sd: _SampleData, test: str, ch: str) -> str:
    t = sd.tests.get(test)
    if ch == "I":
        return "current"
    return "blocked force" if getattr(t, "blocked", False) else "displacement"


def _gain_block(samples, traces_by_model: dict, names, idx) -> dict:
    """RMSE per test (pooled over the samples idx) for each model, and the overall normalized RMSE."""
    out = {"per_test": {}, "overall_normalized_rmse": {}}
    norms = {m: [] for m in traces_by_model}
    for name in names:
        entry = {}
        have = False
        for m, tr in traces_by_model.items():
            vals = [_rmse_parts(samples[i], tr[i], [name]).get(name) for i in idx]
            vals = [v for v in vals if v]
            if not vals:
                continue
            have = True
            unit = vals[0]["y_unit"]
            sig = "blocked_force" if unit == "N" else "displacement"
            ky, kI = f"{sig}_rmse_{unit}", "current_rmse_A"
            entry.setdefault(ky, {})[m] = math.sqrt(float(np.mean([v["y"] ** 2 for v in vals])))
            entry.setdefault(kI, {})[m] = math.sqrt(float(np.mean([v["I"] ** 2 for v in vals])))
            entry.setdefault(f"{sig}_rmse_per_noise_floor", {})[m] = math.sqrt(
                float(np.mean([v["y_norm"] ** 2 for v in vals])))
            entry.setdefault("current_rmse_per_noise_floor", {})[m] = math.sqrt(
                float(np.mean([v["I_norm"] ** 2 for v in vals])))
            norms[m] += [v["y_norm"] ** 2 for v in vals] + [v["I_norm"] ** 2 for v in vals]
        if have:
            out["per_test"][name] = entry
    for m, v in norms.items():
        out["overall_normalized_rmse"][m] = math.sqrt(float(np.mean(v))) if v else None
    b, a = out["overall_normalized_rmse"].get("before"), out["overall_normalized_rmse"].get("after")
    out["overall_normalized_rmse"]["after_over_before"] = (a / b) if a is not None and b else None
    return out


def _records(samples, traces: dict) -> list:
    """Per-sample, per-test metric records (harness.report.tables layout) from full traces."""
    from harness.analysis import metrics
    recs = []
    for i, sd in enumerate(samples):
        for name, tr in sorted(traces[i].items()):
            test = sd.tests[name]
            rec = {"sample": sd.sid, "wt_pct": sd.wt_pct, "diameter_mm": sd.diameter_mm, "test": name}
            unit = "N" if tr["blocked"] else "mm"
            scale = 1.0 if tr["blocked"] else 1e3
            ym, ys = tr["y_meas"] * scale, tr["y_sim"] * scale
            if tr["kind"] == "sweep":
                rec[f"rmse_{unit}"] = float(np.sqrt(np.mean((ym - ys) ** 2)))
            elif test.frequency_hz:
                try:
                    rec.update(metrics.sine_metrics(test.t, ym, ys, float(test.frequency_hz), unit=unit))
                except ValueError:
                    rec[f"rmse_{unit}"] = float(np.sqrt(np.mean((ym - ys) ** 2)))
            else:
                try:
                    rec.update(metrics.step_metrics(test.t, ym, ys, t_step=float(test.t[test.k_on]),
                                                    noise_sigma=test.sig_y * scale, unit=unit))
                except ValueError:
                    rec[f"rmse_{unit}"] = float(np.sqrt(np.mean((ym - ys) ** 2)))
            rec["current_rmse_A"] = float(np.sqrt(np.mean((tr["I_meas"] - tr["I_sim"]) ** 2)))
            recs.append(rec)
    return recs


def _assemble(dataset, st, samples, ctx, paper_mf, base, current, comps, rounds, chosen, cause, unc,
              z_base, z_final, traces, feats, notes, timing, T0) -> Diagnosis:
    import time
    n = len(samples)
    S = set(ctx.shared_idx)
    roles = {i: ("shared fit" if i in S else "held-out sample") for i in range(n)}
    # effect parameters (shared ones with uncertainty; per-sample derived values)
    eff = {}
    for d in _shared_defs(current.effects):
        eff[_ukey(d.key, d.unit)] = {"value": _f(_natural(d, current.shared[d.key])), "std": _f(unc.get(d.key)),
                                     "effect": d.effect, "description": d.description}
    per_sample = {}
    from fmu_src.effects import EFFECTS, EFFECT_SPEC_BY_NAME
    for i, sd in enumerate(samples):
        p = current.params[i]
        per_sample[sd.sid] = {_ukey(k, EFFECT_SPEC_BY_NAME[k].unit): float(getattr(p, k))
                              for e in current.effects for k in EFFECTS[e].params}
    if eff:
        eff["per_sample"] = per_sample
    # gains
    tb = {"before": traces["paper"], "refit": traces["refit"], "after": traces["final"]}
    held = [nm for nm in st.heldout_tests if any(nm in samples[i].tests for i in range(n))]
    fitn = [nm for nm in st.fit_tests if any(nm in samples[i].tests for i in range(n))]
    gain = _gain_block(samples, tb, held, list(range(n)))
    gain["heldout_tests"] = held
    gain["models"] = {"before": "paper model, identified as in the paper (analytic R, L, Em, K1, K2 from T3, T5, "
                                "T8; C, m by least squares on T3/T5)",
                      "refit": "paper model re-fitted by least squares on the fit tests",
                      "after": "extended model " + ("+".join(current.effects) if current.effects else
                                                    "(no effect selected: the refitted paper model)")}
    hs = [i for i in range(n) if roles[i] == "held-out sample"]
    if hs:
        gain["heldout_samples"] = dict(_gain_block(samples, tb, held + fitn, hs),
                                       samples=[samples[i].sid for i in hs])
    gain["fit_tests"] = _gain_block(samples, tb, fitn, list(range(n)))
    fl = _noise_floors(dataset)
    gain["noise_floors"] = {"displacement_mm": fl["displacement_mm"], "force_N": fl["force_N"],
                            "current_A": fl["current_A"]}
    gain["per_sample"] = {samples[i].sid: dict(role=roles[i], **_gain_block(samples, tb, held, [i])["overall_normalized_rmse"])
                          for i in range(n)}

    def comp_json(c: _Comparison):
        return {"effects": list(c.effects), "extra_parameters": c.k, "delta_chi2_fit": _f(c.d_fit),
                "delta_bic": _f(c.d_bic), "delta_chi2_heldout": _f(c.d_heldout), "score": _f(c.score),
                "accepted": bool(c.accepted), "reason": c.reason,
                "shared_parameters": {_ukey(d.key, d.unit): _f(c.shared.get(d.key)) for d in _shared_defs(c.effects)},
                "shows_in": [{"test": t, "signal": _signal_name(samples[0], t, ch), "delta_chi2": _f(v)}
                             for t, ch, v in c.shows_in[:6]]}

    candidates = {c.name: comp_json(c) for c in comps}
    causes = []
    for r, c in enumerate(chosen, 1):
        cj = comp_json(c)
        causes.append({"name": c.name, "rank": r, "score": cj["score"], "delta_bic": cj["delta_bic"],
                       "delta_chi2_heldout": cj["delta_chi2_heldout"], "reason": c.reason,
                       "shows_in": cj["shows_in"], "evidence_features": [k for k, v in feats.items()
                                                                         if c.name in v["points_to"]]})
    zb = {f"{t}_{_CHANNEL[ch]}": _f(v) for (t, ch), v in sorted(z_base.items())}
    zf = {f"{t}_{_CHANNEL[ch]}": _f(v) for (t, ch), v in sorted(z_final.items())}
    remaining = [k for k, v in zf.items() if v is not None and v > st.z_struct]
    evidence = {"features": feats, "baseline_structure_z": zb, "final_structure_z": zf,
                "remaining_structure": remaining,
                "structure_note": "z = (chi2 - n)/sqrt(2 n) of the refitted model's residuals per test and signal, "
                                  "summed over samples (about N(0,1) for pure noise)"}
    decision = {
        "rule": ("Each candidate is fitted (shared effect parameters + every sample's base parameters) on the fit "
                 "tests and accepted when its BIC on the fit data is lower than the refitted paper model's by more "
                 f"than {st.bic_min:g} AND its chi-square on the held-out tests (never fitted) is lower by more than "
                 f"{st.heldout_min:g}; the accepted candidate with the largest score = held-out chi-square "
                 "decrease - BIC change is taken, then each remaining candidate is added to it in turn (greedy "
                 "forward selection) while the selected model's residuals still show structure "
                 f"(z > {st.z_struct:g}). No candidate accepted: 'none' if the refitted paper model's residuals "
                 f"are noise (every z <= {st.z_struct:g}), else 'unexplained'."),
        "thresholds": {"bic_min": st.bic_min, "heldout_chi2_min": st.heldout_min, "structure_z": st.z_struct,
                       "max_effects": st.max_effects},
        "fit_tests": fitn, "heldout_tests": held,
        "shared_fit_samples": [samples[i].sid for i in sorted(S)],
        "heldout_samples": [samples[i].sid for i in hs],
        "n_fit_residuals": base.n("fit"),
        "noise_model": ("time series: white noise at the sensor noise floor; sweep readings (T1/T7, means over "
                        f"the last averaging window of each hold): floor/sqrt(n) but at least {st.sweep_sigma_floor:g} "
                        f"x floor, residuals passed through c*asinh(z/c), c = {st.sweep_robust_c:g} (a pull-in "
                        "mismatch at one gap must not outweigh everything else)"),
        "rounds": [{"reference": r["reference"], "candidates": {c.name: comp_json(c) for c in r["comparisons"]}}
                   for r in rounds],
    }
    sids = [sd.sid for sd in samples]
    timing["total"] = round(time.perf_counter() - T0, 3)
    diag = Diagnosis(
        cause=cause, causes=causes, candidates=candidates, rounds=rounds, effect_parameters=eff, gain=gain,
        evidence=evidence, decision=decision, synthetic=bool(getattr(dataset, "synthetic", False)),
        samples=[{"id": sd.sid, "wt_pct": sd.wt_pct, "diameter_mm": sd.diameter_mm, "role": roles[i]}
                 for i, sd in enumerate(samples)],
        extended_params={sids[i]: current.params[i] for i in range(n)},
        baseline_params={sids[i]: paper_mf.params[i] for i in range(n)},
        refit_params={sids[i]: base.params[i] for i in range(n)},
        effects=tuple(current.effects), timing_s=timing,
        traces={sids[i]: {"before": traces["paper"][i], "after": traces["final"][i]} for i in range(n)},
        records_before=_records(samples, traces["paper"]), records_after=_records(samples, traces["final"]),
        settings=st)
    diag.evidence["baseline_notes"] = {sids[i]: notes[i] for i in range(n) if notes[i]}
    return diag


# ============================================================================ output
def _jsonable(o):
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, (np.floating, float)):
        return _f(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, np.ndarray):
        return [_jsonable(v) for v in o.tolist()]
    return o


def diagnosis_to_json(diag: Diagnosis) -> dict:
    """diagnosis.json as a dict (layout: see the module docstring)."""
    st = diag.settings or DiagnoseSettings()
    return _jsonable({
        "format": "mpc-actuator-diagnosis/1",
        "synthetic": diag.synthetic,
        "cause": diag.cause,
        "causes": diag.causes,
        "effects": list(diag.effects),
        "effect_parameters": diag.effect_parameters,
        "gain": diag.gain,
        "candidates": diag.candidates,
        "evidence": diag.evidence,
        "decision": diag.decision,
        "samples": diag.samples,
        "parameters": {
            "extended": {sid: params_to_json(p) for sid, p in diag.extended_params.items()},
            "paper_identification": {sid: params_to_json(p) for sid, p in diag.baseline_params.items()},
            "paper_refit": {sid: params_to_json(p) for sid, p in diag.refit_params.items()},
        },
        "settings": {k: (list(v) if isinstance(v, tuple) else v) for k, v in st.__dict__.items()},
        "timing_s": diag.timing_s,
    })


def extended_params_json(diag: Diagnosis) -> dict:
    """extended_params.json: every sample's parameters (paper + effect parameters, unit keys)."""
    std = {k: v.get("std") for k, v in diag.effect_parameters.items() if k != "per_sample"}
    return _jsonable({
        "format": "mpc-actuator-params/1",
        "synthetic": diag.synthetic,
        "source": "harness.analysis.diagnose",
        "cause": diag.cause,
        "effects": list(diag.effects),
        "note": ("SI parameters per sample with the unit in every key; the gap r0 is a per-test setting and "
                 "not stored; effect parameters are 0 when the effect is off. fmu_src.params names: the key "
                 "up to the first underscore-unit suffix (harness.data.rig.params_from_json reads this layout)."),
        "shared_effect_parameters": {k: v for k, v in diag.effect_parameters.items() if k != "per_sample"},
        "samples": {sid: {"wt_pct": s["wt_pct"], "diameter_mm": s["diameter_mm"], "role": s["role"],
                          "parameters": params_to_json(diag.extended_params[sid])}
                    for sid, s in ((s["id"], s) for s in diag.samples)},
        "shared_effect_parameter_std": std,
    })


def _fmt(v, digits=4):
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, float, np.floating)):
        if not math.isfinite(v):
            return "–"
        return f"{v:.{digits}g}"
    return str(v)


def _md_table(header, rows) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(_fmt(c) if not isinstance(c, str) else c for c in r) + " |" for r in rows]
    return "\n".join(out)


def _residual_figure(path, sid, tr: dict, effects) -> Path:
    from harness.report import figures
    before, after = tr["before"], tr["after"]
    res_b, res_a, units = {}, {}, {}
    for name in sorted(before):
        b, a = before[name], after[name]
        scale = 1.0 if b["blocked"] else 1e3
        res_b[name] = (b["x"], (b["y_meas"] - b["y_sim"]) * scale)
        res_a[name] = (a["x"], (a["y_meas"] - a["y_sim"]) * scale)
        units[name] = "N" if b["blocked"] else "mm"
    for name in ("T5", "T8"):
        if name in before and before[name]["kind"] == "series":
            b, a = before[name], after[name]
            key = f"{name} current"
            res_b[key] = (b["x"], (b["I_meas"] - b["I_sim"]) * 1e3)
            res_a[key] = (a["x"], (a["I_meas"] - a["I_sim"]) * 1e3)
            units[key] = "mA"
    label = "+".join(effects) if effects else "no effect (refitted paper model)"
    return figures.plot_residuals(path, res_b, res_a, units=units,
                                title=f"{sid}: residuals measured - simulated, paper model (before) and {label} (after)")


def write_diagnosis(diag: Diagnosis, out_dir, max_figures: int | None = None) -> list:
    """Write diagnosis.json, diagnosis.md (with residual figures), extended_params.json and the
    paper-style tables of the baseline and the extended model to ``out_dir``; returns the paths."""
    import json
    from harness.report import tables
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    data = diagnosis_to_json(diag)
    p = out / "diagnosis.json"
    p.write_text(json.dumps(data, indent=2, allow_nan=False) + "\n")
    written.append(p)
    p = out / "extended_params.json"
    p.write_text(json.dumps(extended_params_json(diag), indent=2, allow_nan=False) + "\n")
    written.append(p)
    tdir = out / "tables"
    written += tables.write_tables(diag.records_after, tdir, "extended")
    written += tables.write_tables(diag.records_before, tdir, "paper_model")
    fdir = out / "figures"
    fdir.mkdir(exist_ok=True)
    figs = []
    order = [s["id"] for s in diag.samples if s["role"] == "shared fit"] + \
            [s["id"] for s in diag.samples if s["role"] != "shared fit"]
    for sid in order[: (len(order) if max_figures is None else max_figures)]:
        f = _residual_figure(fdir / f"residuals_{sid}.png", sid, diag.traces[sid], diag.effects)
        figs.append((sid, f))
        written.append(f)
    p = out / "diagnosis.md"
    p.write_text(_markdown(diag, data, figs, out))
    written.append(p)
    return written


def _markdown(diag: Diagnosis, data: dict, figs, out: Path) -> str:
    st = diag.settings or DiagnoseSettings()
    L = []
    L.append("# Model-error diagnosis")
    L.append("")
    if diag.synthetic:
        L.append("> Dataset: **SYNTHETIC** (virtual rig). The diagnosis ran blind: it did not read the hidden "
                 "effects or true parameters stored in the manifest.")
        L.append("")
    if diag.cause == "none":
        verdict = ("**none**: no candidate effect improves on the paper's model beyond the noise; the paper's "
                   "model explains the data.")
    elif diag.cause == "unexplained":
        verdict = ("**unexplained**: the paper's model leaves significant structure in the residuals "
                   f"({', '.join(k for k, v in data['evidence']['baseline_structure_z'].items() if v and v > st.z_struct)}) "
                   "and no candidate of the catalogue explains it.")
    else:
        verdict = "**" + " + ".join(c["name"] for c in diag.causes) + "**" + (
            " (ranked, strongest first)" if len(diag.causes) > 1 else "")
    L.append(f"Cause: {verdict}")
    L.append("")
    if diag.causes:
        L.append("## Ranked causes")
        L.append("")
        L.append(_md_table(["rank", "effect", "BIC change (fit data)", "held-out chi² decrease", "score", "shows in"],
                           [[str(c["rank"]), c["name"], c["delta_bic"], c["delta_chi2_heldout"], c["score"],
                             ", ".join(f"{q['test']} {q['signal']}" for q in c["shows_in"][:5]) or "–"]
                            for c in diag.causes]))
        L.append("")
    L.append("## Effect parameters")
    L.append("")
    if diag.effect_parameters:
        rows = [[k, v["value"], v["std"], v["effect"]] for k, v in diag.effect_parameters.items() if k != "per_sample"]
        L.append(_md_table(["parameter (unit in the name)", "value", "std (from the Jacobian)", "effect"], rows))
        ps = diag.effect_parameters.get("per_sample", {})
        if ps:
            keys = sorted({k for v in ps.values() for k in v})
            L.append("")
            L.append("Per sample (FMU parameters):")
            L.append("")
            L.append(_md_table(["sample"] + keys, [[sid] + [v.get(k) for k in keys] for sid, v in ps.items()]))
    else:
        L.append("None (no effect selected).")
    L.append("")
    L.append("## Gain on held-out data")
    L.append("")
    g = diag.gain
    L.append(f"Held-out tests (never used by a fit): {', '.join(g['heldout_tests'])}. "
             "*before*: paper model identified as in the paper; *refit*: paper model re-fitted by least squares "
             "on the fit tests; *after*: the extended model. RMSE pooled over the samples.")
    L.append("")
    rows = []
    for t, e in g["per_test"].items():
        for k, v in e.items():
            rows.append([t, k, v.get("before"), v.get("refit"), v.get("after")])
    L.append(_md_table(["test", "quantity", "before", "refit", "after"], rows))
    o = g["overall_normalized_rmse"]
    L.append("")
    L.append(f"Overall held-out RMSE in units of the sensor noise floor (RMS over samples, tests and signals): "
             f"before {_fmt(o.get('before'))}, refit {_fmt(o.get('refit'))}, after {_fmt(o.get('after'))} "
             f"(after/before {_fmt(o.get('after_over_before'))}).")
    if "heldout_samples" in g:
        h = g["heldout_samples"]["overall_normalized_rmse"]
        L.append(f"Held-out samples {', '.join(g['heldout_samples']['samples'])} (effect parameters fitted on the "
                 f"other samples; every test): before {_fmt(h.get('before'))}, after {_fmt(h.get('after'))}.")
    L.append("")
    L.append("## Candidates")
    L.append("")
    rows = [[n, c["delta_bic"], c["delta_chi2_heldout"], c["score"], c["accepted"],
             ", ".join(f"{k} = {_fmt(v)}" for k, v in c["shared_parameters"].items()), c["reason"]]
            for n, c in diag.candidates.items()]
    L.append(_md_table(["candidate", "BIC change", "held-out chi² decrease", "score", "accepted",
                        "fitted shared parameters", "reason"], rows))
    if len(diag.decision["rounds"]) > 1:
        for r in diag.decision["rounds"][1:]:
            L.append("")
            L.append(f"Greedy step: candidates added to {' + '.join(r['reference'])}:")
            L.append("")
            L.append(_md_table(["added", "BIC change", "held-out chi² decrease", "accepted", "reason"],
                               [[n, c["delta_bic"], c["delta_chi2_heldout"], c["accepted"], c["reason"]]
                                for n, c in r["candidates"].items()]))
    L.append("")
    L.append("## Evidence in the residuals of the paper model")
    L.append("")
    rows = [[k, v.get("z"), v["points_to"], ", ".join(v["tests"]), v["description"]]
            for k, v in diag.evidence["features"].items()]
    L.append(_md_table(["feature", "z (noise units)", "points to", "tests", "what it measures"], rows))
    L.append("")
    zb = diag.evidence["baseline_structure_z"]
    zf = diag.evidence["final_structure_z"]
    L.append("Structure left in the residuals, z = (chi² - n)/sqrt(2n) per test and signal (about N(0,1) for "
             "noise; refitted paper model vs final model):")
    L.append("")
    L.append(_md_table(["test/signal", "paper model (refit)", "final model"], [[k, zb[k], zf.get(k)] for k in zb]))
    L.append("")
    L.append("## Decision rule")
    L.append("")
    d = diag.decision
    L.append(d["rule"])
    L.append("")
    L.append(f"Fit tests: {', '.join(d['fit_tests'])}; held-out tests: {', '.join(d['heldout_tests'])}. "
             f"Shared effect parameters fitted on {', '.join(d['shared_fit_samples'])}"
             + (f"; held-out samples (base parameters re-fitted on their own fit tests with the effect parameters "
                f"fixed): {', '.join(d['heldout_samples'])}" if d["heldout_samples"] else "") + ".")
    L.append("")
    L.append(d["noise_model"] + ".")
    L.append("")
    L.append("## Figures")
    L.append("")
    for sid, f in figs:
        L.append(f"![{sid} residuals]({Path(f).relative_to(out).as_posix()})")
        L.append("")
    L.append("## Files")
    L.append("")
    L.append("- `diagnosis.json`: everything above, machine-readable (keys carry units).")
    L.append("- `extended_params.json`: every sample's parameters, paper + effect parameters (unit keys), for "
             "`mpc-actuator build --params extended_params.json`.")
    L.append("- `tables/extended_*`, `tables/paper_model_*`: paper-style Tables 3, 4, 5 and a long table of the "
             "extended model and of the paper model (CSV and Markdown).")
    L.append("")
    L.append(f"Wall time: {_fmt(diag.timing_s.get('total'))} s.")
    L.append("")
    return "\n".join(L)
