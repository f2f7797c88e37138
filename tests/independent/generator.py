"""Independent test-data generator: the paper's eleven samples under a matrix of rig conventions.

Physics in :mod:`tests.independent.physics` (written from the paper and the README, importing
nothing of the project's physics). This module imports ``harness.data.dataset`` only to write the
dataset files (the format). It makes ``mpc-actuator-data/1`` datasets whose rig conventions differ
from the project's virtual rig (:class:`RigConventions`) and whose hidden effects include forms
outside the project's catalogue (:data:`EFFECT_FORMS`).

Time base and the step instant
------------------------------
Samples are taken at ``t_k = clock_start_s + k / sample_rate_hz``, ``k = 0 .. N`` with
``N = round(record_s * sample_rate_hz)``. The physics starts at rest at ``t = clock_start_s``. A step
is commanded at ``t_step = clock_start_s + pre_trigger_s + step_phase / sample_rate_hz``
(``0 <= step_phase < 1``: anywhere between two samples when ``pre_trigger_s`` is a whole number of
periods). The ``voltage_V`` column is the commanded zero-order-hold value in force at each sample
instant, right-continuous: ``V_k = V_on`` if ``t_k >= t_step`` else 0. So the first sample that
reads ``V_on`` comes up to one sample period *after* the true step instant, and the current at that
sample has already risen by ``1 - exp(-(t_k - t_step) R / L)``. T6's raised cosine starts at
``t_step`` likewise and is applied as a continuous (analog) drive, as a function generator would;
its ``voltage_V`` column samples that command at ``t_k`` (a replay that holds each sample for one
period lags it by half a period: 1 ms at 500 Hz, 0.006 rad at 1 Hz).

Sweeps (T1, T7): each gap is a separate run from rest, energized for ``sweep_hold_s``. Averaged
sweeps (``sweep_average_s`` set) report the mean of the noisy, quantized samples in the last
``sweep_average_s`` of the hold (``n = round(sweep_average_s * sample_rate_hz)`` samples); the
manifest's ``rig.sweep_average_s`` says so. Single-reading sweeps report the one noisy sample at the
end of the hold (``rig.sweep_average_s`` absent, ``rig.sweep_single_reading`` true).

Command line: ``python -m tests.independent.generator MEMBER --out DIR`` (``--list`` names them).
"""
from __future__ import annotations

import argparse
import math
import sys
import zlib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from tests.independent.physics import TrueParams, raised_cosine_drive, simulate, step_drive

__all__ = ["SensorSpec", "RigConventions", "Member", "MATRIX", "FAST_MATRIX", "EFFECT_FORMS", "ALL_SAMPLES",
           "true_params", "with_effects", "make_dataset", "measure", "sample_times_s", "main"]

# ---------------------------------------------------------------- the paper's samples (re-typed)
ALL_SAMPLES = tuple((w, d) for d in (30, 45, 60) for w in (10, 20, 30)) + ((15, 45), (25, 45))
THICKNESS_MM = 1.5
COIL_A_M, COIL_KB_T_PER_A, COIL_R_OHM, COIL_L_H = 0.015, 0.29, 15.0, 0.12
FIELDS_T = {"T1": 0.23, "T2": 0.06, "T3": 0.11, "T4": 0.16, "T5": 0.23, "T6": 0.23, "T7": 0.23, "T8": 0.23}


def sample_id(wt_pct: float, diameter_mm: float) -> str:
    return f"W{wt_pct:g}-D{diameter_mm:g}"


def true_params(wt_pct: float, diameter_mm: float) -> TrueParams:
    """The README table "rig's true value", typed again (no effects)."""
    w, D = float(wt_pct), float(diameter_mm)
    Em = 0.1059 * (w / 30) ** 1.2 * (D / 60) ** 1.5
    K2 = 30 * (60 / D) * (1 + 0.6 * (w - 10) / 20)
    K1 = 4e5 * (60 / D) ** 4 * (1 + 0.3 * (w - 10) / 20)
    m = 0.004 * (D / 45) ** 2 * (1 + 0.5 * (w - 10) / 20)
    C = 2 * 0.55 * math.sqrt(K2 * m)
    return TrueParams(a_m=COIL_A_M, D_m=D / 1000, kB_T_per_A=COIL_KB_T_PER_A, R_Ohm=COIL_R_OHM, L_H=COIL_L_H,
                      Em_N_m_per_T2=Em, K1_N_per_m3=K1, K2_N_per_m=K2, C_N_s_per_m=C, m_kg=m)


# ---------------------------------------------------------------- hidden effects
EFFECT_FORMS = {
    # the project's catalogue, written independently (magnitude 1 as in the README's effect table)
    "coil_heating": "R(1 + 0.0039/K dT), dT' = (Rth I^2 R - dT)/tau; Rth = 8 K/W * mag, tau = 4 s",
    "filler_saturation": "F * 1/(1 + ksat (kB I)^2); ksat = 3 1/T^2 * mag",
    "viscoelastic_creep": "one Maxwell branch Kc = 0.2 K2 * mag, tau_c = 1 s",
    "edge_stiffening": "spring + K5 x^5, K5 = K1/(D/15)^2 * mag (D in m)",
    "motional_emf": "L(x) = L (1 + lam (a^2/(a^2 + r^2))^1.5), lam = 0.3 * mag; V = R I + d(L(x) I)/dt",
    "sensor_lag": "first-order lag of laser and force readings, tau_s = 5 ms * mag",
    # forms outside the catalogue
    "coil_heating_2tau": "two thermal branches: Rth = (4, 6) K/W * mag, tau = (1.5, 20) s",
    "creep_2tau": "two Maxwell branches: Kc = (0.1, 0.15) K2 * mag, tau_c = (0.25, 4) s",
    "saturation_tanh": "magnetization Bsat tanh(B/Bsat): F * tanh(y)/y, y = kB I/Bsat, Bsat = 0.45 T/sqrt(mag)",
    "saturation_langevin": "magnetization Bsat L(3B/Bsat): F * 3 L(u)/u, u = 3 kB I/Bsat, Bsat = 0.35 T/sqrt(mag)",
}


#: effects OUTSIDE the project's catalogue and of kinds it has no effect for (mechanical, coil, reading), each
#: in a physical form of its own (not the form of any candidate term of the project's library): the data of
#: issue 22's discovery. Magnitude 1 is a realistic size; the notes give what it does.
OUTSIDE_FORMS = {
    "fluid_drag": "mechanical: orifice flow of the pumped fluid, drag -kd v|v| with kd = 20 C/(1 m/s) * mag "
                  "(equal to the viscous damping at 0.05 m/s) and an added mass 0.3 m * mag",
    "clamp_friction": "mechanical: Dahl friction in the clamping, z' = sigma (v - |v| z/Fc), force -z; "
                      "Fc = 3 mN * mag, sigma = Fc/(10 um)",
    "dome_prestress": "mechanical: a pre-stressed dome, spring force + K_even x^2, K_even = 0.15 K2/(D/20) * mag "
                      "(the quadratic term is 15 % of the linear one at a deflection of D/20)",
    "silicone_heating": "mechanical: the coil's loss I^2 R warms the silicone through two nodes (Rth 6 K/W, "
                        "tau 2 s and 1 s) and K1, K2 fall by beta dT, beta = 0.004 1/K * mag",
    "eddy_currents": "coil: a shorted secondary (eddy currents in the core), [L M; M Le] d[I, Ie]/dt = "
                     "[V - R I, -Re Ie], k^2 = M^2/(L Le) = min(0.4 * mag, 0.8), Le/Re = 20 ms",
    "laser_nonlinearity": "reading: the laser reads x + g2 x^2 + g3 x^3, g2 = 8 1/m * mag, g3 = 500 1/m^2 * mag "
                          "(+86 um at 3 mm)",
    "loadcell_creep": "reading: the force transducer creeps, F + sum c_i (z_i - F), z_i' = (F - z_i)/tau_i, "
                      "c = (0.03, 0.02) * mag, tau = (0.3, 3) s",
}

#: the physical kind of each outside form (what a discovered term must be: issue 22)
OUTSIDE_KIND = {"fluid_drag": "mechanical", "clamp_friction": "mechanical", "dome_prestress": "mechanical",
                "silicone_heating": "mechanical", "eddy_currents": "coil", "laser_nonlinearity": "reading",
                "loadcell_creep": "reading"}


def _with_outside(p: TrueParams, name: str, mag: float) -> dict:
    """The TrueParams fields of the outside form ``name`` at magnitude ``mag``."""
    if name == "fluid_drag":
        return dict(drag_N_s2_per_m2=20.0 * p.C_N_s_per_m * mag, added_mass_kg=0.3 * p.m_kg * mag)
    if name == "clamp_friction":
        Fc = 0.003 * mag
        return dict(dahl_Fc_N=Fc, dahl_sigma_N_per_m=Fc / 10e-6)
    if name == "dome_prestress":
        return dict(K_even_N_per_m2=0.15 * p.K2_N_per_m / (p.D_m / 20.0) * mag)
    if name == "silicone_heating":
        return dict(soft_beta_per_K=0.004 * mag, soft_Rth_K_per_W=6.0, soft_tau_s=(2.0, 1.0))
    if name == "eddy_currents":
        return dict(eddy_k2=min(0.4 * mag, 0.8), eddy_tau_s=0.020)
    if name == "laser_nonlinearity":
        return dict(laser_g2_per_m=8.0 * mag, laser_g3_per_m2=500.0 * mag)
    if name == "loadcell_creep":
        return dict(cell_creep=(0.03 * mag, 0.02 * mag), cell_tau_s=(0.3, 3.0))
    raise ValueError(f"unknown outside form {name!r}")


def with_effects(p: TrueParams, effects: dict | None) -> TrueParams:
    """``p`` with hidden effects {name: magnitude} (names of :data:`EFFECT_FORMS` or :data:`OUTSIDE_FORMS`)
    switched on."""
    kw: dict = {}
    for name, mag in (effects or {}).items():
        if name not in EFFECT_FORMS and name not in OUTSIDE_FORMS:
            raise ValueError(f"unknown effect {name!r}; known: {', '.join(list(EFFECT_FORMS) + list(OUTSIDE_FORMS))}")
        mag = float(mag)
        if not (math.isfinite(mag) and mag > 0):
            raise ValueError(f"effect {name}: magnitude must be finite and > 0, got {mag!r}")
        if name == "coil_heating":
            kw.update(Rth_K_per_W=kw.get("Rth_K_per_W", ()) + (8.0 * mag,), tau_th_s=kw.get("tau_th_s", ()) + (4.0,))
        elif name == "coil_heating_2tau":
            kw.update(Rth_K_per_W=kw.get("Rth_K_per_W", ()) + (4.0 * mag, 6.0 * mag),
                      tau_th_s=kw.get("tau_th_s", ()) + (1.5, 20.0))
        elif name == "filler_saturation":
            kw.update(saturation="rational", ksat_per_T2=3.0 * mag)
        elif name == "saturation_tanh":
            kw.update(saturation="tanh", Bsat_T=0.45 / math.sqrt(mag))
        elif name == "saturation_langevin":
            kw.update(saturation="langevin", Bsat_T=0.35 / math.sqrt(mag))
        elif name == "viscoelastic_creep":
            kw.update(Kc_N_per_m=kw.get("Kc_N_per_m", ()) + (0.2 * p.K2_N_per_m * mag,),
                      tau_c_s=kw.get("tau_c_s", ()) + (1.0,))
        elif name == "creep_2tau":
            kw.update(Kc_N_per_m=kw.get("Kc_N_per_m", ()) + (0.1 * p.K2_N_per_m * mag, 0.15 * p.K2_N_per_m * mag),
                      tau_c_s=kw.get("tau_c_s", ()) + (0.25, 4.0))
        elif name == "edge_stiffening":
            kw.update(K5_N_per_m5=p.K1_N_per_m3 / (p.D_m / 15) ** 2 * mag)
        elif name == "motional_emf":
            kw.update(lam_1=0.3 * mag)
        elif name == "sensor_lag":
            kw.update(tau_s_s=0.005 * mag)
        else:
            kw.update(_with_outside(p, name, mag))
    if sum(k in (effects or {}) for k in ("filler_saturation", "saturation_tanh", "saturation_langevin")) > 1:
        raise ValueError("at most one saturation form at a time")
    return replace(p, **kw)


# ---------------------------------------------------------------- sensors and conventions
@dataclass(frozen=True)
class SensorSpec:
    """White Gaussian noise ``sigma`` then quantization to ``resolution`` (both in the column's unit)."""
    model: str
    sigma: float
    resolution: float

    @property
    def noise_floor(self) -> float:
        return math.sqrt(self.sigma**2 + self.resolution**2 / 12)

    def scaled(self, k: float) -> "SensorSpec":
        """Noise sigma times ``k`` (the quantization step is the instrument's and stays)."""
        return replace(self, sigma=self.sigma * k)


OUR_LASER = SensorSpec("laser displacement sensor (our rig's class)", 0.005, 0.002)      # mm
OUR_FORCE = SensorSpec("force transducer (our rig's class)", 0.0005, 0.0001)            # N
OUR_CURRENT = SensorSpec("Hall current sensor (our rig's class)", 0.002, 0.001)         # A


def measure(true_values, sensor: SensorSpec, rng: np.random.Generator) -> np.ndarray:
    """Noisy, quantized readings of ``true_values`` (same unit as the sensor)."""
    y = np.asarray(true_values, dtype=float) + rng.normal(0.0, sensor.sigma, np.shape(true_values))
    return np.round(y / sensor.resolution) * sensor.resolution


@dataclass(frozen=True)
class RigConventions:
    """How a rig records the paper's protocols (see the module docstring for the time base).

    Times in s, rates in Hz, gaps in mm. ``sweep_average_s = None`` means single-reading sweeps.
    ``manifest_coil = False`` leaves ``coil_radius_mm`` and ``field_per_amp_T_per_A`` out of the
    manifest (the identification must then derive them from the data).
    """
    sample_rate_hz: float = 1000.0
    step_phase: float = 0.0
    clock_start_s: float = 0.0
    pre_trigger_s: float = 0.2
    record_s: float = 3.0
    t6_periods: int = 5
    t6_frequency_hz: float = 1.0
    sweep_gaps_mm: tuple = tuple(float(g) for g in range(25, -1, -1))
    sweep_hold_s: float = 1.5
    sweep_average_s: float | None = 0.3
    laser: SensorSpec = OUR_LASER
    force: SensorSpec = OUR_FORCE
    current: SensorSpec = OUR_CURRENT
    manifest_coil: bool = True
    t8_gap_mm: float = 2.0
    step_gap_offset_mm: float = 2.0
    t6_gap_offset_mm: float = 3.0

    def __post_init__(self):
        if not (0.0 <= self.step_phase < 1.0):
            raise ValueError(f"step_phase must be in [0, 1), got {self.step_phase!r}")
        if not (self.sample_rate_hz > 0 and self.record_s > self.pre_trigger_s >= 0):
            raise ValueError("need sample_rate_hz > 0 and record_s > pre_trigger_s >= 0")
        if self.sweep_average_s is not None and not (0 < self.sweep_average_s <= self.sweep_hold_s):
            raise ValueError("sweep_average_s must be in (0, sweep_hold_s] or None")

    @property
    def sample_period_s(self) -> float:
        return 1.0 / self.sample_rate_hz

    @property
    def step_delay_s(self) -> float:
        """Step instant after the clock start [s]."""
        return self.pre_trigger_s + self.step_phase / self.sample_rate_hz


def sample_times_s(conv: RigConventions, record_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(clock times t_k [s] as written, times since the clock start [s] used by the physics)."""
    n = int(round(record_s * conv.sample_rate_hz))
    k = np.arange(n + 1)
    rel = k / conv.sample_rate_hz
    return conv.clock_start_s + rel, rel


def noise_rng(seed: int, *key) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), zlib.crc32("/".join(map(str, key)).encode())]))


# ---------------------------------------------------------------- protocols
def sweep(p: TrueParams, conv: RigConventions, test: str, rng) -> dict:
    """T1 (free) or T7 (blocked) over ``conv.sweep_gaps_mm``: {gap_mm, current_A, displacement_mm|force_N}."""
    blocked = test == "T7"
    V = p.R_Ohm * FIELDS_T[test] / p.kB_T_per_A
    fs = conv.sample_rate_hz
    n_hold = int(round(conv.sweep_hold_s * fs))
    n_avg = 1 if conv.sweep_average_s is None else max(1, int(round(conv.sweep_average_s * fs)))
    t = (n_hold - n_avg + 1 + np.arange(n_avg)) / fs
    gaps, cur, val = [], [], []
    for g in conv.sweep_gaps_mm:
        r = simulate(p, g / 1000.0, blocked, step_drive(0.0, V), t)
        y = r["F_sensor_N"] if blocked else r["x_sensor_m"] * 1e3
        sens = conv.force if blocked else conv.laser
        val.append(float(np.mean(measure(y, sens, rng))))
        cur.append(float(np.mean(measure(r["I_A"], conv.current, rng))))
        gaps.append(float(g))
    col = "force_N" if blocked else "displacement_mm"
    return {"gap_mm": np.array(gaps), "current_A": np.array(cur), col: np.array(val)}


def time_series(p: TrueParams, conv: RigConventions, test: str, gap_mm: float, rng, events: list | None = None) -> dict:
    """T2-T6 or T8 at ``gap_mm``: {time_s, voltage_V, current_A, displacement_mm|force_N}; ``events`` (a list,
    optional) is extended by the physics' contact/release events (instant [s], kind)."""
    blocked = test == "T8"
    V = p.R_Ohm * FIELDS_T[test] / p.kB_T_per_A
    t0 = conv.step_delay_s
    if test == "T6":
        drive = raised_cosine_drive(t0, V, conv.t6_frequency_hz)
        record = conv.pre_trigger_s + conv.t6_periods / conv.t6_frequency_hz
    else:
        drive = step_drive(t0, V)
        record = conv.record_s
    t_clock, t_rel = sample_times_s(conv, record)
    r = simulate(p, gap_mm / 1000.0, blocked, drive, t_rel)
    if events is not None:
        events.extend(r["events"])
    volt = np.array([drive.voltage_V(tt) for tt in t_rel])
    out = {"time_s": t_clock, "voltage_V": volt, "current_A": measure(r["I_A"], conv.current, rng)}
    if blocked:
        out["force_N"] = measure(r["F_sensor_N"], conv.force, rng)
    else:
        out["displacement_mm"] = measure(r["x_sensor_m"] * 1e3, conv.laser, rng)
    return out


def sensor_json(s: SensorSpec, conv: RigConventions, unit: str) -> dict:
    return {"model": s.model, "noise_sigma": s.sigma, "resolution": s.resolution, "noise_floor": s.noise_floor,
            "rate_hz": conv.sample_rate_hz, "unit": unit}


def params_json(p: TrueParams) -> dict:
    d = asdict(p)
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}


def make_dataset(out_dir, conventions: RigConventions, effects: dict | None = None, seed: int = 0,
                 samples=None, description: str = "") -> Path:
    """Generate a dataset (``mpc-actuator-data/1``) into the empty or new folder ``out_dir``.

    Parameters
    ----------
    out_dir : path
        Output folder (refused when not empty, by ``write_dataset``).
    conventions : RigConventions
        Sample rate, step phase, clock, noise, sweeps, record lengths, gap grid, manifest contents.
    effects : dict, optional
        Hidden effects {name: magnitude}, names of :data:`EFFECT_FORMS` (magnitude 1: clearly visible).
    seed : int
        Noise seed (same seed, same bytes).
    samples : iterable of (wt_pct, diameter_mm), optional
        Default: the paper's eleven samples.

    Returns
    -------
    Path
        The dataset folder.

    Examples
    --------
    >>> make_dataset("out/m500", MATRIX["clean-500Hz-single"].conventions,
    ...              samples=[(20, 45)])                                     # doctest: +SKIP
    """
    from harness.data.dataset import Dataset, GapSweep, Sample, TimeSeries, write_dataset

    conv = conventions
    samples = list(ALL_SAMPLES if samples is None else samples)
    out_samples, truth = [], {}
    for w, d in samples:
        sid = sample_id(w, d)
        p = with_effects(true_params(w, d), effects)
        truth[sid] = params_json(p)
        tests = {}
        for test in ("T1", "T7"):
            cols = {"displacement_mm": None, "force_N": None, **sweep(p, conv, test, noise_rng(seed, sid, test))}
            tests[test] = GapSweep(test=test, file=None, field_T=FIELDS_T[test], **cols)
        t1 = tests["T1"]
        g_max = float(t1.gap_mm[int(np.argmax(t1.displacement_mm))])
        for test in ("T2", "T3", "T4", "T5", "T6", "T8"):
            gap = conv.t8_gap_mm if test == "T8" else g_max + (conv.t6_gap_offset_mm if test == "T6"
                                                                else conv.step_gap_offset_mm)
            cols = time_series(p, conv, test, gap, noise_rng(seed, sid, test))
            cols.setdefault("displacement_mm", None)
            cols.setdefault("force_N", None)
            tests[test] = TimeSeries(test=test, file=None, field_T=FIELDS_T[test], gap_mm=gap,
                                     frequency_hz=conv.t6_frequency_hz if test == "T6" else None, **cols)
        out_samples.append(Sample(id=sid, wt_pct=float(w), diameter_mm=float(d), thickness_mm=THICKNESS_MM,
                                  tests={k: tests[k] for k in sorted(tests)}))
    rig = {"sample_period_s": conv.sample_period_s,
           "sweep_hold_s": conv.sweep_hold_s,
           "sensors": {"displacement_mm": sensor_json(conv.laser, conv, "mm"),
                       "force_N": sensor_json(conv.force, conv, "N"),
                       "current_A": sensor_json(conv.current, conv, "A")},
           "generator": "tests/independent/generator.py (independent physics; not harness.data.rig)",
           "conventions": conventions_json(conv),
           "independent_effects": dict(effects or {}),
           "independent_truth": truth,
           "seed": int(seed)}
    if conv.manifest_coil:
        rig["coil_radius_mm"] = COIL_A_M * 1e3
        rig["field_per_amp_T_per_A"] = COIL_KB_T_PER_A
    if conv.sweep_average_s is None:
        rig["sweep_single_reading"] = True
    else:
        rig["sweep_average_s"] = conv.sweep_average_s
    ds = Dataset(root=None, synthetic=True, rig=rig, samples=out_samples,
                 description=description or "SYNTHETIC data from the independent test-data generator "
                                            "(tests/independent), not measured")
    return write_dataset(ds, out_dir)


def conventions_json(conv: RigConventions) -> dict:
    d = asdict(conv)
    d["sweep_gaps_mm"] = list(conv.sweep_gaps_mm)
    d["step_delay_s"] = conv.step_delay_s
    return d


# ---------------------------------------------------------------- the matrix
@dataclass(frozen=True)
class Member:
    """One member of the matrix: conventions, hidden effects and the samples generated."""
    conventions: RigConventions
    effects: dict = field(default_factory=dict)
    samples: tuple | None = None           # None = all eleven
    note: str = ""


_TRAIN_SUBSET = ((10, 45), (20, 45), (30, 45), (20, 30), (20, 60))
_IRREGULAR_GAPS = (24.0, 20.0, 16.0, 13.0, 11.0, 9.5, 8.0, 7.0, 6.0, 5.5, 5.0, 4.5, 4.0, 3.5, 3.0, 2.5, 2.0, 1.5,
                   1.0, 0.5, 0.0)
_HALF_GAPS = tuple(g / 2 for g in range(30, -1, -1))      # 15 .. 0 mm in 0.5 mm steps

MATRIX: dict[str, Member] = {
    "clean-ours": Member(RigConventions(), note="our rig's conventions, independent physics"),
    "clean-500Hz-single": Member(RigConventions(sample_rate_hz=500.0, sweep_average_s=None),
                                 note="500 Hz, single-reading sweeps"),
    "clean-250Hz-phase-clock12": Member(RigConventions(sample_rate_hz=250.0, step_phase=0.37, clock_start_s=12.0),
                                        note="250 Hz, step 0.37 periods after a sample, clock at 12 s"),
    "clean-200Hz-noisy5x": Member(RigConventions(sample_rate_hz=200.0, laser=OUR_LASER.scaled(5),
                                                 force=OUR_FORCE.scaled(5), current=OUR_CURRENT.scaled(5),
                                                 sweep_average_s=1.0, sweep_hold_s=2.0),
                                  note="200 Hz, 5x noise on every channel, 1 s sweep averages after 2 s holds"),
    "clean-2kHz-quiet-longpre": Member(RigConventions(sample_rate_hz=2000.0, laser=OUR_LASER.scaled(0.3),
                                                      force=OUR_FORCE.scaled(0.3), current=OUR_CURRENT.scaled(0.3),
                                                      pre_trigger_s=0.5, record_s=4.5, step_phase=0.8,
                                                      sweep_gaps_mm=_IRREGULAR_GAPS),
                                       samples=_TRAIN_SUBSET,
                                       note="2 kHz, 0.3x noise, 0.5 s pre-trigger, 4.5 s records, irregular gaps"),
    "clean-10kHz-subset": Member(RigConventions(sample_rate_hz=10000.0, step_phase=0.5, sweep_gaps_mm=_HALF_GAPS,
                                                sweep_average_s=0.1, sweep_hold_s=1.0),
                                 samples=((20, 45), (30, 60)), note="10 kHz, 0.5 mm gap grid, two samples"),
    "clean-nocoil-mixed-noise": Member(RigConventions(manifest_coil=False, laser=OUR_LASER.scaled(2.0),
                                                      force=OUR_FORCE.scaled(0.5), current=OUR_CURRENT.scaled(3.0),
                                                      pre_trigger_s=0.1, record_s=2.5, clock_start_s=3.7),
                                       note="no coil radius / field per amp in the manifest, mixed noise"),
    # effects: forms outside the catalogue
    "heat-2tau": Member(RigConventions(sample_rate_hz=500.0), {"coil_heating_2tau": 1.0}),
    "creep-2tau": Member(RigConventions(sample_rate_hz=500.0), {"creep_2tau": 1.0}),
    "sat-tanh": Member(RigConventions(sample_rate_hz=500.0), {"saturation_tanh": 1.0}),
    "sat-langevin": Member(RigConventions(sample_rate_hz=500.0), {"saturation_langevin": 1.0}),
    # effects: the catalogue's forms, written independently
    "cat-heating": Member(RigConventions(), {"coil_heating": 1.0}),
    "cat-saturation": Member(RigConventions(), {"filler_saturation": 1.0}),
    "cat-creep": Member(RigConventions(), {"viscoelastic_creep": 1.0}),
    "cat-edge": Member(RigConventions(), {"edge_stiffening": 1.0}),
    "cat-emf": Member(RigConventions(), {"motional_emf": 1.0}),
    "cat-lag": Member(RigConventions(), {"sensor_lag": 1.0}),
}


#: reduced members, cheap enough for the default test suite (seconds each): three samples at 45 mm (the
#: fewest from which the diagnosis holds one out without ``--unseen``), 2.4 s records, 13-gap sweeps (2 mm
#: grid), two T6 periods, 1 s sweep holds; rig conventions unlike ours (not 1 kHz, the step between two
#: samples, the clock not at 0); one clean, one with a saturation law outside the catalogue
_FAST_GAPS = tuple(float(g) for g in range(24, -1, -2))
_FAST_SAMPLES = ((10, 45), (20, 45), (30, 45))
FAST_MATRIX: dict[str, Member] = {
    "fast-clean-400Hz-single": Member(
        RigConventions(sample_rate_hz=400.0, step_phase=0.6, clock_start_s=7.3, pre_trigger_s=0.15, record_s=2.4,
                       t6_periods=2, sweep_gaps_mm=_FAST_GAPS, sweep_hold_s=1.0, sweep_average_s=None),
        samples=_FAST_SAMPLES,
        note="400 Hz, step 0.6 periods after a sample, clock at 7.3 s, single-reading sweeps, short records"),
    "fast-sat-tanh-250Hz-quiet": Member(
        RigConventions(sample_rate_hz=250.0, step_phase=0.3, clock_start_s=2.0, pre_trigger_s=0.12, record_s=2.4,
                       t6_periods=2, sweep_gaps_mm=_FAST_GAPS, sweep_hold_s=1.0, sweep_average_s=0.2,
                       laser=OUR_LASER.scaled(0.3), force=OUR_FORCE.scaled(0.3)),
        {"saturation_tanh": 1.0}, samples=_FAST_SAMPLES,
        note="250 Hz, step 0.3 periods after a sample, clock at 2 s, 0.3x laser/force noise, 0.2 s sweep "
             "averages, tanh saturation (not the catalogue's form)"),
}


def make_member(name: str, out_dir, seed: int = 0) -> Path:
    """Generate the matrix member ``name`` (of :data:`MATRIX` or :data:`FAST_MATRIX`) into ``out_dir``."""
    members = {**MATRIX, **FAST_MATRIX}
    if name not in members:
        raise KeyError(f"unknown matrix member {name!r}; known: {', '.join(members)}")
    m = members[name]
    return make_dataset(out_dir, m.conventions, m.effects, seed=seed, samples=m.samples,
                        description=f"SYNTHETIC data, independent generator, matrix member {name}: {m.note}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.independent.generator", description=__doc__.split("\n")[0])
    ap.add_argument("member", nargs="?")
    ap.add_argument("--out")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--list", action="store_true")
    a = ap.parse_args(argv)
    if a.list or not a.member:
        for k, m in {**MATRIX, **FAST_MATRIX}.items():
            print(f"{k:28s} {m.effects or ''} {m.note}")
        return 0
    print(make_member(a.member, a.out, seed=a.seed))
    return 0


if __name__ == "__main__":
    sys.exit(main())
