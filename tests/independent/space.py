"""The space of rig descriptions the data format allows, for property-based tests (Hypothesis).

:class:`RigDescription` is one point of that space: everything :mod:`tests.independent.generator` can vary,
and more (per-test sample rates, other coils, other gap offsets, subsets of samples and of tests, several
noise scales per channel). :func:`make_from_description` writes the dataset it describes with the
independent generator's physics (:mod:`tests.independent.physics`, ``scipy.integrate.solve_ivp``) and
sensors (:func:`tests.independent.generator.measure`); :func:`rig_descriptions` is the Hypothesis strategy
over the space. A description is frozen, hashable and its ``repr`` is valid Python, so a shrunk failing
example can be pasted into an ``@example(...)`` as it is printed.

Ranges drawn by :func:`rig_descriptions` (``max_rate_hz`` and ``max_samples`` cap the cost):

* sample rate 100 Hz .. 20 kHz, log-uniform, whole Hz; one for all time series or one per test; the sweeps
  are sampled at T3's rate, and the manifest's ``rig.sample_period_s`` is that period (always when sweeps are
  averaged, so that the reader knows how many samples a reading averages; else written or left out); step
  phase [0, 1) of a period; clock start 0 .. 100 s; pre-trigger 0.05 .. 0.5 s; records 1.5 .. 5 s; T6 one
  or two periods at 0.5 .. 2 Hz;
* sweeps: single readings or averages over 0.05 .. 0.5 s of 0.6 .. 1.5 s holds; 6 .. 26 distinct gaps
  in 0 .. 25 mm (0.5 mm grid: regular or irregular), written descending, ascending or shuffled;
* noise 0.2x .. 5x of our rig's sensors, each of laser, force and current on its own;
* samples (at least 3: :attr:`DiagnoseSettings.min_samples_holdout`): wt% 5 .. 40, D 20 .. 80 mm, distinct;
  coil radius 10 .. 25 mm, field per ampere 0.15 .. 0.5 T/A, stated in the manifest or not; step-test gap
  offset 1 .. 5 mm, T6 offset 1.5 .. 6 mm, T8 gap 0.5 .. 5 mm from the magnet;
* tests: T2, T4, T6 each may be absent (``complete=None``: T1 or T7 too);
* optionally one hidden effect of :data:`tests.independent.generator.EFFECT_FORMS` (or, with ``outside``, of
  :data:`tests.independent.generator.OUTSIDE_FORMS`: effects outside the catalogue), magnitude 1 .. 2.5.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from tests.independent.generator import (
    EFFECT_FORMS, FIELDS_T, OUTSIDE_FORMS, OUTSIDE_KIND, OUR_CURRENT, OUR_FORCE, OUR_LASER, THICKNESS_MM, RigConventions, conventions_json,
    params_json, noise_rng, sensor_json, sample_id, sweep, time_series, true_params, with_effects,
)

__all__ = ["RigDescription", "make_from_description", "rig_descriptions", "TIME_SERIES", "OPTIONAL_TESTS",
           "EXPECTED_CAUSE", "OUTSIDE_KIND"]

TIME_SERIES = ("T2", "T3", "T4", "T5", "T6", "T8")
SWEEPS = ("T1", "T7")
OPTIONAL_TESTS = ("T2", "T4", "T6")          # absent from some datasets; the rest are what identify needs

#: the catalogue cause each hidden form must be named as (as in test_diagnose_effect_members.py)
EXPECTED_CAUSE = {"coil_heating": "coil_heating", "coil_heating_2tau": "coil_heating",
                  "viscoelastic_creep": "viscoelastic_creep", "creep_2tau": "viscoelastic_creep",
                  "filler_saturation": "filler_saturation", "saturation_tanh": "filler_saturation",
                  "saturation_langevin": "filler_saturation", "edge_stiffening": "edge_stiffening",
                  "motional_emf": "motional_emf", "sensor_lag": "sensor_lag"}


@dataclass(frozen=True)
class RigDescription:
    """One rig and dataset (times in s, rates in Hz, lengths in mm; module docstring for the ranges).

    ``rates_hz``: the sample rate of each time-series test, in the order of :data:`TIME_SERIES` (T2, T3, T4,
    T5, T6, T8); ``sweep_rate_hz``: the rate the sweep readings are sampled at; ``manifest_period``: write
    ``rig.sample_period_s`` (= 1 / sweep_rate_hz) into the manifest. ``noise``: (laser, force, current)
    scales of our rig's sensor sigmas. ``samples``: (wt %, D mm) pairs. ``absent``: tests left out of every
    sample. ``effect``: (form, magnitude) or None.
    """
    rates_hz: tuple = (1000.0,) * 6
    sweep_rate_hz: float = 1000.0
    manifest_period: bool = True
    step_phase: float = 0.0
    clock_start_s: float = 0.0
    pre_trigger_s: float = 0.2
    record_s: float = 2.4
    t6_periods: int = 2
    t6_frequency_hz: float = 1.0
    sweep_gaps_mm: tuple = tuple(float(g) for g in range(24, -1, -2))
    sweep_hold_s: float = 1.0
    sweep_average_s: float | None = 0.2
    noise: tuple = (1.0, 1.0, 1.0)
    samples: tuple = ((10, 45), (20, 45), (30, 45))
    coil_radius_mm: float = 15.0
    field_per_amp_T_per_A: float = 0.29
    manifest_coil: bool = True
    step_gap_offset_mm: float = 2.0
    t6_gap_offset_mm: float = 3.0
    t8_gap_mm: float = 2.0
    absent: tuple = ()
    effect: tuple | None = None
    seed: int = 0

    def __post_init__(self):
        if len(self.rates_hz) != len(TIME_SERIES) or min(self.rates_hz) <= 0:
            raise ValueError(f"rates_hz: one positive rate per test of {TIME_SERIES}")
        if len(self.samples) != len({sample_id(w, d) for w, d in self.samples}):
            raise ValueError("duplicate samples")
        if not set(self.absent) <= set(OPTIONAL_TESTS + SWEEPS):
            raise ValueError(f"only {OPTIONAL_TESTS + SWEEPS} may be absent")
        if self.sweep_average_s is not None and self.sweep_average_s < 1.0 / self.sweep_rate_hz:
            raise ValueError("sweep_average_s shorter than one sweep sample period")
        if self.effect is not None and self.effect[0] not in EFFECT_FORMS and self.effect[0] not in OUTSIDE_FORMS:
            raise ValueError(f"unknown effect {self.effect[0]!r}")

    @property
    def complete(self) -> bool:
        """Every test identify and diagnose fit (T1, T3, T5, T7, T8) is present."""
        return not set(self.absent) & set(SWEEPS)

    def rate_hz(self, test: str) -> float:
        return self.rates_hz[TIME_SERIES.index(test)]

    def conventions(self, test: str) -> RigConventions:
        """The generator's conventions for ``test`` (its own sample rate; the sweeps' rate for T1, T7)."""
        scale = dict(zip(("laser", "force", "current"), self.noise))
        return RigConventions(
            sample_rate_hz=self.sweep_rate_hz if test in SWEEPS else self.rate_hz(test),
            step_phase=self.step_phase, clock_start_s=self.clock_start_s, pre_trigger_s=self.pre_trigger_s,
            record_s=self.record_s, t6_periods=self.t6_periods, t6_frequency_hz=self.t6_frequency_hz,
            sweep_gaps_mm=tuple(self.sweep_gaps_mm), sweep_hold_s=self.sweep_hold_s,
            sweep_average_s=self.sweep_average_s, laser=OUR_LASER.scaled(scale["laser"]),
            force=OUR_FORCE.scaled(scale["force"]), current=OUR_CURRENT.scaled(scale["current"]),
            manifest_coil=self.manifest_coil, t8_gap_mm=self.t8_gap_mm,
            step_gap_offset_mm=self.step_gap_offset_mm, t6_gap_offset_mm=self.t6_gap_offset_mm)


def truth(d: RigDescription, wt_pct: float, diameter_mm: float):
    """The true parameters of one sample under ``d`` (its coil, its hidden effect)."""
    p = replace(true_params(wt_pct, diameter_mm), a_m=d.coil_radius_mm / 1000.0,
                kB_T_per_A=d.field_per_amp_T_per_A)
    return with_effects(p, dict([d.effect]) if d.effect else None)


def make_from_description(out_dir, d: RigDescription) -> Path:
    """Write the dataset ``d`` describes into the empty or new folder ``out_dir``; returns the folder.

    The manifest holds the generator's truth under ``rig.independent_*`` (``independent_contact``: {sample id:
    [tests in which the diaphragm reached the coil face]}; remove them with
    :func:`tests.independent.bounds.blind` before identify or diagnose see the dataset).
    """
    from harness.data.dataset import Dataset, GapSweep, Sample, TimeSeries, write_dataset

    out_samples, truths, contacts = [], {}, {}
    for w, dia in d.samples:
        sid = sample_id(w, dia)
        p = truth(d, w, dia)
        truths[sid] = params_json(p)
        tests = {}
        for test in SWEEPS:
            cols = {"displacement_mm": None, "force_N": None,
                    **sweep(p, d.conventions(test), test, noise_rng(d.seed, sid, test))}
            tests[test] = GapSweep(test=test, file=None, field_T=FIELDS_T[test], **cols)
        t1 = tests["T1"]
        g_max = float(t1.gap_mm[int(np.argmax(t1.displacement_mm))])
        for test in TIME_SERIES:
            if test in d.absent:
                continue
            gap = d.t8_gap_mm if test == "T8" else g_max + (d.t6_gap_offset_mm if test == "T6"
                                                             else d.step_gap_offset_mm)
            conv = d.conventions(test)
            events = []
            cols = time_series(p, conv, test, gap, noise_rng(d.seed, sid, test), events)
            if any(kind == "contact" for _, kind in events):
                contacts.setdefault(sid, []).append(test)
            cols.setdefault("displacement_mm", None)
            cols.setdefault("force_N", None)
            tests[test] = TimeSeries(test=test, file=None, field_T=FIELDS_T[test], gap_mm=gap,
                                     frequency_hz=d.t6_frequency_hz if test == "T6" else None, **cols)
        for test in SWEEPS:
            if test in d.absent:
                del tests[test]
        out_samples.append(Sample(id=sid, wt_pct=float(w), diameter_mm=float(dia), thickness_mm=THICKNESS_MM,
                                  tests={k: tests[k] for k in sorted(tests)}))
    sc = d.conventions("T1")
    rig = {"sweep_hold_s": d.sweep_hold_s,
           "sensors": {"displacement_mm": sensor_json(sc.laser, sc, "mm"),
                       "force_N": sensor_json(sc.force, sc, "N"),
                       "current_A": sensor_json(sc.current, sc, "A")},
           "generator": "tests/independent/space.py (independent physics; not harness.data.rig)",
           "conventions": {**conventions_json(sc), "rates_hz": dict(zip(TIME_SERIES, d.rates_hz))},
           "independent_effects": dict([d.effect]) if d.effect else {},
           "independent_truth": truths,
           "independent_description": repr(d),
           "independent_contact": contacts,
           "seed": int(d.seed)}
    if d.manifest_period:
        rig["sample_period_s"] = 1.0 / d.sweep_rate_hz
    if d.manifest_coil:
        rig["coil_radius_mm"] = d.coil_radius_mm
        rig["field_per_amp_T_per_A"] = d.field_per_amp_T_per_A
    if d.sweep_average_s is None:
        rig["sweep_single_reading"] = True
    else:
        rig["sweep_average_s"] = d.sweep_average_s
    ds = Dataset(root=None, synthetic=True, rig=rig, samples=out_samples,
                 description="SYNTHETIC data from the independent test-data generator (tests/independent/space.py), "
                             "not measured")
    return write_dataset(ds, out_dir)


# ---------------------------------------------------------------- the Hypothesis strategy
def _round(x: float, digits: int = 3) -> float:
    return float(round(x, digits))


def rig_descriptions(*, max_rate_hz: float = 20000.0, max_samples: int = 4, max_record_s: float = 5.0,
                     complete: bool | None = None, effect: bool | None = False, max_noise: float = 5.0,
                     outside: bool = False):
    """Hypothesis strategy of :class:`RigDescription` (module docstring for the ranges).

    complete: True = T1, T3, T5, T7, T8 always present (T2, T4, T6 may be absent), None = T1 or T7 may be
    absent too; effect: False = clean, True = one hidden effect, None = either; max_noise: the largest
    noise scale drawn (effects are drawn with at most 1x noise so that they stand above it); outside: the
    hidden effect is one of :data:`OUTSIDE_FORMS` (outside the catalogue) instead of :data:`EFFECT_FORMS`.
    """
    from hypothesis import strategies as st

    lo, hi = math.log10(100.0), math.log10(max_rate_hz)
    rate = st.floats(lo, hi).map(lambda e: float(round(10.0 ** e)))

    @st.composite
    def build(draw):
        if draw(st.booleans()):
            rates = (draw(rate),) * len(TIME_SERIES)
        else:
            rates = tuple(draw(st.lists(rate, min_size=len(TIME_SERIES), max_size=len(TIME_SERIES))))
        sweep_rate = rates[1]           # the sweeps sampled as T3
        single = draw(st.booleans())
        hold = _round(draw(st.floats(0.6, 1.5)), 2)
        avg = None if single else max(_round(draw(st.floats(0.05, 0.5)), 3), 1.0 / sweep_rate)
        # gaps: distinct points of a 0.5 mm grid in 0 .. 25 mm, regular or not, in any order
        if draw(st.booleans()):
            step = draw(st.sampled_from([1.0, 1.5, 2.0, 2.5, 3.0, 4.0]))
            top = draw(st.sampled_from([g for g in np.arange(5 * step, 25.01, 0.5)]))
            gaps = [float(top - k * step) for k in range(int(top / step) + 1)]
        else:
            gaps = sorted(draw(st.sets(st.integers(0, 50), min_size=6, max_size=26)), reverse=True)
            gaps = [g / 2 for g in gaps]
        order = draw(st.sampled_from(["descending", "ascending", "shuffled"]))
        if order == "ascending":
            gaps = gaps[::-1]
        elif order == "shuffled":
            gaps = draw(st.permutations(gaps))
        with_effect = draw(st.booleans()) if effect is None else effect
        noise_hi = min(max_noise, 1.0) if with_effect else max_noise
        noise = tuple(_round(10 ** draw(st.floats(math.log10(0.2), math.log10(noise_hi))), 2) for _ in range(3))
        n = draw(st.integers(3, max(3, max_samples)))
        samples = draw(st.lists(st.tuples(st.integers(5, 40), st.sampled_from([20, 25, 30, 35, 40, 45, 50, 55, 60,
                                                                               65, 70, 75, 80])),
                                min_size=n, max_size=n, unique=True))
        absent_choices = OPTIONAL_TESTS + (SWEEPS if complete is None else ())
        absent = tuple(t for t in absent_choices if draw(st.booleans()) and (t in OPTIONAL_TESTS or
                                                                          draw(st.integers(0, 3)) == 0))
        eff = None
        if with_effect:
            eff = (draw(st.sampled_from(sorted(OUTSIDE_FORMS if outside else EFFECT_FORMS))),
                   _round(draw(st.floats(1.0, 2.5)), 2))
        return RigDescription(
            rates_hz=rates, sweep_rate_hz=sweep_rate, manifest_period=True if avg is not None else draw(st.booleans()),
            step_phase=_round(draw(st.floats(0.0, 0.999)), 3), clock_start_s=_round(draw(st.floats(0.0, 100.0)), 3),
            pre_trigger_s=_round(draw(st.floats(0.05, 0.5)), 3),
            record_s=_round(draw(st.floats(1.5, max_record_s)), 2),
            t6_periods=draw(st.integers(1, 2)), t6_frequency_hz=_round(draw(st.floats(0.5, 2.0)), 2),
            sweep_gaps_mm=tuple(gaps), sweep_hold_s=hold, sweep_average_s=avg, noise=noise,
            samples=tuple(samples), coil_radius_mm=_round(draw(st.floats(10.0, 25.0)), 2),
            field_per_amp_T_per_A=_round(draw(st.floats(0.15, 0.5)), 3), manifest_coil=draw(st.booleans()),
            step_gap_offset_mm=_round(draw(st.floats(1.0, 5.0)), 2),
            t6_gap_offset_mm=_round(draw(st.floats(1.5, 6.0)), 2), t8_gap_mm=_round(draw(st.floats(0.5, 5.0)), 2),
            absent=absent, effect=eff, seed=draw(st.integers(0, 2**16)))

    return build()
