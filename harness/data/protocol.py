"""The test protocol of the paper (Table 2, section 5) in one place.

What every part of the harness must agree on about the tests T1-T8:

* :data:`TESTS`: per test its kind (gap sweep or time series), drive (sweep, step, sine),
  blocked or free, field level [T], gap rule, measured column and CSV columns;
  :data:`IDENTIFICATION_TESTS`: the tests the paper's identification needs.
* Sweep timing: :data:`SWEEP_HOLD_S` (time energized at each gap) and
  :data:`SWEEP_AVERAGE_S` (steady value = mean over the last part of the hold),
  :func:`sweep_timing` (the manifest's values, else these), :func:`sweep_average_mask`.
* Gap rules: :class:`GapRule`, :func:`max_displacement_gap_mm`, :func:`planned_gap_mm`
  (T2-T5 at the gap of maximum T1 displacement + 2 mm, T6 + 3 mm, T8 at 2 mm).
* Drives and their onset: :func:`step_voltage`, :func:`sine_voltage`, and THE step-onset
  rule :func:`step_onset` (first sample above half the maximum voltage),
  :func:`step_level` (the constant voltage of a pure step from rest), :func:`steady_window`
  (where the steady part of a step record begins).
* Sample period: :func:`sample_period` of a record (measured: median spacing of its time
  column), :data:`SAMPLE_PERIOD_S` (the rig's, assumed for sweeps when the manifest has no
  ``rig.sample_period_s``), :func:`time_grid`.
* Noise floor [unit of the column]: :func:`noise_floor` (the manifest's sensor model) and
  :func:`estimate_noise_floor` (from the quiet pre-step part of the records, else the steady ends);
  the array estimators :func:`tail_noise_floor`, :func:`sweep_reading_noise`,
  :func:`pooled_sweep_reading_noise` (a sweep reading's noise from the sweeps themselves) live in
  :mod:`harness.data.noise` and are re-exported here (the one home of the protocol's noise rules).

Pure functions on numbers, arrays and the manifest's ``rig`` dict: nothing here imports
the dataset reader (which imports this module).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, NamedTuple

import numpy as np

from harness.data.noise import (QUIET_MIN_SAMPLES, diff_noise, pooled_sweep_reading_noise,
                                pooled_sweep_reading_noise_rel_sd, sweep_reading_noise, sweep_residuals,
                                tail_noise_floor)

__all__ = [
    "ProtocolError", "NoStepError", "NoiseFloorError", "SamplePeriodError",
    "GapRule", "TestDefinition", "TESTS", "TIME_SERIES_TESTS", "SWEEP_TESTS", "BLOCKED_TESTS",
    "IDENTIFICATION_TESTS", "FIELDS_T",
    "SWEEP_HOLD_S", "SWEEP_AVERAGE_S", "SWEEP_GAPS_MM", "SAMPLE_PERIOD_S", "PRE_STEP_S", "STEP_POST_S",
    "T6_FREQUENCY_HZ", "T6_PERIODS", "T8_GAP_MM", "ONSET_TOLERANCE_S", "QUIET_MIN_SAMPLES",
    "SweepTiming", "sweep_timing", "sweep_average_mask", "time_grid", "sample_period",
    "max_displacement_gap_mm", "planned_gap_mm",
    "step_voltage", "sine_voltage", "StepOnset", "step_onset", "step_level", "steady_window",
    "data_sample_period", "noise_floor", "record_noise_floor", "tail_noise_floor", "sweep_reading_noise",
    "sweep_residuals", "pooled_sweep_reading_noise", "pooled_sweep_reading_noise_rel_sd", "estimate_noise_floor",
    "step_delay_voltage",
]


# ============================================================================ errors
class ProtocolError(ValueError):
    """A record or manifest does not follow the test protocol."""


class NoStepError(ProtocolError):
    """The voltage of a record never rises above 0 V: there is no step (onset) to analyse."""


class NoiseFloorError(ProtocolError):
    """No noise floor can be had: not in the manifest and no quiet pre-step part in the data."""


class SamplePeriodError(ProtocolError):
    """A time column too short, or not increasing, to give a sample period."""


# ============================================================================ timing constants
SWEEP_HOLD_S = 1.5          # [s] time energized at each gap of T1/T7 (one run from rest per gap)
SWEEP_AVERAGE_S = 0.3       # [s] steady value = mean over the last SWEEP_AVERAGE_S of the hold
SWEEP_GAPS_MM = tuple(range(25, -1, -1))   # [mm] T1/T7 gaps: 25 mm down to 0 in 1 mm steps
SAMPLE_PERIOD_S = 1e-3      # [s] the rig's sample period (1 kHz), assumed when a manifest states none
PRE_STEP_S = 0.2            # [s] record before each step (also the T6 drive's start)
STEP_POST_S = 2.8           # [s] record after each step
T6_FREQUENCY_HZ = 1.0       # [Hz] T6 drive frequency
T6_PERIODS = 5              # T6 record: PRE_STEP_S + T6_PERIODS periods
T8_GAP_MM = 2.0             # [mm] fixed gap of T8
ONSET_TOLERANCE_S = 1e-12   # [s] a drive is on from t >= t_on - ONSET_TOLERANCE_S

# ============================================================================ test definitions
_TIME_COLS = ("time_s", "voltage_V", "current_A")
_SWEEP_COLS = ("gap_mm", "current_A")


@dataclass(frozen=True)
class GapRule:
    """Where a test is run: at the gap of maximum T1 displacement + ``offset_mm``, or at ``fixed_mm``.

    Parameters
    ----------
    offset_mm : float or None
        [mm] added to the gap of maximum measured T1 displacement.
    fixed_mm : float or None
        [mm] a fixed gap. Exactly one of the two is given.
    """
    offset_mm: float | None = None
    fixed_mm: float | None = None

    def __post_init__(self):
        if (self.offset_mm is None) == (self.fixed_mm is None):
            raise ProtocolError("GapRule: give exactly one of offset_mm and fixed_mm")

    def gap_mm(self, max_displacement_gap_mm: float | None = None) -> float:
        """The test's gap [mm] given the gap of maximum T1 displacement [mm] (unused for a fixed gap)."""
        if self.fixed_mm is not None:
            return float(self.fixed_mm)
        if max_displacement_gap_mm is None:
            raise ProtocolError("this gap rule needs the gap of maximum T1 displacement")
        return float(max_displacement_gap_mm) + float(self.offset_mm)


@dataclass(frozen=True)
class TestDefinition:
    """One test of paper Table 2.

    Attributes
    ----------
    name : str
        "T1" .. "T8".
    kind : str
        "sweep" (one steady row per gap) or "time_series" (a record in time).
    drive : str
        "sweep" (constant voltage held at each gap), "step" or "sine".
    blocked : bool
        True: the diaphragm is held (force measured), False: free (displacement measured).
    field_T : float
        [T] nominal field level of the drive (step level, sine peak, sweep level).
    measured : str
        The measured response column, "displacement_mm" or "force_N".
    columns : tuple of str
        The CSV columns of the test, in the order the writer uses.
    gap_rule : GapRule or None
        Where a time-series test is run; None for sweeps (every gap of SWEEP_GAPS_MM).
    frequency_hz : float or None
        [Hz] drive frequency of a sine test.
    description : str
        One line, as in the paper's Table 2.
    """
    __test__ = False   # not a pytest test class
    name: str
    kind: str
    drive: str
    blocked: bool
    field_T: float
    measured: str
    columns: tuple[str, ...]
    gap_rule: GapRule | None
    frequency_hz: float | None
    description: str

    @property
    def is_sweep(self) -> bool:
        return self.kind == "sweep"

    @property
    def is_time_series(self) -> bool:
        return self.kind == "time_series"


def _sweep(name, blocked, field_T, description):
    col = "force_N" if blocked else "displacement_mm"
    return TestDefinition(name, "sweep", "sweep", blocked, field_T, col, _SWEEP_COLS + (col,), None, None,
                          description)


def _series(name, drive, blocked, field_T, rule, description, frequency_hz=None):
    col = "force_N" if blocked else "displacement_mm"
    return TestDefinition(name, "time_series", drive, blocked, field_T, col, _TIME_COLS + (col,), rule,
                          frequency_hz, description)


_PLUS2, _PLUS3 = GapRule(offset_mm=2.0), GapRule(offset_mm=3.0)

# Paper, Table 2 (descriptions as the data format documents them).
TESTS: dict[str, TestDefinition] = {
    "T1": _sweep("T1", False, 0.23, "Steady-state displacement vs gap at 0.23 T (gap sweep)"),
    "T2": _series("T2", "step", False, 0.06, _PLUS2, "Displacement step response at 0.06 T, gap = gap of maximum "
                  "T1 displacement + 2 mm"),
    "T3": _series("T3", "step", False, 0.11, _PLUS2, "Displacement step response at 0.11 T, gap = gap of maximum "
                  "T1 displacement + 2 mm"),
    "T4": _series("T4", "step", False, 0.16, _PLUS2, "Displacement step response at 0.16 T, gap = gap of maximum "
                  "T1 displacement + 2 mm"),
    "T5": _series("T5", "step", False, 0.23, _PLUS2, "Displacement step response at 0.23 T, gap = gap of maximum "
                  "T1 displacement + 2 mm"),
    "T6": _series("T6", "sine", False, 0.23, _PLUS3, "Displacement under 1 Hz sinusoidal excitation at 0.23 T, "
                  "gap = gap of maximum T1 displacement + 3 mm", frequency_hz=T6_FREQUENCY_HZ),
    "T7": _sweep("T7", True, 0.23, "Steady-state blocked force vs gap (gap sweep)"),
    "T8": _series("T8", "step", True, 0.23, GapRule(fixed_mm=T8_GAP_MM),
                  "Blocked force step response at 0.23 T, gap 2 mm"),
}
TIME_SERIES_TESTS: tuple[str, ...] = tuple(n for n, d in TESTS.items() if d.is_time_series)
SWEEP_TESTS: tuple[str, ...] = tuple(n for n, d in TESTS.items() if d.is_sweep)
BLOCKED_TESTS: tuple[str, ...] = tuple(n for n, d in TESTS.items() if d.blocked)
FIELDS_T: dict[str, float] = {n: d.field_T for n, d in TESTS.items()}
IDENTIFICATION_TESTS: tuple[str, ...] = ("T3", "T5", "T8")   # what the paper's identification needs


# ============================================================================ gaps
def max_displacement_gap_mm(gap_mm, displacement_mm) -> float:
    """Gap [mm] of the largest T1 displacement (the first such row if several are equal).

    Parameters
    ----------
    gap_mm : array_like
        [mm] T1 gaps.
    displacement_mm : array_like
        [mm] T1 steady displacements, same length.
    """
    g = np.asarray(gap_mm, dtype=float)
    x = np.asarray(displacement_mm, dtype=float)
    if g.ndim != 1 or g.shape != x.shape or g.size == 0:
        raise ProtocolError(f"T1 gaps and displacements must be 1-D of equal non-zero length, got {g.shape} "
                            f"and {x.shape}")
    return float(g[int(np.argmax(x))])


def planned_gap_mm(test: str, max_displacement_gap: float | None = None) -> float:
    """Gap [mm] of a time-series test by its gap rule (T2-T5: +2 mm, T6: +3 mm, T8: 2 mm).

    Parameters
    ----------
    test : str
        "T2" .. "T6" or "T8".
    max_displacement_gap : float, optional
        [mm] gap of maximum T1 displacement (see :func:`max_displacement_gap_mm`).
    """
    d = TESTS.get(test)
    if d is None or d.gap_rule is None:
        raise ProtocolError(f"{test!r} has no gap rule (time-series tests: {', '.join(TIME_SERIES_TESTS)})")
    return d.gap_rule.gap_mm(max_displacement_gap)


# ============================================================================ timing
@dataclass(frozen=True)
class SweepTiming:
    """Timing of a gap sweep point: ``hold_s`` [s] energized from rest, steady value = mean over the
    last ``average_s`` [s], sampled every ``sample_period_s`` [s]; ``*_source`` say where each came
    from: "manifest" (its ``rig`` key), "data" (median spacing of the time-series records) or
    "default" (the protocol's constant). ``average_source == "default"``: the manifest does not say
    how a reading was made (single sample or average), so its noise must be estimated from the sweep
    itself (:func:`sweep_reading_noise`); ``average_s`` is then only the window of the simulated reading."""
    hold_s: float = SWEEP_HOLD_S
    average_s: float = SWEEP_AVERAGE_S
    sample_period_s: float = SAMPLE_PERIOD_S
    hold_source: str = "default"
    average_source: str = "default"
    sample_period_source: str = "default"

    @property
    def readings_averaged(self) -> float | None:
        """Samples averaged per reading, average_s / sample_period_s (at least 1), when the manifest
        states ``sweep_average_s``; else None (unknown)."""
        if self.average_source != "manifest":
            return None
        return max(1.0, self.average_s / self.sample_period_s)


def _rig_dict(rig) -> dict:
    if hasattr(rig, "rig") and isinstance(getattr(rig, "rig"), dict):   # a Dataset
        rig = rig.rig
    return rig if isinstance(rig, dict) else {}


def data_sample_period(data) -> float | None:
    """Median sample period [s] of the time-series records of a dataset (or records), None without any."""
    periods = []
    for rec in _records(data):
        t = getattr(rec, "time_s", None)
        if t is not None and np.size(t) >= 2:
            periods.append(sample_period(t))
    return float(np.median(periods)) if periods else None


def sweep_timing(rig=None) -> SweepTiming:
    """Sweep timing from the manifest's ``rig`` (keys ``sweep_hold_s``, ``sweep_average_s``,
    ``sample_period_s`` [s]; ``sweep_single_reading: true`` says a reading is one sample, the last of the hold, as
    ``sweep_average_s`` of one sample period would); a missing sample period from the data (when ``rig`` is a Dataset:
    :func:`data_sample_period`), else the protocol's :data:`SWEEP_HOLD_S`, :data:`SWEEP_AVERAGE_S`,
    :data:`SAMPLE_PERIOD_S`.

    Parameters
    ----------
    rig : dict or Dataset or None
        The manifest's ``rig`` object (or a dataset holding it).
    """
    r = _rig_dict(rig)
    hold, hsrc = (float(r["sweep_hold_s"]), "manifest") if "sweep_hold_s" in r else (SWEEP_HOLD_S, "default")
    avg, asrc = ((float(r["sweep_average_s"]), "manifest") if "sweep_average_s" in r
                 else (min(SWEEP_AVERAGE_S, hold), "default"))
    if "sample_period_s" in r:
        dt, dsrc = float(r["sample_period_s"]), "manifest"
    else:
        dd = data_sample_period(rig) if getattr(rig, "samples", None) is not None else None
        dt, dsrc = (dd, "data") if dd is not None else (SAMPLE_PERIOD_S, "default")
    if r.get("sweep_single_reading") is True and "sweep_average_s" not in r:
        avg, asrc = dt, "manifest"           # a reading is one sample: the last of the hold
    return SweepTiming(hold_s=hold, average_s=avg, sample_period_s=dt, hold_source=hsrc, average_source=asrc,
                       sample_period_source=dsrc)


def time_grid(duration_s: float, sample_period_s: float = SAMPLE_PERIOD_S) -> np.ndarray:
    """Uniform grid 0 .. duration_s [s] (round(duration/period) + 1 points) at ``sample_period_s`` [s]."""
    n = int(round(duration_s / sample_period_s))
    return np.arange(n + 1) * sample_period_s


def sweep_average_mask(t, average_s: float = SWEEP_AVERAGE_S) -> np.ndarray:
    """Samples of a hold record averaged for its steady value: t >= t[-1] - average_s + 1e-12.

    Parameters
    ----------
    t : array_like
        [s] time of the hold record (from 0 to the hold time).
    average_s : float
        [s] length of the averaging window at the end of the hold.

    Returns
    -------
    numpy.ndarray of bool
        On the 1 ms grid of a 1.5 s hold: the last 300 samples (t = 1.201 .. 1.5 s).
    """
    t = np.asarray(t, dtype=float)
    return t >= t[-1] - average_s + 1e-12


def sample_period(t) -> float:
    """Sample period [s] of a record: the median spacing of its time column [s].

    Raises
    ------
    SamplePeriodError
        Fewer than two samples, or a non-positive median spacing.
    """
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise SamplePeriodError(f"a sample period needs a 1-D time column of at least 2 samples, got shape {t.shape}")
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        raise SamplePeriodError(f"the time column is not increasing (median spacing {dt!r} s)")
    return dt


# ============================================================================ drives and onset
def step_voltage(t, V: float, t_on: float = PRE_STEP_S) -> np.ndarray:
    """Step drive: 0 V before ``t_on`` [s], ``V`` [V] from t >= t_on - ONSET_TOLERANCE_S on."""
    return np.where(t >= t_on - ONSET_TOLERANCE_S, V, 0.0)


def sine_voltage(t, V_peak: float, f: float = T6_FREQUENCY_HZ, t_on: float = PRE_STEP_S) -> np.ndarray:
    """Raised-cosine drive 0..``V_peak`` [V] at ``f`` [Hz] from ``t_on`` [s] (a unipolar sine: the
    force goes with I^2)."""
    tau = np.clip(t - t_on, 0.0, None)
    return np.where(t >= t_on - ONSET_TOLERANCE_S, 0.5 * V_peak * (1.0 - np.cos(2 * np.pi * f * tau)), 0.0)


class StepOnset(NamedTuple):
    """Onset of a step: ``time_s`` [s] and ``index`` of the first sample above half the maximum voltage."""
    time_s: float
    index: int


def step_onset(t, V) -> StepOnset:
    """THE step-onset rule: the first sample at which the voltage exceeds half its maximum.

    Parameters
    ----------
    t : array_like
        [s] time column.
    V : array_like
        [V] voltage column, same length.

    Returns
    -------
    StepOnset
        ``(time_s, index)``: the onset instant [s] and its sample index.

    Raises
    ------
    NoStepError
        The voltage never rises above 0 V.
    """
    V = np.asarray(V, dtype=float)
    if not np.any(V > 0):
        raise NoStepError("the voltage never rises above 0 V: no step to analyse")
    k = _onset_index(V)
    return StepOnset(float(np.asarray(t, dtype=float)[k]), k)


def _onset_index(V: np.ndarray) -> int:
    """Index of the first sample above half the maximum of V (V must rise above 0)."""
    return int(np.argmax(V > 0.5 * np.max(V)))


def step_level(V, index: int) -> float | None:
    """Voltage [V] of a pure step from rest at sample ``index``, else None.

    A pure step: exactly 0 V before ``index`` and constant from it on (peak-to-peak at most
    1e-9 of the level), with at least two samples from the onset on.
    """
    V = np.asarray(V, dtype=float)
    post = V[index:]
    if np.all(V[:index] == 0.0) and post.size > 1 and np.ptp(post) <= 1e-9 * max(abs(float(post[0])), 1e-12):
        return float(post[0])
    return None


def step_delay_voltage(t, V, index: int, step_delay_s: float) -> np.ndarray:
    """The voltage of a step record for a simulator that holds each sample over its interval (zero-order
    hold), with the step at ``t[index] - step_delay_s`` instead of at a sample.

    The interval [t[index-1], t[index]) that holds the step gets its mean voltage,
    V[index] * step_delay_s / (t[index] - t[index-1]) (the same volt-seconds): exact to first order in
    the sample period over the coil's time constant, and exact for everything slower (the mechanics).
    A copy; ``V`` itself unchanged. ``step_delay_s`` [s] in [0, sample period].
    """
    V = np.array(V, dtype=float)
    t = np.asarray(t, dtype=float)
    k = int(index)
    if k < 1:
        return V
    dt = float(t[k] - t[k - 1])
    frac = min(max(float(step_delay_s) / dt, 0.0), 1.0)
    V[k - 1] = V[k - 1] + (V[k] - V[k - 1]) * frac
    return V


def steady_window(n_samples: int, onset_index: int, fraction: float = 0.5) -> slice:
    """The steady part of a step record: the last ``fraction`` of the samples from the onset on,
    at least the last 10 samples.

    Parameters
    ----------
    n_samples : int
        Samples in the record.
    onset_index : int
        Index of the step onset (:func:`step_onset`).
    fraction : float
        Part [-] of the post-onset record taken as steady.

    Returns
    -------
    slice
        ``slice(n_samples - max(10, int(fraction * (n_samples - onset_index))), None)``.
    """
    n = int(n_samples)
    return slice(n - max(10, int(fraction * (n - int(onset_index)))), None)


# ============================================================================ noise floor
def noise_floor(rig, column: str, quantization: bool = True) -> float | None:
    """Sensor noise floor [unit of ``column``] from the manifest's sensor model, or None.

    Parameters
    ----------
    rig : dict or Dataset or None
        The manifest's ``rig`` object (``rig.sensors.<column>``), or a dataset holding it.
    column : str
        "displacement_mm" [mm], "force_N" [N] or "current_A" [A].
    quantization : bool
        True (the diagnosis' convention): the noise floor sqrt(sigma^2 + q^2/12) of white noise
        sigma and quantization step q, as the manifest states it (``noise_floor``; a sensor
        entry without it: its ``noise_sigma``); only positive finite values count.
        False (the identification's and protocol replay's convention): the white-noise std
        sigma alone (``noise_sigma``), as stated.

    Returns
    -------
    float or None
        None when the manifest does not state it (then estimate it from the data:
        :func:`estimate_noise_floor`).
    """
    rig = rig.rig if hasattr(rig, "rig") and isinstance(getattr(rig, "rig"), dict) else rig
    if not quantization:
        try:
            return float(rig["sensors"][column]["noise_sigma"])
        except (KeyError, TypeError, ValueError):
            return None
    try:
        s = ((rig or {}).get("sensors") or {})[column]
        v = float(s.get("noise_floor", s.get("noise_sigma")))
    except (KeyError, TypeError, ValueError, AttributeError):
        return None
    return v if (v > 0 and math.isfinite(v)) else None


def record_noise_floor(V, y) -> float | None:
    """Noise floor [unit of y] of one record from its quiet part before the step, or None.

    The quiet part is every sample before :func:`step_onset` (the whole record if the voltage
    never rises above 0 V); it needs at least :data:`QUIET_MIN_SAMPLES` samples. Estimate from the
    first differences d = diff(y) (they remove a slow drift): 1.4826 * MAD(d) / sqrt(2) (the median
    absolute deviation ignores outliers); for coarsely quantized readings (fewer than 8 distinct
    differences) the RMS of d / sqrt(2) instead, which includes the quantization (q^2/12).

    Parameters
    ----------
    V : array_like
        [V] voltage column.
    y : array_like
        Response column (displacement [mm], force [N] or current [A]), same length.
    """
    y = np.asarray(y, dtype=float)
    V = np.asarray(V, dtype=float)
    k = _onset_index(V) if np.any(V > 0) else y.size
    seg = y[:max(k, 0)]
    if seg.size < QUIET_MIN_SAMPLES:
        return None
    return diff_noise(np.diff(seg), 1)


def _records(data) -> Iterable[Any]:
    samples = getattr(data, "samples", None)
    if samples is not None:
        for s in samples:
            yield from s.tests.values()
    else:
        yield from data


def estimate_noise_floor(data, column: str) -> float:
    """Noise floor [unit of ``column``] estimated from the data: the median over the time-series
    records of :func:`record_noise_floor` (quiet part before the step); when no record has one, the
    median of :func:`tail_noise_floor` (high-frequency residual of the steady end) of the step records.

    Parameters
    ----------
    data : Dataset or iterable of records
        A dataset (every test of every sample) or records with ``time_s``, ``voltage_V`` and
        the column as attributes (sweeps, without ``time_s``, are skipped).
    column : str
        "displacement_mm" [mm], "force_N" [N] or "current_A" [A].

    Raises
    ------
    NoiseFloorError
        No record has a quiet part before its step, or the estimate is not positive.
    """
    vals, tails = [], []
    for rec in _records(data):
        y = getattr(rec, column, None)
        if y is None or not hasattr(rec, "time_s"):
            continue
        v = record_noise_floor(rec.voltage_V, y)
        if v is not None:
            vals.append(v)
        elif getattr(rec, "frequency_hz", None) is None:      # a step record without a quiet part
            v = tail_noise_floor(y)
            if v is not None:
                tails.append(v)
    vals = vals or tails
    v = float(np.median(vals)) if vals else 0.0
    if not v > 0:
        raise NoiseFloorError(f"cannot estimate the noise of {column}: the manifest has no "
                              f"rig.sensors.{column}.noise_floor and no record has a quiet part before the step")
    return v
