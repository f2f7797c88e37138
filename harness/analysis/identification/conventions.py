"""Rig conventions inferred from a dataset, for any rig: what identification and diagnosis assume, stated.

A dataset from another rig differs from ours in how it was recorded, not only in what it measured.
:func:`infer_conventions` reads those conventions from the data (the manifest's ``rig`` values when it
states them) and :meth:`Conventions.as_dict` states them in every report (units in the keys):

* **Sample period and clock** of every time-series test: its own (median spacing of its time column);
  the clock may start anywhere (``clock_start_s``: its first time stamp; only differences are used).
* **Step instant** of every step test (a pure step from rest): within the sample interval before the
  first sample that reads the new voltage, fitted jointly with L/R to the current's RL rise
  (:func:`harness.analysis.identification.analytic.step_instant`). Between samples the voltage is read as the README's
  data format says: 0 (the pre-step value) until the step instant, the step voltage from it on, each
  later sample's voltage held over its interval.
* **Sampled drives** (T6): the voltage between samples either held (``"zoh"``, as a co-simulation master
  or a DAC without reconstruction filter does), linear (``"linear"``, an analog drive sampled fast) or a
  cubic spline through the samples (``"cubic"``, an analog drive sampled slowly: at 105 Hz a 1.9 Hz
  sine read linear leaves 0.05 % of its current, 1.9x the noise variance of a Hall sensor). Decided from
  the data: the exact RL current of each sample's T6 for every reading, with R and L of the same
  sample's T5 step fit, against the measured current (sum of squared residuals over the samples; the
  smallest wins); with no T6 or no T5 fit: ``"linear"``.
* **Sweep readings** (T1, T7): timing from ``rig.sweep_hold_s`` / ``sweep_average_s`` /
  ``sample_period_s`` (the period else from the time series); the noise of one reading is the sensor
  noise floor / sqrt(samples averaged) when the manifest states ``sweep_average_s``, else estimated from
  the sweeps themselves (:func:`harness.data.protocol.pooled_sweep_reading_noise`, over all samples).
* **Noise** of every channel: estimated from the data always (quiet pre-step parts, else the
  high-frequency residual of the steady ends: :func:`harness.data.protocol.estimate_noise_floor`); the
  manifest's sensor model, when it has one, is what is used (and the estimate is stated beside it).
* **Coil**: ``rig.coil_radius_mm`` else derived from the T7 blocked-force sweeps (the loop radius a whose
  force kernel G(gap; a, D) shape fits every sample's F = Em I^2 G with one Em per sample, bounded
  scalar least squares; its standard uncertainty from the curvature); ``field_per_amp_T_per_A`` else
  derived per sample from T5 (field_T / steady current, :mod:`harness.analysis.identification.analytic`).

Only the measured columns and the manifest's rig description are read (never hidden effects or truths).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fmu_src.field import force_kernel
from harness.analysis.identification import analytic
from harness.data import protocol

__all__ = ["ConventionError", "StepInstant", "Conventions", "infer_conventions", "coil_radius_from_t7", "held_step_voltage",
           "write_conventions", "conventions_summary_lines", "step_instants", "NOISE_COLUMNS", "SWEEP_CHANNELS"]

NOISE_COLUMNS = ("displacement_mm", "force_N", "current_A")
SWEEP_CHANNELS = {"T1": ("displacement_mm", "current_A"), "T7": ("force_N", "current_A")}
_A_BOUNDS_M = (1e-3, 0.2)      # [m] search range of a derived loop radius


class ConventionError(ValueError):
    """A convention the data cannot give (e.g. no coil radius in the manifest and no T7 to derive it)."""


@dataclass(frozen=True)
class StepInstant:
    """Step instant of one step test: ``t_step_s`` [s] on the record's clock (``sd_t_step_s`` its standard
    uncertainty), ``step_delay_s`` [s] from it to the first sample of the step (0 .. ``sample_period_s``),
    ``index`` that sample; R_Ohm, L_H of the same RL fit."""
    t_step_s: float
    sd_t_step_s: float
    step_delay_s: float
    sample_period_s: float
    index: int
    R_Ohm: float
    L_H: float


@dataclass(frozen=True)
class Conventions:
    """What a dataset's rig does, as inferred (see the module docstring). Units in the attribute names;
    ``*_source``: "manifest", "data" or "default". Frozen: derived once (:func:`infer_conventions`), then
    only read."""
    noise_floor: dict = field(default_factory=dict)          # col -> floor used (one sample's noise std)
    noise_sigma: dict = field(default_factory=dict)          # col -> white-noise sigma used (identify, metrics)
    noise_source: dict = field(default_factory=dict)         # col -> "manifest" | "data"
    noise_estimated: dict = field(default_factory=dict)      # col -> the data's estimate (None: none)
    sweep: protocol.SweepTiming = field(default_factory=protocol.SweepTiming)
    sweep_reading_noise: dict = field(default_factory=dict)  # test -> {col: noise of one reading}
    sweep_reading_noise_rel_sd: dict = field(default_factory=dict)  # test -> {col: its relative uncertainty}
    sweep_reading_noise_source: str = "data"
    sample_period_s: dict = field(default_factory=dict)      # sid -> {test: period [s]}
    clock_start_s: dict = field(default_factory=dict)        # sid -> {test: first time stamp [s]}
    steps: dict = field(default_factory=dict)                # sid -> {test: StepInstant}
    step_notes: list = field(default_factory=list)
    sampled_drive_hold: str = "linear"
    sampled_drive_sse: dict = field(default_factory=dict)    # {"zoh": .., "linear": .., "cubic": ..} [A^2]
    coil_radius_mm: float | None = None
    sd_coil_radius_mm: float | None = None
    coil_radius_source: str = "manifest"
    field_per_amp_T_per_A: float | None = None
    field_per_amp_source: str = "manifest"

    def effective_rig(self, rig: dict | None) -> dict:
        """A copy of the manifest's ``rig`` completed with what was inferred: ``coil_radius_mm`` (and its standard
        uncertainty ``sd_coil_radius_mm``) when derived,
        ``sensors.<col>.noise_sigma`` / ``noise_floor`` from the data where the manifest has none (the
        keys the identification and the metrics read)."""
        out = dict(rig or {})
        if out.get("coil_radius_mm") is None and self.coil_radius_mm is not None:
            out["coil_radius_mm"] = self.coil_radius_mm
            if self.sd_coil_radius_mm:                 # derived: its uncertainty reaches Em, K1, K2
                out["sd_coil_radius_mm"] = self.sd_coil_radius_mm
        sensors = {k: dict(v) if isinstance(v, dict) else v for k, v in (out.get("sensors") or {}).items()}
        for col in NOISE_COLUMNS:
            if self.noise_source.get(col) == "data":
                entry = sensors.get(col) if isinstance(sensors.get(col), dict) else {}
                entry = dict(entry, noise_sigma=self.noise_sigma[col], noise_floor=self.noise_floor[col])
                sensors[col] = entry
        out["sensors"] = sensors
        return out

    def step(self, sid: str, test: str) -> StepInstant | None:
        """The step instant of a sample's test, None when it has none (not a pure step, or no fit)."""
        return self.steps.get(sid, {}).get(test)

    def as_dict(self) -> dict:
        """The conventions for a report (JSON-ready; units in the keys)."""
        periods = sorted({round(v, 15) for d in self.sample_period_s.values() for v in d.values()})
        clocks = [v for d in self.clock_start_s.values() for v in d.values()]
        delays = [st.step_delay_s / st.sample_period_s for d in self.steps.values() for st in d.values()]
        return {
            "time_series": {
                "sample_periods_s": periods,
                "sample_period_s_by_test": self.sample_period_s,
                "clock_start_s_range": [min(clocks), max(clocks)] if clocks else None,
                "voltage_between_samples": {
                    "step_tests": "0 V (the pre-step value) until the step instant estimated within the sample "
                                  "interval from the current's RL rise, the step voltage from then on, each "
                                  "later sample held over its interval",
                    "sampled_drives": self.sampled_drive_hold,
                    "sampled_drive_current_sse_A2": self.sampled_drive_sse,
                },
                "step_instants": {sid: {n: {"t_step_s": st.t_step_s, "sd_t_step_s": st.sd_t_step_s,
                                            "step_delay_s": st.step_delay_s}
                                        for n, st in d.items()} for sid, d in self.steps.items()},
                "step_delay_fraction_of_period_range": [min(delays), max(delays)] if delays else None,
                "step_notes": list(self.step_notes),
            },
            "sweeps": {"hold_s": self.sweep.hold_s, "hold_source": self.sweep.hold_source,
                       "average_s": self.sweep.average_s, "average_source": self.sweep.average_source,
                       "sample_period_s": self.sweep.sample_period_s,
                       "sample_period_source": self.sweep.sample_period_source,
                       "reading_noise": self.sweep_reading_noise,
                       "reading_noise_source": self.sweep_reading_noise_source},
            "noise": {col: {"floor": self.noise_floor.get(col), "sigma": self.noise_sigma.get(col),
                            "source": self.noise_source.get(col),
                            "estimated_from_data": self.noise_estimated.get(col)} for col in NOISE_COLUMNS},
            "noise_units": {"displacement_mm": "mm", "force_N": "N", "current_A": "A"},
            "coil": {"coil_radius_mm": self.coil_radius_mm, "sd_coil_radius_mm": self.sd_coil_radius_mm,
                     "coil_radius_source": self.coil_radius_source,
                     "field_per_amp_T_per_A": self.field_per_amp_T_per_A,
                     "field_per_amp_source": self.field_per_amp_source},
        }

    def summary_lines(self) -> list[str]:
        """A few lines for the Markdown reports (:func:`conventions_summary_lines` of :meth:`as_dict`)."""
        return conventions_summary_lines(self.as_dict())


def conventions_summary_lines(d: dict) -> list[str]:
    """Markdown lines of a :meth:`Conventions.as_dict` dict (as diagnosis.json and identification.json hold it)."""
    ts, sw, coil, noise = d["time_series"], d["sweeps"], d["coil"], d["noise"]
    per = ", ".join(f"{p * 1e3:g} ms" for p in ts["sample_periods_s"])
    lines = [f"- sample periods (each test its own): {per}; clocks start at "
             f"{ts['clock_start_s_range'][0]:g} .. {ts['clock_start_s_range'][1]:g} s"
             if ts["clock_start_s_range"] else "- no time series"]
    vb = ts["voltage_between_samples"]
    if ts["step_delay_fraction_of_period_range"]:
        lo, hi = ts["step_delay_fraction_of_period_range"]
        lines.append(f"- step instants from the current's RL rise: {lo:.2f} .. {hi:.2f} sample periods before the "
                     f"first sample of the step")
    lines.append(f"- sampled drives (T6) read as `{vb['sampled_drives']}` between samples"
                 + (" (current residual sum of squares " + ", ".join(f"{k} {v:.3g} A^2" for k, v in
                                                                 vb["sampled_drive_current_sse_A2"].items()) + ")"
                    if vb["sampled_drive_current_sse_A2"] else " (no sampled drive to decide it: default)"))
    rn = "; ".join(f"{t}: " + ", ".join(f"{c} {v:.3g}" for c, v in cols.items() if v is not None)
                   for t, cols in sw["reading_noise"].items())
    avg = f"{sw['average_s']:g} s" if sw["average_source"] == "manifest" else "not stated"
    lines.append(f"- sweep readings: hold {sw['hold_s']:g} s ({sw['hold_source']}), average {avg}, sample period "
                 f"{sw['sample_period_s'] * 1e3:g} ms ({sw['sample_period_source']}); noise of one reading "
                 f"({sw['reading_noise_source']}): {rn}")
    parts = []
    for c, v in noise.items():
        if v.get("floor") is None:
            parts.append(f"{c} unknown")
            continue
        est = v.get("estimated_from_data")
        parts.append(f"{c} {v['floor']:.3g} ({v['source']}" + (f"; data {est:.3g})" if est is not None else ")"))
    lines.append("- noise floors (units in the names): " + "; ".join(parts))
    a = coil["coil_radius_mm"]
    a_txt = "unknown" if a is None else (f"{a:.4g} mm ({coil['coil_radius_source']}"
                                         + (f", sd {coil['sd_coil_radius_mm']:.2g} mm)" if coil["sd_coil_radius_mm"]
                                            else ")"))
    kb = coil["field_per_amp_T_per_A"]
    kb_txt = f"{kb:.4g} T/A ({coil['field_per_amp_source']})" if kb else coil["field_per_amp_source"]
    lines.append(f"- coil radius {a_txt}; field per ampere {kb_txt}")
    return lines


# ============================================================================ pieces
class _Fields(dict):
    """Some fields of a :class:`Conventions` being derived (attribute access), before it is built frozen."""
    __getattr__ = dict.__getitem__
    __setattr__ = dict.__setitem__


def _noise(ds) -> dict:
    c = _Fields(noise_floor={}, noise_sigma={}, noise_source={}, noise_estimated={})
    for col in NOISE_COLUMNS:
        try:
            est = protocol.estimate_noise_floor(ds, col)
        except protocol.NoiseFloorError:
            est = None
        c.noise_estimated[col] = est
        floor = protocol.noise_floor(ds.rig, col)
        sigma = protocol.noise_floor(ds.rig, col, quantization=False)
        if floor is not None:
            c.noise_floor[col], c.noise_source[col] = floor, "manifest"
            c.noise_sigma[col] = sigma if sigma is not None else floor
        elif est is not None:
            c.noise_floor[col] = c.noise_sigma[col] = est
            c.noise_source[col] = "data"
        else:
            c.noise_floor[col] = c.noise_sigma[col] = None
            c.noise_source[col] = "none"
    return c


def _sweeps(c: "_Fields", ds) -> dict:
    c = _Fields(noise_floor=c.noise_floor, sweep_reading_noise={}, sweep_reading_noise_rel_sd={})
    c.sweep = protocol.sweep_timing(ds)
    n_avg = c.sweep.readings_averaged
    c.sweep_reading_noise_source = ("manifest sweep_average_s: noise floor / sqrt(samples averaged)"
                                    if n_avg is not None else "estimated from the sweeps themselves")
    for test, cols in SWEEP_CHANNELS.items():
        have = [s.tests[test] for s in ds.samples if test in s.tests]
        if not have:
            continue
        out, rel = {}, {}
        for col in cols:
            if n_avg is not None and c.noise_floor.get(col) is not None:
                out[col], rel[col] = c.noise_floor[col] / math.sqrt(n_avg), 0.0
            else:
                pairs = [(t.gap_mm, getattr(t, col)) for t in have]
                out[col] = protocol.pooled_sweep_reading_noise(pairs)
                rel[col] = protocol.pooled_sweep_reading_noise_rel_sd(pairs) or 0.0
        c.sweep_reading_noise[test] = out
        c.sweep_reading_noise_rel_sd[test] = rel
    del c["noise_floor"]
    return c


def _step_test(name: str, ts) -> analytic.StepTest:
    y = ts.force_N if ts.force_N is not None else ts.displacement_mm
    return analytic.StepTest(name, ts.time_s, ts.voltage_V, ts.current_A, np.asarray(y, dtype=float),
                             float(ts.gap_mm or 0.0) / 1e3, float(ts.field_T), response_name="response")


_FIT = object()      # held_step_voltage: fit the step instant from the record (no instant given)


def _step_onset(ts) -> tuple[np.ndarray, int] | None:
    """(voltage, index of the step's first sample) of a step record with a step level; None for anything else."""
    V = np.asarray(ts.voltage_V, dtype=float)
    if not np.any(V > 0):
        return None
    k = protocol.step_onset(ts.time_s, V).index
    return None if protocol.step_level(V, k) is None else (V, k)


def _instant(name: str, ts, instant):
    """``instant`` itself, or (``_FIT``) the step instant fitted from the record, None where it cannot be."""
    if instant is not _FIT:
        return instant
    try:
        return analytic.step_instant(_step_test(name, ts))
    except (analytic.AnalyticError, ValueError, np.linalg.LinAlgError):
        return None


def step_onset_from_rest(name: str, ts, instant=_FIT) -> float | None:
    """The step's delay [s] before its first sample (``StepInstant.step_delay_s``, 0 .. the sample period) when
    ``ts`` is a pure step from rest: zero voltage up to the step's first sample, a step level, a step instant
    (``instant`` as for :func:`held_step_voltage`; fitted when not given). None otherwise. A simulator that
    can start the step between samples (:func:`harness.sim.population.prepare_test`'s ``onset_delay_s``)
    takes the recorded voltage and this delay instead of a held voltage."""
    step = _step_onset(ts)
    if step is None or step[1] < 1 or np.any(step[0][:step[1]] != 0.0):
        return None
    k = step[1]
    instant = _instant(name, ts, instant)
    if instant is None or int(getattr(instant, "index", k)) != k:
        return None
    dt = float(ts.time_s[k] - ts.time_s[k - 1])
    return min(max(float(instant.step_delay_s), 0.0), dt)


def held_step_voltage(name: str, ts, coil_tau_s: float | None = None, instant=_FIT) -> np.ndarray:
    """The voltage of a dataset time series ``ts`` for a simulator that holds each sample over its interval
    (FMU replay, the identification's objectives): for a pure step from rest, the step at the instant
    estimated within the sample interval (:func:`harness.analysis.identification.analytic.step_instant`) as the mean
    voltage of the interval holding it (:func:`harness.data.protocol.step_delay_voltage`); otherwise (or
    when no instant can be fitted) the recorded voltage. A new array or ``ts.voltage_V`` itself.

    coil_tau_s [s]: the coil's L/R. Given, the interval's held voltage is the one that brings the RL coil's
    current to the true step's value at the interval's end, V (1 - exp(-delay/tau)) / (1 - exp(-dt/tau))
    (from then on the current is exact), instead of the mean voltage, which is exact only to first order in
    dt/tau (at 250 Hz and tau = 8 ms the current then lags by about 0.2 ms: C, m biased by 1-2 %).

    instant: the test's :class:`StepInstant` as already derived (:meth:`Conventions.step`, None: it has
    none, the recorded voltage), instead of fitting it again from the record (the same fit, the same value)."""
    step = _step_onset(ts)
    if step is None:
        return ts.voltage_V
    V, k = step
    instant = _instant(name, ts, instant)
    if instant is None:
        return ts.voltage_V
    if coil_tau_s is None or not (coil_tau_s > 0) or k < 1:
        return protocol.step_delay_voltage(ts.time_s, V, k, instant.step_delay_s)
    V = np.array(V, dtype=float)
    dt = float(ts.time_s[k] - ts.time_s[k - 1])
    delay = min(max(float(instant.step_delay_s), 0.0), dt)
    V[k - 1] += (V[k] - V[k - 1]) * math.expm1(-delay / coil_tau_s) / math.expm1(-dt / coil_tau_s)
    return V


def step_instants(sample, tests=None, notes: list | None = None) -> dict:
    """{test: :class:`StepInstant`} of the pure steps of one sample (every time series, or those named in
    ``tests``), each fitted once (:func:`harness.analysis.identification.analytic.step_instant`); a step
    whose instant cannot be fitted is left out (a line in ``notes``)."""
    out = {}
    for name, ts in sample.tests.items():
        if not hasattr(ts, "time_s") or (tests is not None and name not in tests):
            continue
        V = np.asarray(ts.voltage_V, dtype=float)
        if not np.any(V > 0):
            continue
        k = protocol.step_onset(ts.time_s, V).index
        if protocol.step_level(V, k) is None:
            continue
        try:
            fit = analytic.step_instant(_step_test(name, ts))
        except (analytic.AnalyticError, ValueError, np.linalg.LinAlgError) as e:
            if notes is not None:
                notes.append(f"{sample.id} {name}: no step instant ({e}); step taken at its first sample")
            continue
        out[name] = StepInstant(t_step_s=fit.t_step_s, sd_t_step_s=fit.sd_t_step_s, step_delay_s=fit.step_delay_s,
                                sample_period_s=fit.sample_period_s, index=k, R_Ohm=fit.L_H / fit.tau_s,
                                L_H=fit.L_H)
    return out


def _steps(ds) -> dict:
    c = _Fields(sample_period_s={}, clock_start_s={}, steps={}, step_notes=[])
    for s in ds.samples:
        for name, ts in s.tests.items():
            if hasattr(ts, "time_s"):
                c.sample_period_s.setdefault(s.id, {})[name] = protocol.sample_period(ts.time_s)
                c.clock_start_s.setdefault(s.id, {})[name] = float(ts.time_s[0])
        found = step_instants(s, notes=c.step_notes)
        if found:
            c.steps[s.id] = found
    return c


def _sampled_drive_hold(steps: dict, ds) -> dict:
    c = _Fields()
    sse = {"zoh": 0.0, "linear": 0.0, "cubic": 0.0}
    n = 0
    for s in ds.samples:
        ref = steps.get(s.id, {}).get("T5")
        for name, ts in s.tests.items():
            if ref is None or not hasattr(ts, "time_s") or steps.get(s.id, {}).get(name) is not None:
                continue
            if protocol.TESTS.get(name) is None or protocol.TESTS[name].drive != "sine":
                continue
            I = np.asarray(ts.current_A, dtype=float)
            for hold in sse:
                sim = analytic.rl_current(ts.time_s, ts.voltage_V, ref.R_Ohm, ref.L_H, float(I[0]), hold)
                sse[hold] += float(np.sum((sim - I) ** 2))
            n += 1
    if n:
        c.sampled_drive_sse = sse
        c.sampled_drive_hold = min(sse, key=sse.get)
    return c


def coil_radius_from_t7(samples, reading_sd: tuple[float, float] | None = None) -> tuple[float, float]:
    """Loop radius a [m] and its standard uncertainty [m] from the T7 blocked-force sweeps.

    Minimizes sum over samples and gaps of w (F - Em_s I^2 G(gap; a, D_s, 1 T/A))^2 over a (Em_s in closed
    form per sample; the field per ampere only scales G, so it is absorbed in Em_s), bounded scalar
    search on log a within 1 .. 200 mm; uncertainty from the curvature of the sum at its minimum with
    the residual variance, widened by t(0.975, dof) / 1.96 for the few degrees of freedom of that variance
    (dof = readings - samples - 1). ``samples``: objects with ``diameter_mm`` and ``tests["T7"]``.

    ``reading_sd``: (force [N], current [A]) standard deviations of one sweep reading (the conventions'
    ``sweep_reading_noise["T7"]``). A reading's force error is then sd_F^2 + (2 F sd_I / I)^2 in variance
    (F is proportional to I^2, so the current's noise reaches it in proportion to the force: near the coil
    it dominates), and w is its inverse; without it w = 1 (ordinary least squares, whose uncertainty is
    too small where the noise grows with the force).

    Raises
    ------
    ConventionError
        No sample has a T7 sweep with at least 4 gaps.
    """
    from scipy.optimize import minimize_scalar
    from scipy.stats import norm
    from scipy.stats import t as student_t
    data = []
    for s in samples:
        t = s.tests.get("T7")
        if t is not None and np.size(t.gap_mm) >= 4 and t.force_N is not None:
            I = np.asarray(t.current_A, float)
            F = np.asarray(t.force_N, float)
            if reading_sd is not None and all(math.isfinite(v) and v > 0 for v in reading_sd):
                sd_F, sd_I = reading_sd
                w = 1.0 / (sd_F ** 2 + (2.0 * F * sd_I / np.maximum(np.abs(I), 1e-12)) ** 2)   # 1 / N^2
            else:
                w = np.ones_like(F)
            data.append((np.asarray(t.gap_mm, float) / 1e3, I ** 2, F, float(s.diameter_mm) / 1e3, w))
    if not data:
        raise ConventionError("the manifest has no rig.coil_radius_mm and no sample has a T7 blocked-force "
                              "sweep (at least 4 gaps) to derive the loop radius from")

    def sse(a):
        tot = 0.0
        for g, I2, F, D, w in data:
            x = I2 * force_kernel(g, a, D, 1.0)
            Em = float((w * x) @ F) / max(float((w * x) @ x), 1e-300)
            tot += float(w @ (F - Em * x) ** 2)
        return tot

    lo, hi = (math.log(v) for v in _A_BOUNDS_M)
    grid = np.linspace(lo, hi, 25)
    vals = [sse(math.exp(u)) for u in grid]
    j = int(np.argmin(vals))
    sol = minimize_scalar(lambda u: sse(math.exp(u)), bounds=(grid[max(j - 1, 0)], grid[min(j + 1, 24)]),
                          method="bounded", options={"xatol": 1e-6})
    a = math.exp(float(sol.x))
    n = sum(d[2].size for d in data)
    s2 = sol.fun / max(1, n - len(data) - 1)
    h = 1e-3 * a
    curv = (sse(a + h) - 2 * sol.fun + sse(a - h)) / h ** 2
    sd = math.sqrt(2.0 * s2 / curv) if curv > 0 else float("nan")
    # s2 rests on few readings (n - samples - 1 degrees of freedom, 10 .. 30 here): widen sd so that the normal
    # 95 % interval downstream (Em, K1, K2 and the diagnosis's prior on a) has Student's t coverage
    dof = max(1, n - len(data) - 1)
    return a, sd * float(student_t.ppf(0.975, dof) / norm.ppf(0.975))


def _coil(ds, need_radius: bool, sweep_reading_noise: dict | None = None) -> dict:
    c = _Fields()
    rig = ds.rig or {}
    kB = rig.get("field_per_amp_T_per_A")
    c.field_per_amp_T_per_A = None if kB is None else float(kB)
    c.field_per_amp_source = "manifest" if kB is not None else "derived per sample from T5 (field_T / steady current)"
    a_mm = rig.get("coil_radius_mm")
    if a_mm is not None:
        c.coil_radius_mm, c.coil_radius_source = float(a_mm), "manifest"
        return c
    if not need_radius:
        c.coil_radius_source = "unknown"
        return c
    noise = (sweep_reading_noise or {}).get("T7", {})
    sd_F, sd_I = noise.get("force_N"), noise.get("current_A")
    a, sd = coil_radius_from_t7(ds.samples, None if sd_F is None or sd_I is None else (sd_F, sd_I))
    c.coil_radius_mm, c.sd_coil_radius_mm = a * 1e3, sd * 1e3
    c.coil_radius_source = "derived from the T7 blocked-force sweeps (force-kernel shape)"
    return c


def infer_conventions(ds, need_coil_radius: bool = True) -> Conventions:
    """The conventions of dataset ``ds`` (``harness.data.dataset.Dataset``), see the module docstring.

    Raises :class:`ConventionError` when the coil radius is needed, not in the manifest and cannot be
    derived (no T7).
    """
    noise = _noise(ds)
    steps = _steps(ds)
    sweeps = _sweeps(noise, ds)
    return Conventions(**noise, **sweeps, **steps, **_sampled_drive_hold(steps["steps"], ds),
                       **_coil(ds, need_coil_radius, sweeps["sweep_reading_noise"]))


def write_conventions(conv: Conventions, out_dir, stem: str = "conventions") -> list:
    """Write ``<stem>.json`` (:meth:`Conventions.as_dict`) and ``<stem>.md`` (its summary lines) into
    the existing folder ``out_dir``; returns the two paths."""
    import json
    from pathlib import Path
    out = Path(out_dir)
    pj = out / f"{stem}.json"
    pj.write_text(json.dumps(conv.as_dict(), indent=2, default=float) + "\n")
    pm = out / f"{stem}.md"
    pm.write_text("# Rig conventions inferred from the data\n\n" + "\n".join(conv.summary_lines()) + "\n\n"
                  "Details (every test's sample period, clock start and step instant): "
                  f"`{pj.name}`.\n")
    return [pj, pm]
