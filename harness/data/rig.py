"""Virtual test rig: synthetic measured data for the paper's 11 samples and tests T1-T8.

Everything produced here is SYNTHETIC. The "true" parameters vary smoothly with
filler fraction (wt%) and diameter and are anchored to the paper's magnitudes
(30 wt% 60 mm: ~6.9 mm maximum T1 displacement, ~0.56 N blocked force at zero
gap; 30 mm samples saturate). The data are made by running mpc_actuator.fmu
through fmpy (``harness.sim.fmurun``) and passing the outputs through sensor models.

Hidden effects: ``generate_dataset(..., effects={"coil_heating": 1.0, ...})`` runs
the FMU with candidate effects of ``fmu_src.effects`` switched on (names there;
``effect_params`` maps a magnitude to parameter values, documented in
``EFFECT_MAGNITUDES``; 1.0 = clearly visible but realistic, 0 = off). The
laser and force-transducer readings are the FMU's x_sensor and F_sensor outputs
(equal to x and F unless sensor_lag is on). Each T1/T7 gap is a separate run
from rest (the coil starts cold at every gap).
"""
from __future__ import annotations

import math
import zlib
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fmu_src.params import Params
from fmu_src.coil import voltage_for_field
from fmu_src.diaphragm import damping_coefficient
from fmu_src.effects import EFFECTS
from harness.data import protocol
from harness.data.dataset import Dataset, GapSweep, Sample, TimeSeries, write_dataset
# the protocol's timing and drives under the rig's historical names (public: used by crosscheck and tests)
from harness.data.protocol import (  # noqa: F401
    FIELDS_T, PRE_STEP_S as PRE_S, SAMPLE_PERIOD_S as DT_S, STEP_POST_S, SWEEP_GAPS_MM, SWEEP_HOLD_S,
    T6_FREQUENCY_HZ, T6_PERIODS, sine_voltage, step_voltage, time_grid,
)
from harness.data.paramsjson import params_from_json, params_to_json  # noqa: F401  (rig.params_from_json: public)

# ---------------------------------------------------------------- samples
TRAINING_SAMPLES = tuple((w, d) for d in (30, 45, 60) for w in (10, 20, 30))
UNSEEN_SAMPLES = ((15, 45), (25, 45))
ALL_SAMPLES = TRAINING_SAMPLES + UNSEEN_SAMPLES
THICKNESS_MM = 1.5


def sample_id(wt_pct: float, diameter_mm: float) -> str:
    return f"W{wt_pct:g}-D{diameter_mm:g}"


# ---------------------------------------------------------------- rig constants
# (test fields, gaps, timing, sample period: harness.data.protocol, paper Table 2)
COIL = dict(a=0.015, kB=0.29, R=15.0, L=0.12)   # 50 mm holding electromagnet (SI)
DAMPING_RATIO = 0.55                             # of every sample [-]


def true_params(wt_pct: float, diameter_mm: float) -> Params:
    """The rig's true parameters for a sample (gap r0 left at its default; set per test).

    Em grows with filler fraction and diameter (more particles); the diaphragm
    stiffens with filler and softens with diameter, the Duffing term strongly so
    (small diaphragms saturate); mass grows with area; damping ratio 0.55.
    """
    w, D = float(wt_pct), float(diameter_mm)
    if not (5.0 <= w <= 35.0 and 20.0 <= D <= 70.0):
        raise ValueError(f"sample wt_pct={w}, diameter_mm={D} is outside the rig's range (5-35 wt%, 20-70 mm)")
    Em = 0.1059 * (w / 30.0) ** 1.2 * (D / 60.0) ** 1.5
    K2 = 30.0 * (60.0 / D) * (1.0 + 0.6 * (w - 10.0) / 20.0)
    K1 = 4.0e5 * (60.0 / D) ** 4 * (1.0 + 0.3 * (w - 10.0) / 20.0)
    m = 0.004 * (D / 45.0) ** 2 * (1.0 + 0.5 * (w - 10.0) / 20.0)
    C = float(damping_coefficient(DAMPING_RATIO, K2, m))
    return Params(D=D / 1000.0, Em=Em, K1=K1, K2=K2, C=C, m=m, **COIL)


# ---------------------------------------------------------------- hidden effects
# What magnitude 1.0 means (strengths scale linearly with the magnitude, time constants
# are fixed; see effect_params). Numbers computed with the pure-Python model at 0.23 T
# (cold steady current 0.793 A) for W20-D45 at its T5 gap of 5 mm [W10-D30 at 3 mm,
# W30-D60 at 9 mm in brackets]; "T5 window" = the 2.8 s after the step.
EFFECT_MAGNITUDES = {
    "coil_heating": "Rth = 8 K/W * magnitude, tau_th = 4 s. Steady state (after ~15 s): dT = 61 K, current -19 %. "
                    "Over the T5 window the current falls 11.5 % (0.789 A 0.1 s after the step -> 0.698 A at the "
                    "end; mean of the last second 6.2 % below the mean over 0.3-1.3 s after the step) and the "
                    "final displacement is 28 % below the plain model's [24 %, 30 %]. Same current droop in "
                    "T8 (blocked force -23 % at the end); T1/T7 points (1.5 s holds from cold) read low.",
    "filler_saturation": "ksat = 1/B_sat^2 = 3 1/T^2 * magnitude (B_sat = 0.577 T). Force factor "
                         "1/(1 + ksat*(kB*I)^2) at the steady current: 0.989 (T2, 0.06 T), 0.965 (T3), 0.929 (T4), "
                         "0.863 (T5-T8, 0.23 T). T5 final displacement -17 % [-15 %, -19 %].",
    "viscoelastic_creep": "Kc = 0.2*K2 * magnitude, tau_c = 1 s. In T5 the displacement keeps rising at steady "
                          "current: last-second mean 8.8 % above the 0.5-1.5 s mean [7.4 %, 10.3 %], still 2 % "
                          "below the relaxed value at the end; T1 points (1.5 s holds) up to 8 % low (-0.17 mm at "
                          "the 4 mm gap) [-6 %; W30-D60 is no longer pulled in at 7 mm].",
    "edge_stiffening": "K5 = K1/(D/15)^2 * magnitude: the quintic term equals the Duffing term at a centre deflection "
                       "of D/15 (2, 3, 4 mm for D = 30, 45, 60 mm). Shows at large deflection, T1 near the gap of "
                       "maximum displacement: -0.16 mm (-7 %) at the 4 mm gap, T1 maximum 3.00 -> 2.86 mm "
                       "[-1 %; W30-D60: maximum 7.0 -> 5.0 mm, pull-in only from 6 mm]; T5 final value -2 % "
                       "[-0.1 %, -1.3 %].",
    "motional_emf": "lam = 0.3 * magnitude: L(x) = L*(1 + 0.3*(a^2/(a^2 + r^2))^1.5), i.e. inductance +26 % at "
                    "the T5 gap [+28 %, +19 %] and +29 % at the T8 gap (2 mm): slower current rise (T5 current up "
                    "to 67 mA below the plain model's); with L refitted at the T5 gap the back-EMF of the motion "
                    "still leaves +-3.6 mA in the current while the diaphragm moves [0.9, 4.2 mA].",
    "sensor_lag": "tau_s = 5 ms * magnitude: first-order lag of the laser and force-transducer readings (not "
                  "the current). T5 reading up to 0.24 mm behind the true displacement during the rise "
                  "[0.09, 0.21 mm]; T6 (1 Hz) phase lag atan(2*pi*1 Hz*5 ms) = 0.031 rad.",
}


def effect_params(name: str, magnitude: float, base_params: Params) -> dict:
    """Parameter values {name: SI value} that hide the effect ``name`` at ``magnitude`` in a sample.

    magnitude 0 switches the effect off (all its parameters 0); 1.0 is clearly visible
    but realistic (see ``EFFECT_MAGNITUDES``); strengths scale linearly with the
    magnitude, time constants stay fixed. ``base_params`` are the sample's true
    parameters (creep and edge stiffening scale with its K2, K1 and D).
    """
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}; known effects: {', '.join(EFFECTS)}")
    try:
        mag = float(magnitude)
    except (TypeError, ValueError):
        raise ValueError(f"effect {name}: magnitude must be a number, got {magnitude!r}") from None
    if not (math.isfinite(mag) and mag >= 0.0):
        raise ValueError(f"effect {name}: magnitude must be finite and >= 0, got {magnitude!r}")
    if mag == 0.0:
        return {k: 0.0 for k in EFFECTS[name].params}
    p = base_params
    if name == "coil_heating":
        return {"Rth": 8.0 * mag, "tau_th": 4.0}
    if name == "filler_saturation":
        return {"ksat": 3.0 * mag}
    if name == "viscoelastic_creep":
        return {"Kc": 0.2 * p.K2 * mag, "tau_c": 1.0}
    if name == "edge_stiffening":
        return {"K5": p.K1 / (p.D / 15.0) ** 2 * mag}
    if name == "motional_emf":
        return {"lam": 0.3 * mag}
    if name == "sensor_lag":
        return {"tau_s": 0.005 * mag}
    raise AssertionError(name)  # every catalogue entry is mapped above


def _check_effects(effects) -> dict:
    """{name: magnitude} as floats, in catalogue order; ValueError on unknown names or bad magnitudes."""
    effects = dict(effects or {})
    unknown = sorted(set(effects) - set(EFFECTS))
    if unknown:
        raise ValueError(f"unknown effect(s) {unknown}; known effects: {', '.join(EFFECTS)}")
    out = {}
    for name in EFFECTS:
        if name in effects:
            effect_params(name, effects[name], Params())  # validates the magnitude
            out[name] = float(effects[name])
    return out


def apply_effects(params: Params, effects) -> Params:
    """``params`` with the effects {name: magnitude} switched on (see ``effect_params``)."""
    kw = {}
    for name, mag in _check_effects(effects).items():
        kw.update(effect_params(name, mag, params))
    return params.with_(**kw) if kw else params


# ---------------------------------------------------------------- sensors
@dataclass(frozen=True)
class Sensor:
    """A sensor: additive white Gaussian noise (sigma) and quantization (resolution)."""
    name: str
    column: str
    sigma: float        # noise standard deviation, in the column's unit
    resolution: float   # quantization step, in the column's unit
    rate_hz: float

    @property
    def noise_floor(self) -> float:
        """RMS of noise plus quantization error, sqrt(sigma^2 + resolution^2/12)."""
        return math.sqrt(self.sigma**2 + self.resolution**2 / 12.0)

    def measure(self, true_values: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        y = np.asarray(true_values, dtype=float) + rng.normal(0.0, self.sigma, np.shape(true_values))
        return np.round(y / self.resolution) * self.resolution


LASER = Sensor("laser displacement sensor (Banner LG10A65PU class)", "displacement_mm", 0.005, 0.002, 1000.0)
FORCE = Sensor("force transducer (Sherborne SS2 class)", "force_N", 0.0005, 0.0001, 1000.0)
CURRENT = Sensor("Hall current sensor (Phidgets 1122 class, averaged)", "current_A", 0.002, 0.001, 1000.0)
SENSORS = {"displacement_mm": LASER, "force_N": FORCE, "current_A": CURRENT}


# ---------------------------------------------------------------- protocols
def _rng(seed: int, *key) -> np.random.Generator:
    words = [zlib.crc32("/".join(map(str, key)).encode())]
    return np.random.default_rng(np.random.SeedSequence([int(seed), *words]))


def _simulate(params: Params, t, V, fmu_path):
    from harness.sim import fmurun
    return fmurun.run(params, t, V, fmu_path=fmu_path)


def _sweep_point(args):
    params, gap_mm, blocked, V, fmu_path = args
    t = time_grid(SWEEP_HOLD_S)
    r = _simulate(params.with_(r0=gap_mm / 1000.0, blocked=blocked), t, np.full(t.shape, V), fmu_path)
    return r


def _steady(values, t):
    return values[protocol.sweep_average_mask(t, protocol.SWEEP_AVERAGE_S)]


def generate_sample(wt_pct, diameter_mm, seed=0, fmu_path=None, pool=None, effects=None):
    """Generate all eight tests of one sample; returns (sample dict for the manifest, {test: table})."""
    sid = sample_id(wt_pct, diameter_mm)
    p = apply_effects(true_params(wt_pct, diameter_mm), effects)
    Vf = {k: voltage_for_field(b, p.kB, p.R) for k, b in FIELDS_T.items()}
    mapper = pool.map if pool is not None else map
    tests = {}
    # T1 and T7: one run per gap
    for test in protocol.SWEEP_TESTS:
        blocked, col = protocol.TESTS[test].blocked, protocol.TESTS[test].measured
        runs = list(mapper(_sweep_point, [(p, g, blocked, Vf[test], fmu_path) for g in SWEEP_GAPS_MM]))
        rng = _rng(seed, sid, test)
        gaps, cur, val = [], [], []
        for g, r in zip(SWEEP_GAPS_MM, runs):
            tt = r["time"]
            true_y = r["x_sensor"] * 1e3 if col == "displacement_mm" else r["F_sensor"]
            y = SENSORS[col].measure(_steady(true_y, tt), rng)
            i = CURRENT.measure(_steady(r["I"], tt), rng)
            gaps.append(float(g)); cur.append(float(np.mean(i))); val.append(float(np.mean(y)))
        kw = {"displacement_mm": None, "force_N": None}
        kw[col] = np.array(val)
        tests[test] = GapSweep(test=test, file=Path(sid) / f"{test}.csv", gap_mm=np.array(gaps),
                               current_A=np.array(cur), field_T=FIELDS_T[test], **kw)
    # gap of maximum T1 displacement, from the measured sweep (as an experimenter would)
    g_max = protocol.max_displacement_gap_mm(tests["T1"].gap_mm, tests["T1"].displacement_mm)
    plan = {n: (protocol.planned_gap_mm(n, g_max), protocol.TESTS[n].blocked) for n in protocol.TIME_SERIES_TESTS}
    jobs = []
    for test, (gap, blocked) in plan.items():
        if protocol.TESTS[test].drive == "sine":
            t = time_grid(PRE_S + T6_PERIODS / T6_FREQUENCY_HZ)
            V = sine_voltage(t, Vf[test])
        else:
            t = time_grid(PRE_S + STEP_POST_S)
            V = step_voltage(t, Vf[test])
        jobs.append((test, gap, blocked, t, V))
    results = list(mapper(_run_job, [(p.with_(r0=g / 1000.0, blocked=b), t, V, fmu_path) for _, g, b, t, V in jobs]))
    for (test, gap, blocked, t, V), r in zip(jobs, results):
        rng = _rng(seed, sid, test)
        col = protocol.TESTS[test].measured
        true_y = r["F_sensor"] if blocked else r["x_sensor"] * 1e3
        kw = {"displacement_mm": None, "force_N": None}
        kw[col] = SENSORS[col].measure(true_y, rng)
        tests[test] = TimeSeries(test=test, file=Path(sid) / f"{test}.csv", time_s=t, voltage_V=V,
                                 current_A=CURRENT.measure(r["I"], rng), field_T=FIELDS_T[test],
                                 gap_mm=gap, frequency_hz=protocol.TESTS[test].frequency_hz, **kw)
    return sid, p, dict(sorted(tests.items()))


def _run_job(args):
    params, t, V, fmu_path = args
    return _simulate(params, t, V, fmu_path)


def rig_description(effects=None) -> dict:
    """The manifest's "rig" entry: coil and sensor models with units (and what hidden effects mean)."""
    d = {
        "coil_radius_mm": COIL["a"] * 1e3,
        "field_per_amp_T_per_A": COIL["kB"],
        "sample_period_s": DT_S,
        "sensors": {
            col: {"model": s.name, "noise_sigma": s.sigma, "resolution": s.resolution,
                  "noise_floor": s.noise_floor, "rate_hz": s.rate_hz, "unit": col.rsplit("_", 1)[1]}
            for col, s in SENSORS.items()
        },
    }
    effects = _check_effects(effects)
    if effects:
        d["effect_definitions"] = {name: {"summary": EFFECTS[name].summary, "magnitude_1": EFFECT_MAGNITUDES[name]}
                                   for name in effects}
    return d


def generate_dataset(out_dir, seed: int = 0, samples=ALL_SAMPLES, fmu_path=None, effects=None,
                     workers: int = 2, progress: bool = True, overwrite: bool = False):
    """Generate a synthetic dataset (format mpc-actuator-data/1) into out_dir; returns the Dataset.

    Same seed, same bytes. ``effects`` maps effect names (``fmu_src.effects.EFFECTS``) to
    magnitudes (see ``EFFECT_MAGNITUDES``); they are hidden in the data and recorded in
    the manifest's rig.effects, their parameters in rig.true_parameters.
    """
    from tqdm import tqdm
    effects = _check_effects(effects)   # fail before any simulation
    samples = list(samples)
    truth = {}
    out_samples = []
    pool = ProcessPoolExecutor(max_workers=workers) if workers and workers > 1 else None
    try:
        it = tqdm(samples, desc="virtual rig", unit="sample", disable=not progress)
        for w, d in it:
            sid, p, tests = generate_sample(w, d, seed=seed, fmu_path=fmu_path, pool=pool, effects=effects)
            truth[sid] = p
            out_samples.append(Sample(id=sid, wt_pct=float(w), diameter_mm=float(d),
                                      thickness_mm=THICKNESS_MM, tests=tests))
    finally:
        if pool is not None:
            pool.shutdown()
    rig = rig_description(effects)
    rig["true_parameters"] = {sid: params_to_json(p) for sid, p in truth.items()}
    rig["effects"] = dict(effects)
    rig["seed"] = int(seed)
    ds = Dataset(root=Path(out_dir), synthetic=True,
                 description=("SYNTHETIC data from the mpc-actuator virtual test rig (not the paper's "
                              "measurements): mpc_actuator.fmu run through fmpy with smooth 'true' parameters "
                              "per sample, plus sensor noise and quantization."
                              + (f" Hidden effects (rig.effects): {', '.join(f'{k}={v:g}' for k, v in effects.items())}."
                                 if effects else "")),
                 rig=rig, samples=out_samples)
    write_dataset(ds, out_dir, overwrite=overwrite)
    return ds
