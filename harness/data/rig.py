"""Virtual test rig: synthetic measured data for the paper's 11 samples and tests T1-T8.

Everything produced here is SYNTHETIC. The "true" parameters vary smoothly with
filler fraction (wt%) and diameter and are anchored to the paper's magnitudes
(30 wt% 60 mm: ~6.9 mm maximum T1 displacement, ~0.56 N blocked force at zero
gap; 30 mm samples saturate). This module describes the rig: samples, true parameters, hidden effects
(``effect_params`` maps a magnitude to parameter values, documented in ``EFFECT_MAGNITUDES``; 1.0 = clearly
visible but realistic, 0 = off) and the sensor models. Running it (the FMU through fmpy, then the sensor
models) is ``harness.sim.virtual_rig.generate_dataset``: the data layer runs no simulation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fmu_src.specs import EFFECTS, Params
from fmu_src.diaphragm import damping_coefficient
from harness.data.paramsjson import params_from_json, params_to_json  # noqa: F401  (rig.params_from_json: public)
from harness.data.protocol import SAMPLE_PERIOD_S, SWEEP_AVERAGE_S, SWEEP_HOLD_S

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
# are fixed; see effect_params): the effects' specs (fmu_src.specs.EFFECTS: rig_magnitude_1, rig_note).
EFFECT_MAGNITUDES = {name: e.rig_note for name, e in EFFECTS.items()}


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
    e = EFFECTS[name]
    return {k: v if k in e.rig_fixed else v * mag for k, v in e.rig_magnitude_1(base_params).items()}


def check_effects(effects) -> dict:
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
    for name, mag in check_effects(effects).items():
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


def rig_description(effects=None) -> dict:
    """The manifest's "rig" entry: coil and sensor models with units (and what hidden effects mean)."""
    d = {
        "coil_radius_mm": COIL["a"] * 1e3,
        "field_per_amp_T_per_A": COIL["kB"],
        "sample_period_s": SAMPLE_PERIOD_S,
        "sweep_hold_s": SWEEP_HOLD_S,          # the virtual rig's sweep readings: means over the last
        "sweep_average_s": SWEEP_AVERAGE_S,    # 0.3 s of each 1.5 s hold
        "sensors": {
            col: {"model": s.name, "noise_sigma": s.sigma, "resolution": s.resolution,
                  "noise_floor": s.noise_floor, "rate_hz": s.rate_hz, "unit": col.rsplit("_", 1)[1]}
            for col, s in SENSORS.items()
        },
    }
    effects = check_effects(effects)
    if effects:
        d["effect_definitions"] = {name: {"summary": EFFECTS[name].summary, "magnitude_1": EFFECT_MAGNITUDES[name]}
                                   for name in effects}
    return d
