"""Parameter identification of MPC diaphragm actuators (paper section 3): the public entry points.

Numerics only (no plotting). Per sample, from the measured tests T3, T5 (displacement
steps at 0.11 T and 0.23 T) and T8 (blocked-force step at 0.23 T, gap 2 mm):

1. R [Ohm], L [H], kB [T/A], Em [N.m/T^2], K1 [N/m^3], K2 [N/m] by the paper's analytic steps,
   :mod:`harness.analysis.identification.analytic` (the one implementation, shared with the diagnosis; identify's
   options: the RL fit starts from the pre-step current, non-physical data raise). Loop radius
   a [m]: ``rig.coil_radius_mm``, else derived from T7; kB: ``rig.field_per_amp_T_per_A``, else T5's
   ``field_T`` / steady current; noise and step instants from the data
   (:mod:`harness.analysis.identification.conventions`). Every step response must settle before its steady window.
2. C [N.s/m] and m [kg] by NSGA-II (:mod:`harness.analysis.core.nsga`: pymoo by ask/tell) with four
   objectives (:mod:`harness.analysis.identification.objectives`): the 2 % settling-time error [s] and the RMSE
   [mm] of T3 and of T5 between measured and simulated displacement. The whole Pareto front is
   kept; the paper's model is chosen by its Eq. 6, J = sum_i alpha_i * Jbar_i, with Jbar_i the
   objectives min-max normalized over the front (equal weights by default; :mod:`harness.analysis.identification.selection`).
   ``residual_check``: how far the residuals put that choice from the front's least-squares model.
3. The (C, m) handed downstream (``IdentifySettings.choice``): by default the least-squares estimate from
   the T3 + T5 residuals, with the joint covariance of all seven parameters (``covariance_7``, ``interval_95``;
   :mod:`harness.analysis.identification.cm_joint`). Eq. 6, not an estimator, stays as the paper's reproduction (``paper_choice``).

Search space: the small-signal natural frequency f_n = sqrt(K2/m)/(2 pi) and damping ratio
zeta = C / (2 sqrt(K2 m)) span ``f_n_range_hz`` and ``zeta_range`` (m in [K2/(2 pi f_hi)^2,
K2/(2 pi f_lo)^2], for each m C in [2 zeta_lo sqrt(K2 m), 2 zeta_hi sqrt(K2 m)]). NSGA-II (pymoo's
NSGA2, seeded; candidates already evaluated are looked up) works on (log10 m, log10 zeta), bounds
from the identified K2 (a box in (C, m) would include absurd corners such as zeta = 500). STE is rounded to ``ste_resolution_s`` (default: the sample
period): settling times are not resolved below one sample, and without the rounding models
whose settling times match the noisy measured ones to a fraction of a millisecond, however
poor their RMSE, end up on the front and dominate the min-max normalization of Eq. 6.

:func:`identify_dataset` runs the samples of a dataset in ``workers`` processes; within a
process their populations share one batched simulation per generation. Results are written
by :func:`write_identification` (``identification.json``, ``pareto/<id>.csv``,
:mod:`harness.analysis.identification.identify_results`).

Bad data raise :class:`IdentificationError` (a ``ValueError``) naming the sample and
the test.
"""
from __future__ import annotations

import dataclasses
import math
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

import numpy as np

from fmu_src.specs import Params
from harness.analysis.core import metrics
from harness.analysis.identification.conventions import (ConventionError, Conventions, held_step_voltage,
                                                         step_instants, step_onset_from_rest,
                                                         write_conventions)
from harness.analysis.identification.prepared import PreparedData, as_prepared, prepare
from harness.analysis.identification.analytic import (MIN_STEADY_SAMPLES, AnalyticError, AnalyticInput, AnalyticOptions,
                                       AnalyticResult, SteadyState, StepTest, analytic_identification, steady_state)
from harness.analysis.identification.identify_results import (PARAM_KEYS, PARAM_UNITS, ParetoFront, SampleIdentification,
                                               identification_to_json, sample_to_json, write_identification)
from harness.analysis.identification.cm_joint import (CHOICE_ALIASES, CHOICES, CMEstimate, analytic_covariance_or_none, identified_cm,
                                       least_squares_estimate)
from harness.analysis.core.nsga import NSGARun, non_dominated, run_lockstep
from harness.parallel import process_pool, sync_manager
from harness.analysis.identification.settings import IdentifySettings
from harness.analysis.identification.selection import CHI2_95_2DOF, residual_check, select_by_weights, validate_weights
from harness.analysis.identification.objectives import (OBJECTIVE_NAMES, CMObjective, StepRecord,
                                         evaluate_many)
from harness.data import protocol

__all__ = [
    "IdentificationError", "IdentifySettings", "SampleIdentification", "ParetoFront", "identify_sample",
    "identify_dataset", "identification_to_json", "write_identification", "select_by_weights", "residual_check",
    "CHI2_95_2DOF", "CHOICES", "CHOICE_ALIASES", "validate_weights", "non_dominated", "training_samples",
    "identify_and_write", "OBJECTIVE_NAMES", "REQUIRED_TESTS", "sample_to_json", "SampleAnalytic", "analyse_sample",
    "objective_for", "estimate_cm", "instant_nuisance", "shifted_instants", "evaluate_many", "SampleChoice", "SampleSelection", "select_samples", "IncompleteSampleWarning",
]

REQUIRED_TESTS = protocol.IDENTIFICATION_TESTS
#: a response settling after the start of its default steady window is averaged from its settling time on if at
#: least this part of the record after the step follows (the settling time's own final level is the mean of the
#: last 10 %, :func:`harness.analysis.core.metrics.settling_time_robust`)
MIN_SETTLED_FRACTION = 0.1
#: ... if its two halves' means differ by at most 3 noise sd or this part of the band (times the step)
MAX_SETTLED_DRIFT = 0.1


class IncompleteSampleWarning(UserWarning):
    """A sample lacking a test the identification needs was skipped (``SampleChoice.skip_incomplete``)."""


class IdentificationError(ValueError):
    """Data that cannot be identified; the message names the sample and the test."""

    def __init__(self, sample: str, test: str | None, message: str):
        self.sample, self.test, self.reason = sample, test, message
        where = f"sample {sample}" + (f", test {test}" if test else "")
        super().__init__(f"{where}: {message}")


# ============================================================================ helpers
def _step_test(sid, ts, col: str) -> StepTest:
    """A dataset time series as the analytic identification's StepTest (response in m or N)."""
    y = getattr(ts, col)
    if y is None:
        raise IdentificationError(sid, ts.test, f"no {col} column")
    field_T = getattr(ts, "field_T", None)
    return StepTest(name=ts.test, time_s=ts.time_s, voltage_V=ts.voltage_V, current_A=ts.current_A,
                    response=y / 1000.0 if col == "displacement_mm" else y, gap_m=float(ts.gap_mm) / 1000.0,
                    field_T=float("nan") if field_T is None else float(field_T), response_name=col)


def _settling_checked(sid, ts, col: str, st: SteadyState, settings: IdentifySettings,
                      noise_sigma) -> tuple[float, float, int | None]:
    """(settling time [s], band [-], steady start): 2 % or the narrowest band the noise resolves.

    A response that settles after the start of the default steady window (the last ``steady_fraction`` of the record
    after the step) but leaves enough settled readings (at least :data:`MIN_SETTLED_FRACTION` of the post-step
    record and twice ``MIN_STEADY_SAMPLES``: each half of them a steady window) that do not drift (the means of
    their two halves differ by no more than three standard deviations of their noise or :data:`MAX_SETTLED_DRIFT` of
    the band) gets its steady window from the first reading after its settling time on (steady start: that index,
    else None). A late settling time on a small noisy step is typically one noise excursion; a slow approach from
    one side still drifts. Raises :class:`IdentificationError` if it never settles or settles too late for that."""
    t, y = ts.time_s, getattr(ts, col)
    try:
        band = metrics.resolvable_band(t, y, t_step=st.t_step_s, noise_sigma=noise_sigma, band=settings.band)
        ts_meas = metrics.settling_time_robust(t, y, t_step=st.t_step_s, noise_sigma=noise_sigma, band=band)
    except ValueError as e:
        raise IdentificationError(sid, ts.test, f"settling time of {col}: {e}") from None
    if math.isfinite(ts_meas) and st.t_step_s + ts_meas <= t[st.start]:
        return float(ts_meas), float(band), None
    n_after = t.size - st.step
    start = int(np.searchsorted(t, st.t_step_s + ts_meas, side="right")) if math.isfinite(ts_meas) else t.size
    why = None
    if t.size - start < max(2 * MIN_STEADY_SAMPLES, MIN_SETTLED_FRACTION * n_after):
        why = (f"at least {100 * MIN_SETTLED_FRACTION:.3g} % of the record after the step must follow it, "
               f"{t[-1] - st.t_step_s:.3g} s of record after the step")
    else:
        w = np.asarray(y[start:], dtype=float)
        first, second = w[: w.size // 2], w[w.size // 2:]
        drift = abs(float(np.mean(second) - np.mean(first)))
        noise = math.sqrt(np.var(first) / first.size + np.var(second) / second.size)
        step = abs(float(np.mean(w)) - float(np.mean(y[: st.step])))      # [the column's unit]
        if drift > max(3.0 * noise, MAX_SETTLED_DRIFT * band * step):
            why = (f"the readings after it still drift by {100 * drift / step:.2g} % of the step between their "
                   f"halves")
    if why is not None:
        raise IdentificationError(
            sid, ts.test, f"the {col} step never settles within the record ({100 * band:.3g} % settling time "
                          f"{'none' if not math.isfinite(ts_meas) else f'{ts_meas:.3g} s'}; {why})")
    return float(ts_meas), float(band), start


def _require_tests(sample) -> None:
    missing = [n for n in REQUIRED_TESTS if n not in sample.tests]
    if missing:
        raise IdentificationError(sample.id, ", ".join(missing),
                                  f"missing test{'s' if len(missing) > 1 else ''} {', '.join(missing)} "
                                  f"(identification needs T3, T5 and T8; the sample has "
                                  f"{', '.join(sample.tests) or 'none'})")
    for n in REQUIRED_TESTS:
        ts = sample.tests[n]
        if not hasattr(ts, "time_s"):
            raise IdentificationError(sample.id, n, "expected a time series")


# ============================================================================ analytic part
@dataclass(frozen=True, eq=False)
class SampleAnalytic:
    """The analytic part of one sample's identification.

    sid, wt_pct [wt%]; params: R, L, kB, Em, K1, K2 (C, m at their defaults); result: the
    :class:`harness.analysis.identification.analytic.AnalyticResult`; steady: steady values for the JSON (units in
    the keys); uncertainty: {name: standard uncertainty}; tests: {"T3", "T5": TimeSeries};
    settling_s: {"T3", "T5", "T8": settling time [s] of the measured response}; settling_band: its band [-];
    step_instants: {"T3", "T5": StepInstant or None} (the prepared data's, else fitted once by :func:`analyse_sample`).
    """
    sid: str
    wt_pct: float
    params: Params
    result: AnalyticResult
    steady: dict
    uncertainty: dict
    tests: dict
    settling_s: dict
    settling_band: dict
    step_instants: dict = dataclasses.field(default_factory=dict)

    @property
    def st(self) -> dict:
        """{"T3", "T5", "T8": SteadyState}."""
        return self.result.steady


def analyse_sample(sample, rig, settings: IdentifySettings) -> SampleAnalytic:
    """The analytic part (R, L, kB, Em, K1, K2) of one sample, checked for identification.

    sample: :class:`harness.data.dataset.Sample`; rig: the prepared data
    (:class:`harness.analysis.identification.prepared.PreparedData`), or the manifest's ``rig`` (or the
    Dataset), read as stated. Besides :func:`harness.analysis.identification.analytic.analytic_identification`'s checks, every step
    response must settle before its steady window. Raises :class:`IdentificationError`.
    """
    sid = sample.id
    _require_tests(sample)
    prep = as_prepared(rig)
    a_mm = prep.coil_radius_mm
    if a_mm is None or not (a_mm > 0):
        raise IdentificationError(sid, None, "the dataset manifest has no rig.coil_radius_mm (the loop radius a "
                                             "of the electromagnet is needed for the field model)")
    D = float(sample.diameter_mm) / 1000.0
    if not (D > 0):
        raise IdentificationError(sid, None, f"diameter_mm must be > 0, got {sample.diameter_mm!r}")
    options = AnalyticOptions(steady_fraction=settings.steady_fraction)
    tests, settling, bands = {}, {}, {}
    try:
        for name in REQUIRED_TESTS:
            ts, col = sample.tests[name], protocol.TESTS[name].measured
            tests[name] = _step_test(sid, ts, col)
            st = steady_state(tests[name], settings.steady_fraction)
            sigma = prep.noise_sigma.get(col)
            settling[name], bands[name], start = _settling_checked(sid, ts, col, st, settings, sigma)
            if start is not None:                 # settled after the default window's start: averaged from then on
                tests[name] = dataclasses.replace(tests[name], steady_start=start)
        inp = AnalyticInput(T3=tests["T3"], T5=tests["T5"], T8=tests["T8"], a_m=a_mm / 1000.0, D_m=D,
                            kB_T_per_A=prep.field_per_amp_T_per_A,
                            sd_a_m=float(prep.sd_coil_radius_mm or 0.0) / 1000.0)
        res = analytic_identification(inp, options)
    except AnalyticError as e:
        raise IdentificationError(sid, e.test, e.reason) from None
    s3, s5, s8 = (res.steady[n] for n in REQUIRED_TESTS)
    T3, T5, T8 = (sample.tests[n] for n in REQUIRED_TESTS)
    steady = {
        "T3_displacement_mm": s3.response * 1000.0, "T3_current_A": s3.current_A, "T3_gap_mm": float(T3.gap_mm),
        "T5_displacement_mm": s5.response * 1000.0, "T5_current_A": s5.current_A, "T5_voltage_V": s5.voltage_V,
        "T5_gap_mm": float(T5.gap_mm),
        "T8_force_N": s8.response, "T8_current_A": s8.current_A, "T8_gap_mm": float(T8.gap_mm),
        "kB_source": res.kB_source,
    }
    found = prep.step_instants(sid)
    found = step_instants(sample, tests=("T3", "T5")) if found is None else found   # a bare rig: fitted once, here
    return SampleAnalytic(sid=sid, wt_pct=float(sample.wt_pct), params=res.params(), result=res, steady=steady,
                          uncertainty=res.uncertainty(), tests={"T3": T3, "T5": T5}, settling_s=settling,
                          settling_band=bands, step_instants={n: found.get(n) for n in ("T3", "T5")})


# ============================================================================ objectives
def objective_for(an: SampleAnalytic, rig, settings: IdentifySettings, coil_step: bool = False) -> CMObjective:
    """The C/m objectives of a sample (T3 and T5 with its analytic parameters; each step simulated from its
    instant estimated within the sample interval, ``an.step_instants``). coil_step (the least-squares estimate
    and its uncertainty): a step from rest starts at its instant, between samples
    (:func:`harness.analysis.identification.conventions.step_onset_from_rest`), any other record gets the held
    voltage that gives the RL coil's current (``held_step_voltage``); without it (NSGA-II's search for the
    paper's Eq. 6 choice, kept as it was so that ``--choose paper`` reproduces the earlier numbers) the mean
    held voltage. rig: as for :func:`analyse_sample` (the displacement sensor's noise)."""
    tau = an.params.L / an.params.R if coil_step else None
    records = []
    for name, ts in an.tests.items():
        onset = step_onset_from_rest(name, ts, an.step_instants[name]) if coil_step else None
        V = ts.voltage_V if onset is not None else held_step_voltage(name, ts, tau, an.step_instants[name])
        records.append(StepRecord(time_s=ts.time_s, voltage_V=V, displacement_mm=ts.displacement_mm,
                                  gap_m=float(ts.gap_mm) / 1000.0, step=an.st[name].step, onset_delay_s=onset))
    sigma_mm = as_prepared(rig).noise_sigma.get("displacement_mm")
    return CMObjective(an.params, records, sigma_mm, settings.objective())


# ============================================================================ optimization
def instant_nuisance(an: SampleAnalytic) -> tuple[tuple, np.ndarray | None]:
    """(tests, covariance [s^2]) of the step instants of T3 and T5 that the C/m objectives start their steps
    at (``an.step_instants``, each with its own standard uncertainty from its RL fit, taken as independent):
    the nuisance of :func:`harness.analysis.identification.cm_joint.least_squares_estimate`. ((), None)
    when neither has one. At low sample rates an instant's uncertainty moves m by about as much as its own
    noise does (measured at 136 Hz: T5's instant sd moved m by 0.84 of m's profile sd)."""
    names = tuple(n for n in ("T3", "T5") if an.step_instants.get(n) is not None
                  and an.step_instants[n].sd_t_step_s > 0 and math.isfinite(an.step_instants[n].sd_t_step_s))
    if not names:
        return (), None
    return names, np.diag([an.step_instants[n].sd_t_step_s ** 2 for n in names])


def shifted_instants(an: SampleAnalytic, names: tuple, shift_s) -> SampleAnalytic:
    """``an`` with the step instants of ``names`` later by ``shift_s`` [s] (each: t_step_s + shift, the
    delay before the step's first sample shorter by as much)."""
    st = dict(an.step_instants)
    for n, d in zip(names, shift_s):
        i = st[n]
        st[n] = dataclasses.replace(i, t_step_s=i.t_step_s + float(d), step_delay_s=i.step_delay_s - float(d))
    return dataclasses.replace(an, step_instants=st)


def estimate_cm(an: SampleAnalytic, rig, tight: IdentifySettings, params: Params, cov5, C0: float, m0: float,
                n_grid: int = 11) -> CMEstimate:
    """Least-squares (C, m) near (C0, m0) at the analytic model ``params`` and the joint covariance, with the
    analytic parameters' (cov5) and the step instants' (:func:`instant_nuisance`) uncertainties propagated."""
    names, Q = instant_nuisance(an)

    def make(p, shift=()):
        a = dataclasses.replace(an if not len(shift) else shifted_instants(an, names, shift), params=p)
        return objective_for(a, rig, tight, True)
    return least_squares_estimate(make, params, cov5, C0, m0, n_grid=n_grid, nuisance_cov=Q)


def _estimate(an: SampleAnalytic, rig, settings: IdentifySettings, C0: float, m0: float) -> CMEstimate:
    """Least-squares (C, m) near (C0, m0) and joint covariance (:mod:`harness.analysis.identification.cm_joint`)."""
    tight = dataclasses.replace(settings, settle_rtol=min(settings.settle_rtol, 1e-8), rk_tol=min(settings.rk_tol, 1e-5))
    cov5 = analytic_covariance_or_none(an.result, [an.steady[f"{n}_gap_mm"] / 1000.0 for n in REQUIRED_TESTS])
    return estimate_cm(an, rig, tight, an.params, cov5, C0, m0)


def _finish(an: SampleAnalytic, obj: CMObjective, run: NSGARun, settings: IdentifySettings, t_analytic: float,
            rig=None) -> SampleIdentification:
    X, F = run.population()
    nd = non_dominated(F)
    X, F = X[nd], F[nd]
    C, m = obj.decode(X)
    order = np.lexsort((C, m))
    C, m, F = C[order], m[order], F[order]
    k, J = select_by_weights(F, settings.weights)
    check = residual_check(F, [meas["t"].size for meas in obj.meas], k, C, m)
    ls = check["least_squares_front_model"]
    ta = time.perf_counter()
    est = _estimate(an, rig, settings, ls["C_N_s_per_m"], ls["m_kg"])
    t_ls = time.perf_counter() - ta
    C_id, m_id, used, paper = identified_cm(settings.choice, est, C[k], m[k], k)
    p = an.params.with_(C=C_id, m=m_id)
    values = {name: (float(getattr(p, name)), PARAM_UNITS[name]) for name in PARAM_KEYS}
    chosen = {n: float(v) for n, v in zip(OBJECTIVE_NAMES, F[k])}
    chosen["J"] = float(J[k])
    st = run.stats
    return SampleIdentification(
        sample=an.sid, wt_pct=float(an.wt_pct), diameter_mm=an.params.D * 1000.0, params=p, values=values,
        uncertainty=an.uncertainty, steady=an.steady, pareto=ParetoFront(C=C, m=m, objectives=F), chosen=int(k),
        chosen_objectives=chosen, J=J, weights=settings.weights, bounds=obj.bounds_json(),
        timing_s={"analytic_s": t_analytic, "optimization_s": st.time_s, "evaluation_s": st.evaluation_s,
                  "least_squares_s": t_ls},
        settings=settings, evaluations=int(st.evaluations), analytic_notes=tuple(an.result.notes),
        settling_band={n: b for n, b in an.settling_band.items() if b > settings.band},
        residual_check=check, least_squares=est.least_squares, choice=used, paper_choice=paper,
        covariance_7=est.covariance_7, interval_95=est.interval_95)


def identify_sample(sample, dataset_rig=None, settings: IdentifySettings | None = None
                    ) -> SampleIdentification:
    """Identify one sample (tests T3, T5, T8 needed).

    sample: :class:`harness.data.dataset.Sample`; dataset_rig: the manifest's ``rig`` dict
    (or the Dataset) providing ``coil_radius_mm`` [mm] (required), ``field_per_amp_T_per_A``
    [T/A] (optional) and the sensor noise; settings: :class:`IdentifySettings`.
    Raises :class:`IdentificationError` for unusable data.
    """
    return _identify_group([sample], dataset_rig, settings or IdentifySettings())[0]


def _identify_group(samples, rig, settings: IdentifySettings, on_generation=None) -> list[SampleIdentification]:
    """NSGA-II for several samples in lock-step: their populations share one batched integration per
    generation; each has its own algorithm and random generator (results independent of the grouping)."""
    ans, objs, t_an = [], [], []
    for s in samples:
        ta = time.perf_counter()
        an = analyse_sample(s, rig, settings)
        objs.append(objective_for(an, rig, settings))
        ans.append(an)
        t_an.append(time.perf_counter() - ta)
    runs = [NSGARun(o.xl, o.xu, len(OBJECTIVE_NAMES), settings.nsga()) for o in objs]
    run_lockstep(runs, lambda which, Xs: evaluate_many([objs[i] for i in which], Xs), on_generation)
    out = []
    for s, an, obj, run, ta in zip(samples, ans, objs, runs, t_an):
        r = _finish(an, obj, run, settings, ta, rig)
        r.diameter_mm = float(s.diameter_mm)
        out.append(r)
    return out


# ============================================================================ dataset
@dataclass(frozen=True)
class SampleChoice:
    """Which samples of a dataset the identification uses (what the user declared).

    unseen: ids of the samples kept out of the identification, whose parameters are predicted
    from the surface fits (generalization, Table 5). None: for a synthetic dataset the virtual
    rig's unseen samples (15 and 25 wt%, 45 mm; ``harness.data.rig.UNSEEN_SAMPLES``), for
    measured data none. skip_incomplete: a training sample lacking a test the identification
    needs is skipped (with a warning, and listed as skipped in every report) instead of being
    an error naming sample and test.
    """
    unseen: tuple | None = None
    skip_incomplete: bool = False

    def __post_init__(self):
        if self.unseen is not None:
            if isinstance(self.unseen, str):
                object.__setattr__(self, "unseen", (self.unseen,))
            object.__setattr__(self, "unseen", tuple(str(u) for u in self.unseen))


@dataclass(frozen=True)
class SampleSelection:
    """The outcome of :func:`select_samples`: training ids, unseen ids, skipped {id: reason}."""
    training: tuple
    unseen: tuple
    skipped: dict


def _missing_tests_error(sample) -> IdentificationError | None:
    try:
        return _require_tests(sample)
    except IdentificationError as e:
        return e


def select_samples(dataset, samples: Iterable[str] | None = None, choice: SampleChoice = SampleChoice()
                   ) -> SampleSelection:
    """The training, unseen and skipped samples of a dataset (no warning, no identification).

    samples: ids to identify (default: every sample not declared unseen). Raises
    :class:`IdentificationError` for an unknown unseen id, a sample both identified and unseen,
    or (without ``choice.skip_incomplete``) training samples lacking T3, T5 or T8, naming every
    such sample and test.
    """
    ids = [s.id for s in dataset.samples]
    if choice.unseen is not None:
        unknown = [u for u in choice.unseen if u not in ids]
        if unknown:
            raise IdentificationError(", ".join(unknown), None, f"declared unseen but not in the dataset "
                                                                f"(its samples: {', '.join(ids) or 'none'})")
        unseen = [i for i in ids if i in set(choice.unseen)]
    elif getattr(dataset, "synthetic", False):
        from harness.data.rig import UNSEEN_SAMPLES
        coords = {(float(w), float(d)) for w, d in UNSEEN_SAMPLES}
        unseen = [s.id for s in dataset.samples if (float(s.wt_pct), float(s.diameter_mm)) in coords]
    else:
        unseen = []
    if samples is None:
        candidates = [s for s in dataset.samples if s.id not in unseen]
    else:
        candidates = [dataset.sample(i) for i in samples]
        both = [s.id for s in candidates if s.id in unseen]
        if both:
            raise IdentificationError(", ".join(both), None, "both to be identified and declared unseen")
    training, skipped, errors = [], {}, []
    for s in candidates:
        err = _missing_tests_error(s)
        if err is None:
            training.append(s.id)
        elif choice.skip_incomplete:
            skipped[s.id] = str(err)
        else:
            errors.append(err)
    if errors:
        hint = ("; declare such samples unseen (--unseen) or skip them (--skip-incomplete)")
        if len(errors) == 1:
            e = errors[0]
            raise IdentificationError(e.sample, e.test, e.reason + hint)
        raise IdentificationError(", ".join(e.sample for e in errors), None,
                                  "unusable data" + hint + ":\n  " + "\n  ".join(str(e) for e in errors))
    return SampleSelection(training=tuple(training), unseen=tuple(unseen), skipped=skipped)


def training_samples(dataset, choice: SampleChoice = SampleChoice()) -> list:
    """Samples used for identification: every sample not declared unseen (:class:`SampleChoice`;
    synthetic data: not the paper's two unseen samples, 15 and 25 wt% at 45 mm). A sample lacking
    T3, T5 or T8 is an error unless ``choice.skip_incomplete`` (see :func:`select_samples`)."""
    return [dataset.sample(i) for i in select_samples(dataset, None, choice).training]


def _worker(args):
    samples, rig, settings, queue = args
    cb = (lambda n: queue.put(n)) if queue is not None else None
    c0 = time.process_time()
    res = _identify_group(samples, rig, settings, on_generation=cb)
    cpu = time.process_time() - c0
    for r in res:
        r.timing_s["process_cpu_s"] = cpu        # CPU time of the process that ran this sample's group
    return res


def identify_dataset(dataset, settings: IdentifySettings | None = None, progress: bool = True, workers: int = 2,
                     samples: Iterable[str] | None = None, choice: SampleChoice = SampleChoice(),
                     conventions: Conventions | PreparedData | None = None) -> dict:
    """Identify the training samples of a dataset; returns {sample id: SampleIdentification}.

    samples: ids to identify (default :func:`training_samples`); choice: unseen samples and
    whether incomplete samples are skipped (each with a :class:`IncompleteSampleWarning`). The samples are spread
    over ``workers`` processes; within a process their NSGA-II populations share one
    batched integration per generation. A tqdm bar counts generations x samples.
    The data of every sample are checked first: an :class:`IdentificationError` lists
    every unusable sample before any optimization starts. conventions: the dataset's prepared data (or its
    conventions; derived once when None, :func:`harness.analysis.identification.prepared.prepare`), which every later step reads.
    """
    settings = settings or IdentifySettings()
    selection = select_samples(dataset, samples, choice)
    for sid, why in selection.skipped.items():
        warnings.warn(IncompleteSampleWarning(f"skipped {why}"), stacklevel=2)
    chosen = [dataset.sample(i) for i in selection.training]
    if not chosen:
        raise ValueError(f"dataset {getattr(dataset, 'root', '')} has no sample with T3, T5 and T8 to identify")
    rig = conventions if isinstance(conventions, PreparedData) else _prepare(dataset, selection.training, conventions)
    # check every sample first (fast) so that bad data fail before the optimization
    errors, cost = [], {}
    for s in chosen:
        try:
            an = analyse_sample(s, rig, settings)
            # relative cost of a sample: its responses settle slower -> longer integrations
            cost[s.id] = 1.0 + 10.0 * an.settling_s["T5"]
        except IdentificationError as e:
            errors.append(e)
    if len(errors) == 1:
        raise errors[0]
    if errors:
        err = IdentificationError(", ".join(e.sample for e in errors), None,
                                  "unusable data:\n  " + "\n  ".join(str(e) for e in errors))
        raise err
    workers = max(1, min(int(workers or 1), len(chosen)))
    # chunks of about equal cost (longest first to the least loaded process); the samples of a
    # chunk share one integration per generation. Results do not depend on the split.
    chunks, load = [[] for _ in range(workers)], [0.0] * workers
    for s in sorted(chosen, key=lambda s: -cost[s.id]):
        i = int(np.argmin(load))
        chunks[i].append(s)
        load[i] += cost[s.id]
    total = len(chosen) * int(settings.n_gen)
    from tqdm import tqdm
    bar = tqdm(total=total, desc="NSGA-II C, m (generations x samples)", unit="gen", disable=not progress,
               mininterval=0.5)
    results = {}
    try:
        if workers == 1:
            c0 = time.process_time()
            res = _identify_group(chosen, rig, settings, on_generation=bar.update)
            for r in res:
                r.timing_s["process_cpu_s"] = time.process_time() - c0
            results = {r.sample: r for r in res}
        else:
            with sync_manager() as manager:
                queue = manager.Queue()
                with process_pool(workers) as pool:
                    futs = [pool.submit(_worker, (c, rig, settings, queue)) for c in chunks]
                    done = 0
                    while done < total and not all(f.done() for f in futs):
                        try:
                            n = queue.get(timeout=0.2)
                        except Exception:
                            continue
                        bar.update(n)
                        done += n
                    for f in futs:
                        for r in f.result():
                            results[r.sample] = r
                    while not queue.empty():
                        bar.update(queue.get())
    finally:
        bar.close()
    return {s.id: results[s.id] for s in chosen}


def _prepare(dataset, sample_ids, conventions: Conventions | None = None) -> PreparedData:
    """:func:`prepare`; a convention the data cannot give is an :class:`IdentificationError` naming the samples."""
    try:
        return prepare(dataset, conventions)
    except ConventionError as e:
        raise IdentificationError(", ".join(sample_ids), None, str(e)) from None


def identify_and_write(dataset, out_dir, settings: IdentifySettings | None = None, workers: int = 2,
                       progress: bool = True, samples: Iterable[str] | None = None,
                       predict_unseen: bool = True, choice: SampleChoice = SampleChoice()) -> tuple[dict, list[Path]]:
    """Identify a dataset's training samples and write the results (what ``mpc-actuator identify`` does).

    Writes to out_dir: ``identification.json`` (parameters per sample, with units in the
    keys, the Pareto fronts, Eq. 6 choice, settings, timing, the unseen and the skipped
    samples, the rig conventions inferred from the data), ``identification_conventions.{json,md}``
    and ``pareto/<id>.csv``; with predict_unseen (and at least 3 identified samples
    spanning a surface) also ``generalization.json``: surface fits of Em, K1, K2, C, m and the
    predicted parameters of the samples declared unseen (``choice``, :class:`SampleChoice`) with
    the mean identified coil. Returns ({id: SampleIdentification}, written paths).
    """
    from harness.analysis.identification import generalize
    settings = settings or IdentifySettings()
    selection = select_samples(dataset, samples, choice)
    t0 = time.perf_counter()
    prepared = _prepare(dataset, selection.training)       # derived once; every later step reads it
    conv = prepared.conventions
    results = identify_dataset(dataset, settings, progress=progress, workers=workers, samples=samples, choice=choice,
                               conventions=prepared)
    wall = time.perf_counter() - t0
    written = write_identification(results, out_dir, settings, synthetic=getattr(dataset, "synthetic", None),
                                   wall_time_s=wall, selection={"unseen": list(selection.unseen),
                                                                "skipped": dict(selection.skipped)},
                                   conventions=conv.as_dict())
    written += write_conventions(conv, out_dir, "identification_conventions")
    if predict_unseen:
        others = [(s.id, s.wt_pct, s.diameter_mm) for s in dataset.samples if s.id in selection.unseen]
        try:
            fits = generalize.fit_surfaces(results)
        except generalize.GeneralizationError:
            fits = None
        if fits is not None:
            preds, skipped = generalize.predict_samples(fits, others, generalize.mean_coil(results))
            written.append(generalize.write_generalization(fits, preds, out_dir, skipped,
                                                           skipped_incomplete=selection.skipped))
    return results, written
