"""Dataset -> prepared samples and tests for the diagnosis (SI units, noise levels, step instants).

The rig's conventions are inferred from the data (:func:`harness.analysis.identification.conventions.infer_conventions`):
each test's own sample period (any clock start), the step instant of every step test within its sample
interval (``Series.step_delay_s``), how a sampled drive is read between samples (``Series.hold``), the
sweep timing, the noise floors (manifest rig.sensors, else estimated from the data) and the coil radius
(manifest, else derived from T7). Noise model: time series, white noise at the sensor noise floor; sweep
readings, the noise of one reading (floor/sqrt(samples averaged) when the manifest states
``sweep_average_s``, else estimated from the sweeps), at least ``sweep_sigma_floor`` x floor.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from harness.analysis.core import quantized
from harness.analysis.identification.conventions import ConventionError, Conventions, infer_conventions
from harness.data import protocol

from .heldout import declared_unseen

NOISE_COLUMNS = ("displacement_mm", "force_N", "current_A")


class PrepareError(ValueError):
    """The dataset lacks what the diagnosis needs (rig description, tests, a uniform time grid)."""


@dataclass(frozen=True)
class NoiseFloors:
    """Sensor noise floors (one sample's noise std) of the three measured columns."""
    displacement_mm: float
    force_N: float
    current_A: float

    def as_dict(self) -> dict:
        """{"displacement_mm": ..., "force_N": ..., "current_A": ...} (units in the keys)."""
        return {"displacement_mm": self.displacement_mm, "force_N": self.force_N, "current_A": self.current_A}


@dataclass(frozen=True)
class Series:
    """A time-series test prepared for simulation (SI units; y = displacement [m] or force [N]).

    ``k_on``: first sample with the input on (local time 0); ``V_on``: constant voltage [V] after the onset
    (None: replay V on the whole record); ``sig_y``/``sig_I``: noise std of a reading [m or N] / [A];
    ``step_delay_s`` [s]: the step instant lies this long before sample ``k_on`` (0 .. dt, estimated from
    the current's RL rise; ``sd_step_delay_s`` its standard uncertainty); ``hold``: how a replayed voltage is read
    between samples ("zoh" | "linear" | "cubic"); ``weights_y``/``weights_I``: for a channel whose converter's
    rounding shapes its noise (:func:`harness.analysis.core.quantized.detect`), the (offset, scale) per reading its
    residuals are standardized with (:func:`harness.analysis.core.quantized.reading_weights`); None: the noise
    floor alone.
    """
    name: str
    blocked: bool
    r0: float
    field_T: float
    t: np.ndarray
    V: np.ndarray
    I: np.ndarray
    y: np.ndarray
    k_on: int
    V_on: float | None
    sig_y: float
    sig_I: float
    frequency_hz: float | None = None
    step_delay_s: float = 0.0
    hold: str = "zoh"
    sd_step_delay_s: float = 0.0       # [s] standard uncertainty of step_delay_s (0: none estimated)
    weights_y: tuple | None = None     # (offset, scale) per reading of a quantized channel (reading_weights)
    weights_I: tuple | None = None

    @property
    def dt(self) -> float:
        """Sample period [s]."""
        return float(self.t[1] - self.t[0])

    @property
    def t_step_s(self) -> float:
        """The step instant [s] on the record's clock: ``step_delay_s`` before sample ``k_on`` (the conventions'
        estimate within the sample interval; ``t[k_on]`` when none was estimated). Every time "after the step"
        counts from it (evidence windows, settling times), as the simulation does."""
        return float(self.t[self.k_on]) - float(self.step_delay_s)


@dataclass(frozen=True)
class Sweep:
    """A gap sweep: one steady reading per gap (mean over the last avg_s of a hold_s hold from rest).

    ``gaps`` [m], ``I`` [A], ``y`` [m] or [N], ``V_on`` [V], ``hold_s``/``avg_s`` [s]; ``sig_y``/``sig_I``:
    effective noise of a reading (mean of many samples, with a floor); ``floor_y``/``floor_I``: sensor noise
    floor (per sample); ``dt``: sample period of the rig [s] (the simulation step grid); ``fit_mask``: gaps
    simulated inside fits (all when None); ``rel_sd_sig``: {"y", "I": relative standard uncertainty of sig_y,
    sig_I} (0: known, e.g. from the manifest; an estimate from few sweep readings: up to tens of %).
    """
    name: str
    blocked: bool
    field_T: float
    gaps: np.ndarray
    I: np.ndarray
    y: np.ndarray
    V_on: float
    hold_s: float
    avg_s: float
    sig_y: float
    sig_I: float
    floor_y: float
    floor_I: float
    dt: float = 1e-3
    fit_mask: np.ndarray | None = None
    rel_sd_sig: dict | None = None


@dataclass(frozen=True)
class SampleData:
    """One sample as the diagnosis sees it: id, composition, geometry (a, D [m]), field per ampere kB [T/A]
    and its prepared tests {name: Series | Sweep}; ``unseen``: declared unseen by the user (a held-out sample)."""
    sid: str
    wt_pct: float
    diameter_mm: float
    a: float
    D: float
    kB: float
    tests: dict
    unseen: bool = False


@dataclass(frozen=True)
class PreparedDataset:
    """The prepared samples (in dataset order), the sensor noise floors used and the rig conventions
    inferred (:class:`harness.analysis.identification.conventions.Conventions`; its ``as_dict()`` goes into the reports)."""
    samples: tuple
    floors: NoiseFloors
    synthetic: bool = False
    conventions: Conventions | None = None


def noise_floors(ds, conventions: Conventions | None = None) -> NoiseFloors:
    """Sensor noise floors from the manifest's rig.sensors (``harness.data.protocol.noise_floor``), else
    estimated from the data (``protocol.estimate_noise_floor``: quiet pre-step parts, else the steady
    ends' high-frequency residual)."""
    out = {}
    for col in NOISE_COLUMNS:
        v = conventions.noise_floor.get(col) if conventions is not None else protocol.noise_floor(ds.rig, col)
        out[col] = protocol.estimate_noise_floor(ds, col) if v is None else v
    return NoiseFloors(**out)


def _onset(t, V) -> tuple:
    """(index of the step onset or 0, constant voltage [V] after it or None) by the protocol's onset rule."""
    if not np.any(V > 0):
        return 0, None
    k = protocol.step_onset(t, V).index
    level = protocol.step_level(V, k)
    return (k, level) if level is not None else (0, None)


def _prepare_series(sid: str, name: str, t, floors: NoiseFloors, conv: Conventions | None = None) -> Series:
    blocked = t.force_N is not None and t.displacement_mm is None
    y = t.force_N if blocked else t.displacement_mm / 1e3
    k_on, V_on = _onset(t.time_s, t.voltage_V)
    dt = protocol.sample_period(t.time_s)
    if not np.allclose(np.diff(t.time_s), dt, rtol=1e-6, atol=0.0):
        raise PrepareError(f"sample {sid}, test {name}: the diagnosis needs a uniform time grid")
    st = conv.step(sid, name) if conv is not None else None
    own = st is not None and V_on is not None and st.index == k_on
    delay = float(st.step_delay_s) if own else 0.0
    sd_delay = float(st.sd_t_step_s) if own and np.isfinite(st.sd_t_step_s) else 0.0
    hold = conv.sampled_drive_hold if conv is not None else "zoh"
    # the converter's step found in the readings as written (mm, N, A), the displacement's then in m
    sig_y = floors.force_N if blocked else floors.displacement_mm / 1e3
    qy = quantized.detect(t.force_N if blocked else t.displacement_mm, floors.force_N if blocked
                          else floors.displacement_mm)
    if qy is not None and not blocked:
        qy = quantized.Quantization(sigma=qy.sigma / 1e3, q=qy.q / 1e3)
    qI = quantized.detect(t.current_A, floors.current_A)
    return Series(name=name, blocked=blocked, r0=float(t.gap_mm) / 1e3, field_T=float(t.field_T),
                  t=t.time_s, V=t.voltage_V, I=t.current_A, y=y, k_on=k_on, V_on=V_on,
                  sig_y=sig_y, sig_I=floors.current_A,
                  frequency_hz=t.frequency_hz, step_delay_s=delay, hold=hold, sd_step_delay_s=sd_delay,
                  weights_y=None if qy is None else quantized.reading_weights(y, qy),
                  weights_I=None if qI is None else quantized.reading_weights(t.current_A, qI))


@dataclass(frozen=True)
class _SweepRig:
    hold_s: float
    avg_s: float
    dt: float
    sigma_floor: float
    reading_noise: dict      # test -> {col: noise of one reading (unit of col)}
    reading_noise_rel_sd: dict   # test -> {col: relative standard uncertainty of that noise}


def _sweep_voltage(sid: str, name: str, field_T: float, series_v: dict) -> float:
    """Drive voltage of a sweep: the step voltage of a time series at the same nominal field (the rig sets
    the voltage for the field); else scaled by field, else an error."""
    ref = [v for f, v in series_v.values() if abs(f - field_T) < 1e-9]
    if ref:
        return float(np.median(ref))
    if series_v:
        f0, v0 = series_v.get("T5", next(iter(series_v.values())))
        return v0 * field_T / f0
    raise PrepareError(f"sample {sid}, test {name}: no time-series test to infer the drive voltage")


def _prepare_sweep(sid: str, name: str, t, series_v: dict, floors: NoiseFloors, rig: _SweepRig) -> Sweep:
    blocked = name == "T7" or (t.force_N is not None and t.displacement_mm is None)
    y = t.force_N if blocked else t.displacement_mm / 1e3
    Von = _sweep_voltage(sid, name, float(t.field_T), series_v)
    fy = floors.force_N if blocked else floors.displacement_mm / 1e3
    fl_I = floors.current_A
    rn = rig.reading_noise.get(name, {})
    ry = rn.get("force_N" if blocked else "displacement_mm")
    ry = fy if ry is None else (ry if blocked else ry / 1e3)
    rI = rn.get("current_A")
    rI = fl_I if rI is None else rI
    # inside fits: every gap with a reading of at least 5 % of the largest, every third of the others
    big = np.abs(y) >= 0.05 * np.max(np.abs(y)) if y.size else np.zeros(0, bool)
    fit_mask = big | (np.arange(y.size) % 3 == 0)
    rel = rig.reading_noise_rel_sd.get(name, {})
    rel_sd = {"y": float(rel.get("force_N" if blocked else "displacement_mm") or 0.0),
              "I": float(rel.get("current_A") or 0.0)}
    return Sweep(name=name, blocked=blocked, field_T=float(t.field_T), gaps=t.gap_mm / 1e3,
                 I=t.current_A, y=y, V_on=Von, hold_s=rig.hold_s, avg_s=rig.avg_s,
                 sig_y=max(ry, rig.sigma_floor * fy),
                 sig_I=max(rI, rig.sigma_floor * fl_I),
                 floor_y=fy, floor_I=fl_I, dt=rig.dt, fit_mask=fit_mask, rel_sd_sig=rel_sd)


def prepare(ds, settings) -> PreparedDataset:
    """Prepare every sample of dataset ``ds`` (``harness.data.dataset.Dataset``) for the diagnosis.

    Reads the measured tests and the rig description (coil radius, field per ampere, sample period,
    sweep hold and averaging, sensor noise), never the hidden effects or true parameters. ``settings``
    (``DiagnoseSettings``) gives the sweep noise floor factor.
    """
    rig = ds.rig or {}
    try:
        conv = infer_conventions(ds)
    except ConventionError as e:
        raise PrepareError(str(e)) from None
    floors = noise_floors(ds, conv)
    a = float(conv.coil_radius_mm) / 1e3
    timing = conv.sweep
    sweep_rig = _SweepRig(hold_s=timing.hold_s, avg_s=timing.average_s, dt=timing.sample_period_s,
                          sigma_floor=settings.sweep_sigma_floor, reading_noise=conv.sweep_reading_noise,
                          reading_noise_rel_sd=conv.sweep_reading_noise_rel_sd)
    unseen = set(declared_unseen([s.id for s in ds.samples], getattr(settings, "unseen", None)))
    out = []
    for s in ds.samples:
        tests = {}
        kB = rig.get("field_per_amp_T_per_A")
        series_v = {}
        for name, t in s.tests.items():
            if not hasattr(t, "time_s"):
                continue
            test = _prepare_series(s.id, name, t, floors, conv)
            tests[name] = test
            if test.V_on is not None:
                series_v[name] = (float(t.field_T), test.V_on)
            if kB is None and name == "T5":
                k_on = protocol.step_onset(t.time_s, t.voltage_V).index if np.any(t.voltage_V > 0) else 0
                kB = float(t.field_T) / float(np.mean(t.current_A[-max(10, (t.current_A.size - k_on) // 2):]))
        if kB is None:
            raise PrepareError(f"sample {s.id}: no rig.field_per_amp_T_per_A and no T5 to derive it from")
        for name, t in s.tests.items():
            if not hasattr(t, "time_s"):
                tests[name] = _prepare_sweep(s.id, name, t, series_v, floors, sweep_rig)
        out.append(SampleData(sid=s.id, wt_pct=float(s.wt_pct), diameter_mm=float(s.diameter_mm), a=a,
                              D=float(s.diameter_mm) / 1e3, kB=float(kB), tests=dict(sorted(tests.items())),
                              unseen=s.id in unseen))
    if not out:
        raise PrepareError("the dataset has no samples")
    return PreparedDataset(samples=tuple(out), floors=floors, synthetic=bool(getattr(ds, "synthetic", False)),
                           conventions=conv)


def noise_rel_sd(samples) -> dict:
    """{(test, channel "y" | "I"): relative standard uncertainty of the noise level its residuals are divided by}
    over prepared samples (the largest of any sample; sweeps whose reading noise was estimated from the sweeps)."""
    out = {}
    for sd in samples:
        for name, t in sd.tests.items():
            for ch, v in (getattr(t, "rel_sd_sig", None) or {}).items():
                out[(name, ch)] = max(out.get((name, ch), 0.0), float(v))
    return out
