"""Property-based tests over the space of valid datasets (issue 20): Hypothesis draws rig descriptions
(:func:`tests.independent.space.rig_descriptions`: per-test sample rates 100 Hz .. 20 kHz, step phases,
clocks, pre-triggers, record lengths, sweep grids and readings, per-channel noise, coils, gap offsets,
samples across and beyond the paper's range, subsets of samples and tests, hidden effects) and the
independent generator writes each dataset (its own physics, ``scipy.integrate.solve_ivp``).

Invariants:

1. reading, conventions inference, ``identify`` and ``diagnose`` end normally or refuse with one of the
   project's user-facing errors (a ``ValueError`` subclass defined in ``harness``, which the CLI prints as
   ``error: ...``); anything else (a bare ``ValueError`` from numpy such as "operands could not be broadcast
   together", an ``IndexError``, ...) is a defect. Through the CLI (in process) on one example per profile:
   every file written is complete and readable (JSON parses, CSV has a header and rows, others non-empty);
2. clean data (every test identify and diagnose fit present) -> the diagnosis verdict is ``none``;
3. clean data -> identified R, L, Em, K1, K2 and identify's least-squares C, m within the noise-derived
   bounds of :mod:`tests.independent.bounds` (:func:`~tests.independent.bounds.check`);
4. one hidden effect (magnitude 1 .. 2.5, noise at most 1x) whose paper-model held-out RMSE is at least
   three noise floors -> the diagnosis names its catalogue cause.

Several invariants share one generated dataset and its analysis (cached by the drawn description: the
parametrized tests below draw the same descriptions, ``derandomize`` seeds by the test function).

Profiles:

* fast (default suite; ``derandomize=True``, so CI draws the same examples every run; failures reported
  unshrunk): rates up to 2 kHz, records up to 2.5 s, three samples; 2 descriptions for invariant 1, 2 clean
  3 clean ones, each checked against invariants 2 and 3, 1 with an effect, the CLI on one fixed description, and the shrunk
  failures of :data:`REGRESSIONS` (measured: 2 min 39 s wall, 1 min 49 s CPU, on a loaded 2-core machine);
* deep (marker ``deep``, deselected by default): the whole space, hundreds of examples in total::

      nice pytest -m deep tests/independent/test_properties.py

  (150 descriptions for invariant 1, 60 clean ones for invariants 2 and 3, 60 with an effect for invariant
  4, 5 through the CLI: 275 examples, hours on one core). ``MPC_DEEP_SCALE=0.1`` runs a tenth of them;
  ``MPC_PROPS_NO_SHRINK=1`` reports a failure unshrunk (shrinking one takes minutes: every step is a
  whole analysis). A failure Hypothesis shrinks goes into :data:`REGRESSIONS` (the description's repr is
  valid Python; ``test_shrunk_failure`` checks it against the invariant it broke), so that it runs in the
  default suite forever.
"""
from __future__ import annotations

import csv
import json
import os
import tempfile
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, assume, event, example, given, settings
from hypothesis.control import currently_in_test_context

from harness.analysis import diagnosis as dg
from harness.analysis.identification.conventions import infer_conventions
from harness.analysis.identification.identify import identify_dataset
from harness.analysis.identification.settings import IdentifySettings
from harness.data.dataset import read_dataset
from tests.independent.bounds import ANALYTIC_KEYS, K_SD, REL_MODEL, Checks, blind, check
from tests.independent.space import EXPECTED_CAUSE, RigDescription, make_from_description, rig_descriptions

NSGA = IdentifySettings(pop_size=12, n_gen=5)
_COMMON = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                                     HealthCheck.data_too_large], print_blob=True)
if os.environ.get("MPC_PROPS_NO_SHRINK"):        # development runs: report the first failure unshrunk
    _COMMON["phases"] = [Phase.explicit, Phase.reuse, Phase.generate]
# the fast profile reports a failure unshrunk (shrinking one takes minutes: each step is a whole analysis);
# the deep profile shrinks
FAST = settings(max_examples=2, derandomize=True, database=None,
                **{**_COMMON, "phases": [Phase.explicit, Phase.reuse, Phase.generate]})
_SCALE = float(os.environ.get("MPC_DEEP_SCALE", "1"))


def _deep(n: int) -> settings:
    # no example database: its entries (and Hypothesis's mutations of them) would make near-copies of a few old
    # descriptions, with the same noise seed, a large part of the draws; the shrunk failures live in REGRESSIONS
    return settings(max_examples=max(1, int(round(n * _SCALE))), database=None, **_COMMON)


FAST_SPACE = dict(max_rate_hz=2000.0, max_samples=3, max_record_s=2.5)

# ---------------------------------------------------------------- shrunk failures, kept as fixtures
#: 100 Hz, coil radius not in the manifest (derived from T7: 9.894 +- 0.029 mm, true 10 mm), sweeps 0 .. 2.5 mm:
#: identified Em of W7-D35 and W9-D45 about 1 % low against a reported sd of 0.1 %: Em's uncertainty leaves
#: out the derived radius's (with the radius in the manifest the same data pass). Fixed on main (db13299).
EM_DERIVED_RADIUS = RigDescription(
    rates_hz=(100.0,) * 6, sweep_rate_hz=100.0, manifest_period=True, pre_trigger_s=0.05, record_s=1.5,
    t6_periods=1, t6_frequency_hz=0.5, sweep_gaps_mm=(2.5, 2.0, 1.5, 1.0, 0.5, 0.0), sweep_hold_s=0.6,
    sweep_average_s=0.05, samples=((5, 25), (7, 35), (9, 45)), coil_radius_mm=10.0, field_per_amp_T_per_A=0.15,
    manifest_coil=False, step_gap_offset_mm=1.0, t6_gap_offset_mm=1.5, t8_gap_mm=0.5)
#: no sample at the paper's 10/20/30 wt %: `mpc-actuator identify` writes validation_table3.csv and
#: validation_table4.csv with a header and no rows (Tables 3 and 4 summarized only IDENTIFICATION_WT_PCT).
#: Fixed on main (11b6ceb).
NO_PAPER_FRACTIONS = RigDescription(samples=((5, 25), (7, 35), (9, 45)))
#: identify with a small NSGA-II (12 x 5): the Eq. 6 point of W26-D45 far off (m 0.0030 kg, true 0.0056), and
#: the least-squares estimate started from it stops in a local minimum (m 0.00649 kg, reported sd 3e-5 kg;
#: residual sigma 5.59 um against 5.05 um at the global one that 24 x 15 and 64 x 60 populations reach)
LS_LOCAL_MINIMUM = RigDescription(
    rates_hz=(256.0, 1392.0, 1558.0, 1930.0, 200.0, 763.0), sweep_rate_hz=1392.0, manifest_period=True,
    step_phase=0.134, clock_start_s=91.256, pre_trigger_s=0.146, record_s=2.0, t6_periods=1, t6_frequency_hz=1.88,
    sweep_gaps_mm=(1.0, 3.5, 6.0, 8.5, 11.0, 13.5), sweep_hold_s=0.62, sweep_average_s=None,
    noise=(1.0, 2.57, 4.97), samples=((7, 60), (26, 45), (18, 45)), coil_radius_mm=16.78,
    field_per_amp_T_per_A=0.342, manifest_coil=False, step_gap_offset_mm=5.0, t6_gap_offset_mm=5.87,
    t8_gap_mm=3.74, absent=('T6',), effect=None, seed=5906)
#: the same family at 1148 Hz: identify's least-squares estimate of W24-D55 fails ("the T3/T5 residuals do not
#: determine C and m (no curvature around the identified point)") where the profile likelihood the test computes
#: from identify's own parameters finds C and m (sd 0.2 %, 0.4 %)
LS_NO_CURVATURE = RigDescription(
    rates_hz=(1148.0,) * 6, sweep_rate_hz=1148.0, manifest_period=True, step_phase=0.732, clock_start_s=0.0,
    pre_trigger_s=0.391, record_s=2.22, t6_periods=2, t6_frequency_hz=1.2,
    sweep_gaps_mm=(0.0, 7.0, 12.0, 14.0, 14.5, 17.0, 19.5, 21.5, 23.0, 23.5, 25.0), sweep_hold_s=1.02,
    sweep_average_s=None, noise=(1.1, 0.24, 0.5), samples=((24, 55), (39, 40), (36, 20)), coil_radius_mm=14.75,
    field_per_amp_T_per_A=0.389, manifest_coil=False, step_gap_offset_mm=2.0, t6_gap_offset_mm=1.9, t8_gap_mm=2.46,
    absent=('T4',), effect=None, seed=543)
#: clean, 190 Hz, single-reading sweeps on 7 irregular gaps: the sweep-reading noise estimated from the sweeps
#: (harness.data.protocol pooled_sweep_reading_noise, "estimated from the sweeps themselves") is 0.82 mA for
#: T7's current and 0.90 mA for T1's against the true 2 mA (one reading is one sample), so diagnose sees
#: "structure" in the T7 current (z = 13) and says "unexplained" instead of "none"
SWEEP_NOISE_UNDERESTIMATED = RigDescription(
    rates_hz=(190.0,) * 6, sweep_rate_hz=190.0, manifest_period=True, record_s=2.0, t6_periods=1,
    sweep_gaps_mm=(23.5, 18.5, 14.0, 12.5, 11.0, 7.0, 1.0), sweep_hold_s=1.0, sweep_average_s=None,
    samples=((11, 75), (5, 55), (31, 50)), absent=('T2', 'T4', 'T6'), seed=184)
#: clean, T5 sampled at 150 Hz (the other tests at 100 .. 1904 Hz), current noise 0.39x (sigma 0.78 mA under
#: a 1 mA quantization step): diagnose says "unexplained", structure in the T5 current (z = 5.2)
T5_CURRENT_STRUCTURE_150HZ = RigDescription(
    rates_hz=(100.0, 810.0, 677.0, 150.0, 100.0, 1904.0), sweep_rate_hz=810.0, manifest_period=True,
    pre_trigger_s=0.05, record_s=2.0, t6_periods=1, sweep_gaps_mm=(0.5, 3.0, 5.5, 8.0, 10.5, 13.0, 15.5, 18.0, 20.5, 23.0),
    sweep_hold_s=1.0, sweep_average_s=0.436, noise=(1.0, 1.0, 0.39), samples=((38, 25), (19, 60), (11, 40)),
    absent=('T2', 'T4', 'T6'))
#: clean, every test at 100 Hz, single-reading sweeps on 10 .. 25 mm only (the maximum-displacement gap found is the
#: sweep's smallest, 10 mm), coil radius derived: "unexplained", structure in many signals (T6 displacement
#: z = 13, T1 displacement 9.4, T8 current 9.3, T5 current 8.8, ...); partly shrunk (by hand: 4 -> 3 samples)
UNEXPLAINED_100HZ_FAR_SWEEP = RigDescription(
    rates_hz=(100.0,) * 6, sweep_rate_hz=100.0, manifest_period=False, step_phase=0.559, clock_start_s=7.682,
    pre_trigger_s=0.158, record_s=1.9, t6_periods=1, t6_frequency_hz=1.03,
    sweep_gaps_mm=(10.0, 11.0, 13.0, 14.0, 16.0, 19.0, 25.0), sweep_hold_s=0.81, sweep_average_s=None,
    noise=(0.74, 4.47, 0.49), samples=((26, 65), (36, 65), (12, 50)), coil_radius_mm=24.59,
    field_per_amp_T_per_A=0.499, manifest_coil=False, step_gap_offset_mm=1.88, t6_gap_offset_mm=4.18, t8_gap_mm=1.0,
    absent=('T2',), effect=None, seed=1193)


def user_error(e: BaseException) -> bool:
    """A documented, user-facing refusal, which the CLI prints as ``error: <message>``: a ValueError subclass
    the project defines (``harness.*``), or a plain ValueError raised by a ``raise`` statement of the project
    (:func:`harness.cli.raised_by_a_check`); never numpy's or scipy's ValueError (e.g. "operands could not be
    broadcast together"), an AssertionError of an internal invariant, or another exception."""
    from harness.cli import raised_by_a_check
    if not isinstance(e, ValueError):
        return False
    if type(e) is ValueError:
        return raised_by_a_check(e)
    return type(e).__module__.startswith("harness.")


def _event(text: str):
    """Hypothesis's ``event`` (statistics) inside a property; nothing in the plain regression tests."""
    if currently_in_test_context():
        event(text)


def _assume(condition: bool, why: str):
    """Hypothesis's ``assume`` inside a property; a plain regression test's description must satisfy it."""
    if currently_in_test_context():
        assume(condition)
    else:
        assert condition, why


# ---------------------------------------------------------------- one analysis per description (cached)
@dataclass
class Analysis:
    desc: RigDescription
    folder: Path | None = None
    ds: object = None
    conventions: object = None
    identified: dict | None = None
    diagnosis: object = None
    errors: dict = field(default_factory=dict)    # {stage: exception} (read, conventions, identify, diagnose)
    contact: dict = field(default_factory=dict)   # {sample id: [tests where the diaphragm reached the coil]}
    stage_s: dict = field(default_factory=dict)   # {stage: wall time [s]}
    stage_cpu_s: dict = field(default_factory=dict)   # {stage: CPU time of this process [s]: its wall time on an
    #                                                   idle core, whatever the machine's load (one worker)}
    done: bool = False

    @property
    def contact_in_identification(self) -> bool:
        """The diaphragm reached the coil face in T3 or T5: the paper's static balance cannot hold there."""
        return any(t in ("T3", "T5") for tests in self.contact.values() for t in tests)

    @property
    def must_be_analysed(self) -> bool:
        """Clean, complete (T1, T3, T5, T7, T8), no contact in T3/T5: nothing is missing, no stage may refuse."""
        return self.desc.complete and self.desc.effect is None and not self.contact_in_identification


_CACHE: dict = {}
_TMP = tempfile.TemporaryDirectory(prefix="mpc-props-")


def analyse(desc: RigDescription, without_contact: bool = False, diagnose: bool = True) -> Analysis:
    """Generate, read, infer conventions, identify, diagnose (identify and diagnose each on their own: the
    diagnosis does not need identify's result). ``without_contact``: Hypothesis rejects (``assume``) a
    dataset where the diaphragm reached the coil face in T3 or T5, before anything is analysed;
    ``diagnose=False``: stop after identify (the diagnosis runs on a later call that asks for it)."""
    if desc not in _CACHE:
        a = _CACHE[desc] = Analysis(desc)
        folder = Path(tempfile.mkdtemp(dir=_TMP.name)) / "ds"
        make_from_description(folder, desc)        # a generator failure is a test error, not a finding
        a.contact = json.loads((folder / "manifest.json").read_text())["rig"]["independent_contact"]
        a.folder = folder
    a = _CACHE[desc]
    if without_contact:
        _assume(not a.contact_in_identification, f"contact in T3/T5: {a.contact}")
    if a.done or (not diagnose and a.identified is not None):
        return a

    def stage(name, run):
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return run()
        except Exception as e:        # noqa: BLE001 - classified by the invariants
            a.errors[name] = e
            return None
        finally:
            a.stage_s[name] = time.perf_counter() - t0
            a.stage_cpu_s[name] = time.process_time() - c0

    if "read" not in a.stage_s:
        a.ds = stage("read", lambda: read_dataset(a.folder))
        if a.ds is not None:
            a.conventions = stage("conventions", lambda: infer_conventions(blind(a.ds)))
            a.identified = stage("identify", lambda: identify_dataset(blind(a.ds), NSGA, progress=False,
                                                                      workers=1))
    if diagnose and a.ds is not None:
        a.diagnosis = stage("diagnose", lambda: dg.diagnose(blind(a.ds), dg.DiagnoseSettings(workers=1)))
    a.done = diagnose or a.ds is None
    _record(a)          # identify-only analyses too (the coverage test's); a later diagnosis records again
    return a


def interval_rows(a: Analysis) -> list:
    """Identify's 95 % intervals of one analysis: one dict per sample and parameter (R, L, Em, K1, K2, C, m)
    with its ``estimate``, ``sd`` (of the joint covariance), ``lo``, ``hi`` and the generator's ``truth``
    (SI units, keys with units as in ``covariance_7``)."""
    rows = []
    truth = a.ds.rig.get("independent_truth", {}) if a.ds is not None else {}
    for sid, r in (a.identified or {}).items():
        cov = getattr(r, "covariance_7", None)
        if cov is None:
            continue
        sd = np.sqrt(np.diag(np.asarray(cov["matrix"], dtype=float)))
        est = [float(getattr(r.params, n)) for n in ("R", "L", "Em", "K1", "K2")]
        est += [r.least_squares["C_N_s_per_m"], r.least_squares["m_kg"]]
        for k, key in enumerate(cov["parameters"]):
            lo, hi = r.interval_95[key]
            rows.append(dict(sample=sid, key=key, estimate=est[k], sd=float(sd[k]), lo=float(lo), hi=float(hi),
                             truth=float(truth[sid][key])))
    return rows


def _record(a: Analysis):
    """With ``MPC_PROPS_RECORD=<file.jsonl>``: append one JSON line per analysis (``diagnosed`` false for the
    coverage test's identify-only ones) of a description (its repr, the wall
    time of each stage [s], refusals, the verdict, the held-out RMSE in noise floors (paper model, refit, final: what
    the effect invariant's "visible" reads) and, for identify's results, every sample's estimate, sd,
    95 % interval and truth of R, L, Em, K1, K2, C, m): the deep profile's measurements, summarized by
    ``benchmarks/deep_profile_report.py`` (interval coverage over the clean datasets, times)."""
    path = os.environ.get("MPC_PROPS_RECORD")
    if not path:
        return
    rows = interval_rows(a)
    line = dict(desc=repr(a.desc), drawn=currently_in_test_context(), effect=a.desc.effect, complete=a.desc.complete,
                contact_t3_t5=a.contact_in_identification, clean=a.must_be_analysed,
                rates_hz=list(a.desc.rates_hz), n_samples=len(a.desc.samples), stage_s=a.stage_s,
                stage_cpu_s=a.stage_cpu_s,
                errors={st: f"{type(e).__name__}: {e}" for st, e in a.errors.items()},
                verdict=getattr(a.diagnosis, "verdict", None), cause=getattr(a.diagnosis, "cause", None),
                heldout_rmse_per_noise_floor=(getattr(a.diagnosis, "gain", None) or {}).get("overall_normalized_rmse"),
                diagnosed="diagnose" in a.stage_s, intervals=rows)
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)   # one write: xdist workers share the file
    try:
        os.write(fd, (json.dumps(line) + "\n").encode("utf-8"))
    finally:
        os.close(fd)


def _describe(a: Analysis, stages=None) -> str:
    return "; ".join(f"{st}: {type(e).__module__}.{type(e).__name__}: {e}" for st, e in a.errors.items()
                     if stages is None or st in stages) or "no error"


# ---------------------------------------------------------------- the invariants (shared by both profiles)
def invariant_no_crash(desc: RigDescription):
    a = analyse(desc)
    crashes = {st: e for st, e in a.errors.items() if not user_error(e)}
    assert not crashes, f"crash, not a user-facing refusal: {_describe(a, crashes)}\n{desc!r}"
    for st, e in a.errors.items():
        _event(f"refused at {st}: {type(e).__name__}")
    if not a.errors:
        _event("analysed")
    # a refusal must concern a dataset that really lacks something (or has contact, or a hidden effect the
    # paper's model cannot settle): a clean, complete one must be analysed
    assert not (a.errors and a.must_be_analysed), f"clean, complete dataset refused: {_describe(a)}\n{desc!r}"


def _clean_analysis(desc: RigDescription, stages=("read", "conventions", "identify", "diagnose")) -> Analysis:
    a = analyse(desc, without_contact=True)
    assert not set(a.errors) & set(stages), f"dataset not analysed: {_describe(a, stages)}\n{desc!r}"
    return a


def invariant_verdict_none(desc: RigDescription):
    diag = _clean_analysis(desc).diagnosis
    assert diag.verdict == "none", (diag.verdict, diag.remainder.get("where"),
                                    {n: c["reason"] for n, c in diag.candidates.items()}, desc)


_UNDETERMINED = "do not determine C and m"


def invariant_within_bounds(desc: RigDescription, determined: bool = False):
    """identify's estimates within their bounds (tests.independent.bounds.check); where the T3/T5 residuals do not
    determine C and m, R, L, Em, K1 and K2 alone, unless ``determined`` (a fixture whose C and m the data pin)."""
    a = _clean_analysis(desc)
    try:
        c = check(a.ds, a.identified)
    except ValueError as e:
        assert not determined, f"C and m must be determined here: {type(e).__name__}: {e}\n{desc!r}"
        # the T3/T5 profile likelihood has no curvature: the data do not determine C and m, so their bound is
        # unbounded; R, L, Em, K1, K2 are still checked (their bounds come from the analytic identification)
        assert _UNDETERMINED in str(e), f"{type(e).__name__}: {e}\n{desc!r}"
        _event("C, m undetermined by the data")
        c = check_analytic(a.ds, a.identified)
    bad = c.analytic + c.least_squares
    assert not bad, "\n".join(bad) + f"\n{desc!r}"


def check_analytic(ds, results) -> Checks:
    """The analytic part of :func:`tests.independent.bounds.check` (R, L, Em, K1, K2) alone."""
    truth = ds.rig["independent_truth"]
    out = Checks()
    for sid, r in results.items():
        for key, true_key in ANALYTIC_KEYS:
            est, sd, true = getattr(r.params, key), r.uncertainty[key], truth[sid][true_key]
            if abs(est - true) > K_SD * sd + REL_MODEL * abs(true):
                out.analytic.append(f"{sid} {key}: {est:.6g} vs {true:.6g} (sd {sd:.3g})")
    return out


def invariant_effect_named(desc: RigDescription):
    a = _clean_analysis(desc, stages=("read", "conventions", "diagnose"))
    diag = a.diagnosis
    ov = diag.gain["overall_normalized_rmse"]
    msg = (f"effect {desc.effect}: verdict {diag.verdict!r}, cause {diag.cause!r}, held-out RMSE {ov}, "
           f"candidates { {n: (c['accepted'], c['reason']) for n, c in diag.candidates.items()} }\n{desc!r}")
    visible = bool(np.isfinite(ov["before"]) and ov["before"] >= 3.0)
    _event(f"effect {'visible' if visible else 'below 3 noise floors'}")
    if visible:
        assert diag.cause == EXPECTED_CAUSE[desc.effect[0]], msg


CLEAN_INVARIANTS = {"verdict_none": invariant_verdict_none, "within_bounds": invariant_within_bounds}


# ---------------------------------------------------------------- fast profile (default suite)
# Shrunk failures found by the deep profile or by development runs; each stays here forever.
@FAST
@given(desc=rig_descriptions(complete=None, effect=None, **FAST_SPACE))
def test_any_valid_dataset_is_analysed_or_refused_clearly(desc):
    invariant_no_crash(desc)


def _all_clean_invariants(desc):
    """Every clean invariant on one description (one analysis), all failures reported together."""
    failures = []
    for name in sorted(CLEAN_INVARIANTS):
        try:
            CLEAN_INVARIANTS[name](desc)
        except AssertionError as e:
            failures.append(f"{name}: {e}")
    assert not failures, "\n".join(failures)


# both invariants on each description: parametrized by invariant, Hypothesis drew different descriptions for
# each (derandomize seeds by the test's id), so the verdict went unchecked on the within-bounds draws (one of
# them, DERIVED_RADIUS_PULLED_1148HZ, was "unexplained")
@settings(FAST, max_examples=3)
@given(desc=rig_descriptions(complete=True, effect=False, **FAST_SPACE))
def test_clean_dataset(desc):
    _all_clean_invariants(desc)


@settings(FAST, max_examples=1)
@given(desc=rig_descriptions(complete=True, effect=True, **FAST_SPACE))
def test_hidden_effect_is_named(desc):
    invariant_effect_named(desc)


# ---------------------------------------------------------------- deep profile (-m deep)
@pytest.mark.deep
@_deep(150)
@given(desc=rig_descriptions(complete=None, effect=None))
def test_deep_any_valid_dataset_is_analysed_or_refused_clearly(desc):
    invariant_no_crash(desc)


@pytest.mark.deep
@_deep(60)
@given(desc=rig_descriptions(complete=True, effect=False))
def test_deep_clean_dataset(desc):
    """Both clean invariants on each description (one analysis)."""
    _all_clean_invariants(desc)


@pytest.mark.deep
@_deep(60)
@given(desc=rig_descriptions(complete=True, effect=True, max_samples=4))
def test_deep_hidden_effect_is_named(desc):
    invariant_effect_named(desc)


#: the target of issue 20: each parameter's 95 % interval holds the truth in 90 .. 98 % of the clean samples
COVERAGE_TARGET = (0.90, 0.98)
#: a coverage is refused when a one-sided binomial test rejects the nearer end of the target at this level
COVERAGE_ALPHA = 0.01


def independent_noise(desc: RigDescription) -> RigDescription:
    """``desc`` with a noise seed that depends on every other field too (CRC-32 of its repr with seed 0, XOR the
    drawn seed, 16 bits). Hypothesis draws many near-copies of its simplest examples (seed 0, the smallest
    samples, only a rate changed); the generator seeds each sample's noise by (seed, sample, test), so such
    copies share their sweeps' and steps' noise, and one unlucky realization (a coil radius 3 sd off, which moves
    Em of every sample of the dataset) would count as many. A coverage needs independent realizations."""
    import zlib
    from dataclasses import replace
    return replace(desc, seed=(zlib.crc32(repr(replace(desc, seed=0)).encode()) ^ int(desc.seed)) & 0xFFFF)


def test_independent_noise_separates_near_copies():
    """Two descriptions that differ only in one rate get different noise seeds; the same description the same."""
    a = RigDescription()
    b = RigDescription(rates_hz=(999.0,) + RigDescription().rates_hz[1:])
    assert independent_noise(a) == independent_noise(RigDescription())
    assert independent_noise(a).seed != independent_noise(b).seed
    assert independent_noise(a).rates_hz == a.rates_hz and 0 <= independent_noise(b).seed <= 0xFFFF


def coverage_verdicts(rows: list, target=COVERAGE_TARGET, alpha: float = COVERAGE_ALPHA) -> dict:
    """{parameter key: (n, hits, coverage, p-value, ok)} over interval rows (:func:`interval_rows`).

    ``ok``: the hits are consistent with a coverage inside ``target``: a one-sided binomial test of
    "coverage >= target[0]" (too few hits) and of "coverage <= target[1]" (too many: intervals too wide)
    does not reject at ``alpha``. With hundreds of samples this is the target itself; with a few dozen
    (``MPC_DEEP_SCALE`` < 1) it refuses only clear misses."""
    from scipy.stats import binomtest
    out = {}
    for key in dict.fromkeys(r["key"] for r in rows):
        sel = [r for r in rows if r["key"] == key]
        n = len(sel)
        hits = sum(r["lo"] <= r["truth"] <= r["hi"] for r in sel)
        p_low = binomtest(hits, n, target[0], alternative="less").pvalue
        p_high = binomtest(hits, n, target[1], alternative="greater").pvalue
        p = min(p_low, p_high)
        out[key] = (n, hits, hits / n, p, p >= alpha)
    return out


def _rows(n: int, hits: int, key: str = "L_H") -> list:
    return [dict(key=key, lo=0.0, hi=1.0, truth=0.5 if i < hits else 2.0) for i in range(n)]


def test_coverage_verdicts_by_hand():
    """Binomial tails computed by hand: 0.98**300 = 0.0023 (all 300 hits: intervals too wide), 0.98**100 =
    0.133 (all 100 hits: not enough samples to say), P(X <= 80 | n=100, p=0.9) = 0.0020 (too narrow), P(X <= 86)
    = 0.124 (consistent with 90 %)."""
    v = coverage_verdicts(_rows(300, 300))["L_H"]
    assert v[:3] == (300, 300, 1.0) and abs(v[3] - 0.98 ** 300) < 1e-12 and not v[4]
    v = coverage_verdicts(_rows(100, 100))["L_H"]
    assert abs(v[3] - 0.98 ** 100) < 1e-12 and v[4]
    assert not coverage_verdicts(_rows(100, 80))["L_H"][4]
    assert coverage_verdicts(_rows(100, 86))["L_H"][4]
    assert coverage_verdicts(_rows(200, 190) + _rows(50, 10, "R_Ohm")).keys() == {"L_H", "R_Ohm"}


@pytest.mark.deep
def test_deep_interval_coverage(capsys):
    """Issue 20's coverage criterion over independent draws of clean, complete datasets (the whole space): each of
    R, L, Em, K1, K2, C, m has its 95 % interval hold the truth in 90 .. 98 % of the samples
    (:func:`coverage_verdicts`). Plain random draws (no database replay, no explicit examples, no shrinking),
    so that the samples are independent noise realizations (:func:`independent_noise`); a description drawn twice
    counts once."""
    rows: dict = {}

    @settings(_deep(80), phases=[Phase.generate])
    @given(desc=rig_descriptions(complete=True, effect=False))
    def collect(desc):
        desc = independent_noise(desc)
        a = analyse(desc, without_contact=True, diagnose=False)
        assert "identify" not in a.errors, f"clean dataset not identified: {_describe(a)}\n{desc!r}"
        for r in interval_rows(a):
            rows[(repr(desc), r["sample"], r["key"])] = r

    collect()
    verdicts = coverage_verdicts(list(rows.values()))
    table = "\n".join(f"  {k:16s} n={n:4d} coverage {c:6.1%} (p {p:.3g})" for k, (n, h, c, p, ok) in verdicts.items())
    text = f"95 % interval coverage over {len({k[0] for k in rows})} clean datasets:\n{table}"
    with capsys.disabled():
        print("\n" + text)
    record = os.environ.get("MPC_PROPS_RECORD")
    if record:          # under xdist a worker's output is not shown: keep the table beside the record
        with open(f"{record}.coverage.txt", "a", encoding="utf-8") as f:
            f.write(text + "\n")
    bad = [k for k, v in verdicts.items() if not v[-1]]
    assert not bad, f"coverage outside {COVERAGE_TARGET}: {bad}\n{table}"


# ---------------------------------------------------------------- the CLI on one example per profile
def _check_outputs(out: Path):
    files = [p for p in out.rglob("*") if p.is_file()]
    assert files, f"nothing written to {out}"
    for p in files:
        assert p.stat().st_size > 0, f"empty file {p}"
        if p.suffix == ".json":
            json.loads(p.read_text(encoding="utf-8"))
        elif p.suffix == ".csv":
            rows = [r for r in csv.reader(line for line in p.read_text(encoding="utf-8").splitlines()
                                          if line and not line.startswith("#"))]
            assert rows and all(len(r) == len(rows[0]) for r in rows), f"ragged or empty CSV {p}"
            assert len(rows) >= 2, f"CSV without data rows (header only): {p.name}: {rows[0][:4]}..."
    return files


def _cli(desc: RigDescription, tmp_path: Path):
    from harness.cli import main
    folder = make_from_description(tmp_path / "ds", desc)
    for cmd, extra in (("identify", ["--pop-size", "12", "--generations", "5"]), ("diagnose", [])):
        out = tmp_path / cmd
        try:
            main([cmd, str(folder), "--out", str(out), "--workers", "1", "--quiet", *extra])
        except SystemExit as e:
            msg = str(e.code)
            assert msg.startswith("error: ") and "unexpected" not in msg, f"{cmd}: {msg}"
            assert not out.exists() or not any(out.iterdir()), f"{cmd} refused but left files in {out}"
            _event(f"{cmd} refused")
            continue
        _check_outputs(out)


@example(desc=NO_PAPER_FRACTIONS)
@settings(FAST, phases=[Phase.explicit])
@given(desc=rig_descriptions(complete=True, effect=None, **FAST_SPACE))
def test_cli_writes_complete_readable_files(desc):
    with tempfile.TemporaryDirectory(dir=_TMP.name) as d:
        _cli(desc, Path(d))


# ---------------------------------------------------------------- shrunk failures (default suite, forever)
#: deep profile on main (MPC_DEEP_SCALE=0.3): clean, 787 Hz, coil radius derived from T7 (11.27 +- 0.16 mm, true
#: 11.0): "unexplained", T6 displacement z = 23.8 (W37-D55, W17-D70: a 0.9 % amplitude error at 9 mm) because the
#: refit, whose default stopping rule ends a fit on a chi-square step below 2, left the radius at 11.24 mm; the
#: reference model now converges fully when it carries the radius (a 11.028 mm, verdict none)
T6_DERIVED_RADIUS_787HZ = RigDescription(
    rates_hz=(787.0,) * 6, sweep_rate_hz=787.0, manifest_period=False, step_phase=0.055, clock_start_s=0.0,
    pre_trigger_s=0.269, record_s=1.5, t6_periods=2, t6_frequency_hz=1.47,
    sweep_gaps_mm=(2.5, 5.5, 8.5, 11.5, 14.5, 17.5, 20.5, 23.5), sweep_hold_s=1.1, sweep_average_s=None,
    noise=(0.9, 5.0, 0.64), samples=((14, 20), (37, 55), (17, 70)), coil_radius_mm=11.0,
    field_per_amp_T_per_A=0.16, manifest_coil=False, step_gap_offset_mm=2.4, t6_gap_offset_mm=3.56, t8_gap_mm=3.73,
    absent=('T4',), effect=None, seed=0)

#: deep profile on main (MPC_DEEP_SCALE=0.3, session 6): clean, 787 Hz, single-reading sweeps in shuffled order:
#: "unexplained", T1 displacement z = 12.3 (W31-D20 alone: 22; -0.028 mm at the 2.5 mm gap). T3/T5 deflect too
#: little to determine K1: the analytic K1 came out non-positive, was floored at 1 N/m^3, and the refit, on
#: log K1 with a +-3 box, could neither move (zero gradient) nor reach the true 4.3e7 N/m^3; the refit now
#: starts an undetermined K1 at 0.1 K2/(D/20)^2 inside a box reaching 100 x that (K1 4.4e7, verdict none)
K1_UNDETERMINED_787HZ = RigDescription(
    rates_hz=(787.0,) * 6, sweep_rate_hz=787.0, manifest_period=True, step_phase=0.706, clock_start_s=71.784,
    pre_trigger_s=0.182, record_s=3.98, t6_periods=1, t6_frequency_hz=1.86,
    sweep_gaps_mm=(23.5, 20.5, 8.5, 17.5, 2.5, 14.5, 5.5, 11.5), sweep_hold_s=1.1, sweep_average_s=None,
    noise=(0.59, 1.0, 2.82), samples=((23, 20), (31, 20), (19, 55), (31, 70)), coil_radius_mm=11.41,
    field_per_amp_T_per_A=0.33, manifest_coil=True, step_gap_offset_mm=4.33, t6_gap_offset_mm=4.2, t8_gap_mm=2.84,
    absent=('T2', 'T4'), effect=None, seed=729)

#: fast profile (session 7; drawn for ``within_bounds`` only, so the verdict went unchecked until the deep
#: profile's record showed it): clean, 1148 Hz, radius derived from T7 (14.739 +- 0.013 mm, true 14.75): the
#: refit, guided only by T1's shape, moved the radius 1 % (to its bound, 14.59 mm) and the held-out T7 forces
#: showed structure (z 23.6, "unexplained"); the radius now carries its derivation as a Gaussian prior (14.735 mm)
DERIVED_RADIUS_PULLED_1148HZ = RigDescription(
    rates_hz=(1148.0,) * 6, sweep_rate_hz=1148.0, manifest_period=True, step_phase=0.732, clock_start_s=0.0,
    pre_trigger_s=0.391, record_s=2.22, t6_periods=2, t6_frequency_hz=1.2,
    sweep_gaps_mm=(2.0, 7.0, 12.0, 14.0, 14.5, 17.0, 19.5, 21.5, 23.0, 23.5, 25.0), sweep_hold_s=1.02,
    sweep_average_s=None, noise=(1.12, 0.24, 0.5), samples=((24, 55), (39, 40), (36, 35)), coil_radius_mm=14.75,
    field_per_amp_T_per_A=0.389, manifest_coil=False, step_gap_offset_mm=2.4, t6_gap_offset_mm=1.9, t8_gap_mm=2.46,
    absent=('T4',), effect=None, seed=543)

#: fast profile under xdist (session 7): clean, 905 Hz; the small NSGA-II front put W20-D80's m a decade low
#: (1.5 g, true 15.8 g): the C, m profile's coarse stage ran out of its 12 grids walking the C-m valley and the fine
#: stage out of its 4 recentrings: "the smallest residuals lie on the edge of the profile grid" (C, m None); now
#: 30 and 10 (C 0.7477, m 0.01581). Since session 18 that error says "do not determine C and m", which the bound
#: otherwise accepts; this fixture requires C and m determined ("within_bounds_determined")
CM_START_DECADE_OFF_905HZ = RigDescription(
    rates_hz=(905.0,) * 6, sweep_rate_hz=905.0, manifest_period=True, step_phase=0.7, clock_start_s=33.041,
    pre_trigger_s=0.333, record_s=2.43, t6_periods=2, t6_frequency_hz=1.97,
    sweep_gaps_mm=(1.5, 4.0, 6.5, 9.0, 11.5, 14.0, 16.5), sweep_hold_s=0.74, sweep_average_s=0.26,
    noise=(0.21, 0.94, 1.0), samples=((16, 75), (25, 65), (20, 80)), coil_radius_mm=18.79,
    field_per_amp_T_per_A=0.176, manifest_coil=True, step_gap_offset_mm=2.0, t6_gap_offset_mm=4.38, t8_gap_mm=1.85,
    absent=('T4',), effect=None, seed=287)

REGRESSIONS = {
    "least-squares-start-decade-off-905hz": ("within_bounds_determined", CM_START_DECADE_OFF_905HZ),
    "unexplained-derived-radius-pulled-1148hz": ("verdict_none", DERIVED_RADIUS_PULLED_1148HZ),
    "unexplained-k1-undetermined-787hz": ("verdict_none", K1_UNDETERMINED_787HZ),
    "unexplained-t6-derived-radius-787hz": ("verdict_none", T6_DERIVED_RADIUS_787HZ),
    "em-sd-without-derived-radius": ("within_bounds", EM_DERIVED_RADIUS),
    "least-squares-local-minimum": ("within_bounds", LS_LOCAL_MINIMUM),
    "least-squares-no-curvature": ("within_bounds", LS_NO_CURVATURE),
    "unexplained-sweep-reading-noise": ("verdict_none", SWEEP_NOISE_UNDERESTIMATED),
    "unexplained-t5-current-150hz": ("verdict_none", T5_CURRENT_STRUCTURE_150HZ),
    "unexplained-100hz-far-sweep": ("verdict_none", UNEXPLAINED_100HZ_FAR_SWEEP),
}

#: deep profile, session 11 (78533a9, MPC_DEEP_SCALE=0.5, unshrunk): clean, mixed rates (T3 and the sweeps at 100 Hz,
#: T5 7 kHz, T6 9.6 kHz), coil radius derived from the data, W14-D70 touching the coil face in T6: `unexplained`, T6
#: displacement z 5.19 (threshold 5), nothing accepted. Parameters within 0.1 % of the truth, but near the coil a 0.1 %
#: error in Em moves T6 by hundreds of chi-square units: the structure test now allows for the chi-square the fitted
#: parameters' own uncertainty adds to a held-out test (T6 displacement: mean 1975, sd 2721; z -0.49; verdict none)
T6_DERIVED_RADIUS_MIXED_RATES = RigDescription(rates_hz=(2753.0, 100.0, 2980.0, 7083.0, 9645.0, 215.0), sweep_rate_hz=100.0, manifest_period=True, step_phase=0.333, clock_start_s=45.469, pre_trigger_s=0.2, record_s=1.5, t6_periods=1, t6_frequency_hz=1.12, sweep_gaps_mm=(15.0, 24.5, 0.0, 17.5, 10.0, 17.0, 13.0, 0.5, 22.0, 1.0, 4.0, 7.0, 14.0, 7.5, 19.0, 8.5, 13.5, 3.5, 21.0), sweep_hold_s=1.23, sweep_average_s=0.427, noise=(1.0, 1.0, 1.84), samples=((33, 20), (32, 75), (14, 70)), coil_radius_mm=18.48, field_per_amp_T_per_A=0.227, manifest_coil=False, step_gap_offset_mm=3.71, t6_gap_offset_mm=1.5, t8_gap_mm=2.74, absent=(), effect=None, seed=4461)

#: slow clean-rig test of the discovery (session 11, ``test_clean_rigs_give_none`` rig 7): clean, 543 Hz, radius in the
#: manifest; T6 drives W27-D70 to 0.7 mm from the coil face: `unexplained`, T6 displacement z 7.94 (W27-D70 alone 12.4)
#: with every parameter within 0.1 % of the truth (at the truth z 2.3; Em +0.1 % gives 409). Allowing for the
#: parameters' prediction uncertainty (T6 displacement: mean 1376, sd 1381 of chi-square): z -0.53, verdict none
T6_NEAR_COIL_543HZ = RigDescription(
    rates_hz=(543.0,) * 6, sweep_rate_hz=543.0, manifest_period=True, step_phase=0.679, clock_start_s=0.0,
    pre_trigger_s=0.444, record_s=1.9, t6_periods=2, t6_frequency_hz=1.27,
    sweep_gaps_mm=(24.5, 20.5, 16.5, 12.5, 8.5, 4.5, 0.5), sweep_hold_s=1.29, sweep_average_s=0.474,
    noise=(0.28, 1.01, 1.49), samples=((21, 75), (14, 40), (27, 70)), coil_radius_mm=23.18, field_per_amp_T_per_A=0.489,
    manifest_coil=True, step_gap_offset_mm=4.53, t6_gap_offset_mm=2.78, t8_gap_mm=1.37, absent=('T4',), effect=None,
    seed=288)

#: deep profile, session 12 (e822842, MPC_DEEP_SCALE=0.3, unshrunk): clean, T6 at 105 Hz (a 1.89 Hz analog drive,
#: 55 samples per period): `unexplained`, T6 current z 8.51, every parameter near the truth. Reading the drive linear
#: between samples leaves 0.05 % of the current (chi-square 1.9 per reading of a Hall sensor's floor); the conventions
#: now also try a cubic spline through the samples, which the current picks (chi-square 0.93 per reading): verdict none
T6_ANALOG_DRIVE_105HZ = RigDescription(
    rates_hz=(386.0, 3471.0, 607.0, 528.0, 105.0, 565.0), sweep_rate_hz=3471.0, manifest_period=True, step_phase=0.0,
    clock_start_s=0.0, pre_trigger_s=0.05, record_s=1.5, t6_periods=1, t6_frequency_hz=1.89,
    sweep_gaps_mm=(8.5, 13.5, 10.5, 7.5, 3.5, 0.5, 14.5, 5.5, 16.5, 4.5, 15.5, 18.5, 11.5, 2.5, 6.5, 1.5, 19.5, 9.5,
                   17.5, 12.5), sweep_hold_s=0.99, sweep_average_s=None, noise=(1.0, 3.8, 0.22),
    samples=((39, 20), (37, 75), (24, 45)), coil_radius_mm=10.0, field_per_amp_T_per_A=0.15, manifest_coil=False,
    step_gap_offset_mm=1.0, t6_gap_offset_mm=1.5, t8_gap_mm=1.81, absent=(), effect=None, seed=0)

#: deep profile, session 13 (4c0dba0, MPC_DEEP_SCALE=0.3, unshrunk): clean, T3/T4/T5 and the sweeps at 100 Hz, radius in
#: the manifest: `unexplained`, T4 displacement z 6.83 (W23-D55 alone 11.3). T4's step instant, estimated from its
#: current's RL rise (1-2 samples on an 8 ms rise), lay 1.8 ms (2.3 sd) late, which moves the predicted rise by many
#: noise floors; the allowance now holds the held-out step tests' own instant uncertainty (T4 displacement: mean 170,
#: sd 132 of chi-square; z 0.80, verdict none)
T4_STEP_INSTANT_100HZ = RigDescription(
    rates_hz=(1756.0, 100.0, 100.0, 100.0, 232.0, 2764.0), sweep_rate_hz=100.0, manifest_period=True, step_phase=0.0,
    clock_start_s=1.569, pre_trigger_s=0.333, record_s=2.82, t6_periods=2, t6_frequency_hz=1.87,
    sweep_gaps_mm=(4.0, 1.0, 8.5, 23.5, 8.0, 11.0, 16.0, 9.5, 18.5, 11.5, 24.5, 25.0, 17.0), sweep_hold_s=0.87,
    sweep_average_s=0.098, noise=(1.01, 1.0, 2.66), samples=((23, 55), (20, 50), (33, 70)), coil_radius_mm=19.34,
    field_per_amp_T_per_A=0.5, manifest_coil=True, step_gap_offset_mm=1.94, t6_gap_offset_mm=3.72, t8_gap_mm=4.64,
    absent=('T2', 'T6'), effect=None, seed=33499)

#: session-15 deep profile (test_deep_clean_dataset): clean, T2 at 13.55 kHz whose current converter (1 mA steps)
#: has white noise of only 0.4 mA (0.2x); all three samples' T2 current rests 0.27 of a step above a level, where the
#: rounded reading's variance is 1.3 % above sigma^2 + q^2/12. Over 41 000 readings per sample the chi-square of
#: the T2 current stood 5.66 sd above its count: "unexplained" from the rounding alone. The residuals of a channel
#: whose rounding shapes its noise are now standardized with the rounded reading's exact mean and variance at the
#: readings' own level (harness.analysis.core.quantized.reading_weights).
T2_CURRENT_ROUNDING_13550HZ = RigDescription(
    rates_hz=(13550.0, 4339.0, 13550.0, 365.0, 316.0, 172.0), sweep_rate_hz=4339.0, manifest_period=True,
    step_phase=0.811, clock_start_s=1.0, pre_trigger_s=0.119, record_s=3.02, t6_periods=1, t6_frequency_hz=1.48,
    sweep_gaps_mm=(23.0, 21.0, 19.0, 17.0, 15.0, 13.0, 11.0, 9.0, 7.0, 5.0, 3.0, 1.0), sweep_hold_s=1.42,
    sweep_average_s=0.05, noise=(3.75, 0.25, 0.2), samples=((19, 65), (5, 80), (6, 35)), coil_radius_mm=24.0,
    field_per_amp_T_per_A=0.413, manifest_coil=False, step_gap_offset_mm=4.15, t6_gap_offset_mm=5.27, t8_gap_mm=1.02,
    absent=('T4',), effect=None, seed=954)

#: session-15 deep profile (test_deep_hidden_effect_is_named), found with the first form of the rounding fix above
#: (each residual standardized at the simulated value): laser and current noise 0.21x and 0.24x (below 0.7 of their
#: converters' steps), a two-time-constant coil heating 61 noise floors visible. Weights that follow the prediction
#: swing by +-6 % each time it crosses a step; with the paper model tens of floors off, that ripple steered the refit
#: (17.7 floors instead of 22.4) and the verdict was "motional_emf + unexplained remainder". The weights now come
#: from the readings' own moving mean (quantized.reading_weights): coil_heating.
COIL_HEATING_2TAU_ROUNDING_RIPPLE = RigDescription(
    rates_hz=(18540.0, 4311.0, 2071.0, 1872.0, 251.0, 4911.0), sweep_rate_hz=4311.0, manifest_period=True,
    step_phase=0.055, clock_start_s=1.207, pre_trigger_s=0.431, record_s=3.84, t6_periods=2, t6_frequency_hz=1.53,
    sweep_gaps_mm=(15.0, 20.5, 1.0, 21.0, 13.0, 19.0, 5.5, 12.0, 13.5, 23.5), sweep_hold_s=1.34, sweep_average_s=0.5,
    noise=(0.21, 1.0, 0.24), samples=((19, 55), (20, 40), (13, 20)), coil_radius_mm=18.76,
    field_per_amp_T_per_A=0.27, manifest_coil=False, step_gap_offset_mm=2.0, t6_gap_offset_mm=5.76, t8_gap_mm=3.19,
    absent=('T2', 'T4', 'T6'), effect=('coil_heating_2tau', 1.5), seed=142)

REGRESSIONS.update({
    "effect-coil-heating-2tau-rounding-weights-ripple": ("effect_named", COIL_HEATING_2TAU_ROUNDING_RIPPLE),
    "unexplained-t2-current-rounding-13550hz": ("verdict_none", T2_CURRENT_ROUNDING_13550HZ),
    "unexplained-t4-step-instant-100hz": ("verdict_none", T4_STEP_INSTANT_100HZ),
    "unexplained-t6-derived-radius-mixed-rates": ("verdict_none", T6_DERIVED_RADIUS_MIXED_RATES),
    "unexplained-t6-near-coil-543hz": ("verdict_none", T6_NEAR_COIL_543HZ),
    "unexplained-t6-current-105hz-analog-drive": ("verdict_none", T6_ANALOG_DRIVE_105HZ),
})


#: slow clean-rig test of the discovery (session 11, ``test_clean_rigs_give_none`` rig 5): clean, T3 at 100 Hz, T5 at
#: 667 Hz, radius derived from the data; W35-D65 (D 65 mm, gap 8.5 mm) rests on the coil face in T5. The paper's
#: static balance at that contact point put K1 at 7.09e5 N/m^3 (truth 3.99e5), the C, m fit made m 0.026 kg (truth
#: 0.0136) to make up for it, the refit could not recover (held-out RMSE 1.13 -> 6.70 noise floors) and the verdict
#: was "discovered:x_quadratic + discovered:x_cubic + unexplained remainder" after 317 CPU-s. Contact at T5 now
#: bounds K1 only, and the paper baseline fits K1 with C and m (K2 on T3's balance line).
T5_CONTACT_667HZ = RigDescription(
    rates_hz=(159.0, 100.0, 116.0, 667.0, 773.0, 294.0), sweep_rate_hz=100.0, manifest_period=True, step_phase=0.763,
    clock_start_s=99.521, pre_trigger_s=0.05, record_s=2.66, t6_periods=2, t6_frequency_hz=1.17,
    sweep_gaps_mm=(0.0, 2.5, 5.0, 10.5, 14.5, 20.0, 21.5, 25.0), sweep_hold_s=1.17, sweep_average_s=None,
    noise=(0.41, 0.93, 0.41), samples=((38, 40), (35, 65), (37, 35)), coil_radius_mm=13.44,
    field_per_amp_T_per_A=0.297, manifest_coil=False, step_gap_offset_mm=3.5, t6_gap_offset_mm=5.3, t8_gap_mm=2.62,
    absent=('T4', 'T6'), effect=None, seed=243)


def test_shrunk_failure_t5_contact_bounds_k1_only():
    """A clean dataset whose T5 reaches the coil face: the diagnosis says none, and its paper baseline's K1, K2, C, m
    of the contact sample are near the truth (the analytic K1 from the contact point was 78 % high)."""
    a = analyse(T5_CONTACT_667HZ)
    assert a.contact == {"W35-D65": ["T5"]}, a.contact          # the case is what it claims to be
    assert "diagnose" not in a.errors, _describe(a)
    diag = a.diagnosis
    truth = a.ds.rig["independent_truth"]["W35-D65"]
    p = diag.baseline_params["W35-D65"]
    for key, true_key, rel in (("K1", "K1_N_per_m3", 0.05), ("K2", "K2_N_per_m", 0.01), ("C", "C_N_s_per_m", 0.03),
                               ("m", "m_kg", 0.03)):
        assert abs(getattr(p, key) - truth[true_key]) <= rel * truth[true_key], (key, getattr(p, key), truth[true_key])
    assert any("rests on the coil face" in n for n in diag.evidence["baseline_notes"]["W35-D65"])
    assert diag.verdict == "none", (diag.verdict, diag.remainder.get("where"))


#: deep profile, session 11 (78533a9, MPC_DEEP_SCALE=0.5), rerun on main in session 12: filler_saturation 1.28 (the
#: catalogue's own form), 102 Hz, radius derived, T1 on an ascending grid 0-24.5 mm. The paper model misses by 8.87
#: noise floors (visible), but the verdict is `discovered:even_spring + unexplained remainder` (before: `unexplained`);
#: with a 3600 CPU-s budget and no screening, filler_saturation lowers BIC by 8.96 only (needs 10). Cause found: T1's
#: points at the dynamic pull-in boundary (W27-D60 and W36-D60 at 6.5 mm: measured on the coil face, the fitted models
#: free, 2.2 and 3.7 mm): at the true parameters (ksat included) the simulator puts them on the face too, but a fit
#: started from the refit's optimum cannot cross that discontinuity. Session 13: filler saturation also starts from
#: Em raised to keep T8's force and K1, K2 re-solved from T3/T5's saturated static balance at ksat 1, 3, 10 / T^2
#: (candidates.extra_starts): `filler_saturation + unexplained remainder` (held-out RMSE 8.86 -> 2.01; without the
#: starts, on the same main, `unexplained`).
T1_PULLIN_SATURATION = RigDescription(rates_hz=(102.0, 102.0, 102.0, 102.0, 102.0, 102.0), sweep_rate_hz=102.0, manifest_period=True, step_phase=0.432, clock_start_s=45.198, pre_trigger_s=0.347, record_s=2.0, t6_periods=1, t6_frequency_hz=0.7, sweep_gaps_mm=(0.0, 0.5, 1.0, 1.5, 2.5, 3.0, 4.5, 5.0, 6.5, 7.5, 10.0, 12.0, 12.5, 15.0, 16.0, 17.0, 17.5, 18.0, 19.0, 20.0, 21.5, 23.5, 24.0, 24.5), sweep_hold_s=0.87, sweep_average_s=0.349, noise=(0.87, 0.7, 0.98), samples=((27, 60), (37, 40), (33, 40), (36, 60)), coil_radius_mm=10.0, field_per_amp_T_per_A=0.161, manifest_coil=False, step_gap_offset_mm=4.18, t6_gap_offset_mm=2.18, t8_gap_mm=0.9, absent=(), effect=('filler_saturation', 1.28), seed=0)


@pytest.mark.deep
def test_shrunk_failure_t1_pullin_boundary_saturation_named():
    """Deep-profile failure of the effect invariant (about 80 CPU-s: under the deep marker)."""
    invariant_effect_named(T1_PULLIN_SATURATION)


#: deep profile, session 12 (e822842, MPC_DEEP_SCALE=0.3, unshrunk): edge_stiffening 2.5 with T1 and T6 absent (the
#: fit tests are T3, T5, T8 only), mixed rates 222 Hz-5.9 kHz, radius derived: the paper model misses the held-out
#: tests by 5.52 noise floors, but the verdict was `unexplained`. Session 13 found why: the refit holds W14-D80's T5
#: (6.3 of 6.9 mm) at the edge of pull-in with K1 4.5x too high, where adding K5 alone only makes it worse (chi-square
#: 3.9e6 -> 9.3e6 at K5 D^2/K1 = 0.001), so no fit left that optimum; and the first-round candidates started with the
#: derived radius reset to its prior centre (chi-square +2.0e6: the refit sits on a pull-in cliff). Now every candidate
#: starts at the refit's nuisance values, and edge stiffening also from K1, K2 re-solved from T3/T5's static balance
#: with the quintic spring (candidates.extra_starts): edge_stiffening named, held-out RMSE 5.52 -> 1.8.
EDGE_WITHOUT_T1 = RigDescription(
    rates_hz=(492.0, 5891.0, 1071.0, 222.0, 251.0, 4956.0), sweep_rate_hz=5891.0, manifest_period=False,
    step_phase=0.448, clock_start_s=24.083, pre_trigger_s=0.197, record_s=4.4, t6_periods=1, t6_frequency_hz=1.41,
    sweep_gaps_mm=(0.0, 0.5, 3.0, 9.5, 11.0, 17.5, 19.5, 20.0), sweep_hold_s=0.91, sweep_average_s=None,
    noise=(0.59, 0.91, 0.61), samples=((17, 50), (14, 80), (31, 75), (18, 45)), coil_radius_mm=13.48,
    field_per_amp_T_per_A=0.5, manifest_coil=False, step_gap_offset_mm=3.92, t6_gap_offset_mm=1.9, t8_gap_mm=1.73,
    absent=('T6', 'T1'), effect=('edge_stiffening', 2.5), seed=5247)


#: deep profile, session 13 (17c80c2, MPC_DEEP_SCALE=0.3, unshrunk): edge_stiffening 2.41, mixed rates, radius
#: derived: `unexplained` after 80 CPU-s (held-out RMSE 29.6 noise floors). The candidates' joint fits spent the
#: whole budget, so the held-out sample W35-D65 kept its start under the new shared K5 (0 iterations) and edge
#: stiffening lost the fit data by it (BIC +2.9e8); and a refit 30 prior sd off in the derived radius made the
#: screening charge every candidate that prior's chi-square (919). Now the joint fits end by their share of the
#: budget and the screening compares data chi-square only: edge_stiffening named (held-out RMSE 29.6 -> 5.2).
EDGE_BUDGET_SHARE = RigDescription(
    rates_hz=(2630.0, 1545.0, 131.0, 3536.0, 7308.0, 318.0), sweep_rate_hz=1545.0, manifest_period=True,
    step_phase=0.401, clock_start_s=0.333, pre_trigger_s=0.229, record_s=4.77, t6_periods=2, t6_frequency_hz=0.72,
    sweep_gaps_mm=(7.0, 9.0, 23.5, 24.0, 6.5, 16.0, 8.0, 1.0, 11.5, 8.5, 10.5, 5.0, 12.0, 13.0, 19.0, 12.5),
    sweep_hold_s=0.67, sweep_average_s=0.128, noise=(0.63, 0.26, 0.81), samples=((35, 65), (22, 55), (22, 70)),
    coil_radius_mm=17.07, field_per_amp_T_per_A=0.23, manifest_coil=False, step_gap_offset_mm=1.29,
    t6_gap_offset_mm=2.8, t8_gap_mm=2.71, absent=('T2',), effect=('edge_stiffening', 2.41), seed=15139)


@pytest.mark.deep
@pytest.mark.parametrize("desc", [EDGE_WITHOUT_T1, EDGE_BUDGET_SHARE], ids=["without-t1", "budget-share"])
def test_shrunk_failure_edge_stiffening_named(desc):
    """Deep-profile failures of the effect invariant (each about 80 CPU-s: under the deep marker)."""
    invariant_effect_named(desc)


def _paper_model_at_truth(desc: RigDescription, tmp_path):
    """(settings, prepared samples, FitContext, {i: Params}, ModelFit) of the paper model at the generator's true
    parameters of ``desc``'s dataset (blind: the diagnosis's view of it), for checks of the allowance against its
    definition."""
    from fmu_src.specs import Params
    from harness.analysis.diagnosis.candidates import base_vector
    from harness.analysis.diagnosis.fitting import FitContext, ModelFit
    from harness.analysis.diagnosis.prepare import prepare
    ds0 = read_dataset(make_from_description(tmp_path / "ds", desc))
    truth = ds0.rig["independent_truth"]
    st = dg.DiagnoseSettings(workers=1)
    samples = prepare(blind(ds0), st).samples
    ctx = FitContext(samples, st)
    params = {}
    for i, sd in enumerate(samples):
        t = truth[sd.sid]
        params[i] = Params(a=sd.a, D=sd.D, kB=sd.kB, R=t["R_Ohm"], L=t["L_H"], Em=t["Em_N_m_per_T2"],
                           K1=t["K1_N_per_m3"], K2=t["K2_N_per_m"], C=t["C_N_s_per_m"], m=t["m_kg"])
    mf = ModelFit(effects=(), shared={}, base={i: base_vector(p) for i, p in params.items()}, params=params,
                  fit_chi2=ctx.fit_chi2_of(params))
    return st, samples, ctx, params, mf


def test_prediction_allowance_is_the_mean_excess_of_parameter_draws(tmp_path):
    """The allowance's mean for a held-out test against its definition, by simulation instead of linear algebra: the
    mean, over parameter vectors drawn from each sample's covariance, of the held-out chi-square's increase over the
    chi-square at the centre (nonlinear simulations, no Jacobian of the held-out tests). On the T6_NEAR_COIL_543HZ
    data at the true parameters, where T6's displacement is the sensitive prediction."""
    from harness.analysis.diagnosis.allowance import heldout_parts, parameter_covariances, points, prediction_allowance
    st, samples, ctx, params, mf = _paper_model_at_truth(T6_NEAR_COIL_543HZ, tmp_path)
    allowance = prediction_allowance(ctx, mf)
    covs = parameter_covariances(ctx, mf)
    rng = np.random.default_rng(7)
    n_draws = 120
    jobs = []
    for i, (x0, cov) in covs.items():
        xs = rng.multivariate_normal(x0, cov, size=n_draws)
        jobs += [(i, p) for p in points(ctx, mf, i, list(xs))]
    held = heldout_parts(ctx, jobs)
    centre = heldout_parts(ctx, list(params.items()))
    checked = 0
    for key, (mu, var) in allowance.items():
        if mu < 20.0 or key[0] not in ctx.heldout_names:      # the fit tests' part: by refits, below
            continue
        excess = np.zeros(n_draws)
        for q, (i, _) in enumerate(jobs):
            excess[q % n_draws] += float(held[q][key] @ held[q][key]) - float(centre[i][key] @ centre[i][key])
        se = excess.std(ddof=1) / np.sqrt(n_draws)
        assert abs(excess.mean() - mu) <= 4.0 * se + 0.1 * mu, (key, excess.mean(), se, mu)
        checked += 1
    assert checked >= 1, allowance          # T6's displacement must be among the checked keys
    assert allowance[("T6", "y")][0] > 20.0, allowance


@pytest.mark.parametrize("name", sorted(REGRESSIONS))
def test_shrunk_failure(name, tmp_path):
    """Each description a property once failed on (shrunk), checked against the invariant it broke."""
    invariant, desc = REGRESSIONS[name]
    if invariant == "cli":
        _cli(desc, tmp_path)
    else:
        {**CLEAN_INVARIANTS, "no_crash": invariant_no_crash, "effect_named": invariant_effect_named,
         "within_bounds_determined": lambda d: invariant_within_bounds(d, determined=True)}[invariant](desc)


@pytest.mark.deep
@_deep(5)
@given(desc=rig_descriptions(complete=None, effect=None))
def test_deep_cli_writes_complete_readable_files(desc):
    with tempfile.TemporaryDirectory(dir=_TMP.name) as d:
        _cli(desc, Path(d))


def test_step_instant_allowance_is_the_mean_excess_of_instant_draws(tmp_path):
    """The step-instant allowance's mean against its definition, by simulation: the expectation, over step instants
    N(estimate, sd^2) (Gauss-Hermite quadrature, every node within the sample interval), of the held-out chi-square's
    increase over the chi-square at the estimate. On the T4_STEP_INSTANT_100HZ data at the true parameters, T4
    (100 Hz) of W23-D55."""
    from dataclasses import replace as dc_replace

    from harness.analysis.diagnosis.allowance import step_instant_allowance
    from harness.analysis.diagnosis.fitting import FitContext, ModelFit
    from harness.analysis.diagnosis.jobs import JobOptions, residual_parts, run_jobs
    st, samples, ctx, params, mf = _paper_model_at_truth(T4_STEP_INSTANT_100HZ, tmp_path)
    assert "T4" in ctx.heldout_names
    i = [k for k, sd in enumerate(samples) if sd.sid == "W23-D55"][0]
    sd, t4 = samples[i], samples[i].tests["T4"]
    assert t4.sd_step_delay_s > 0                               # the case is what it claims to be
    ctx1 = FitContext([sd], st)                                 # this sample's share of the allowance
    ctx1.heldout_names = ["T4"]
    mf1 = ModelFit(effects=(), shared={}, base={0: mf.base[i]}, params={0: params[i]}, fit_chi2={0: mf.fit_chi2[i]})
    mu = step_instant_allowance(ctx1, mf1)[("T4", "y")][0]
    # the expectation over d ~ N(0, sd^2) by 10-node Gauss-Hermite quadrature of simulated chi-squares (no Jacobian)
    nodes, weights = np.polynomial.hermite_e.hermegauss(10)
    deltas = t4.step_delay_s + t4.sd_step_delay_s * nodes
    assert deltas.min() > 0 and deltas.max() < t4.dt              # every node within the sample interval
    moved = [dc_replace(sd, tests={**sd.tests, "T4": dc_replace(t4, step_delay_s=float(d))}) for d in deltas]
    opts = JobOptions(full=True, max_rate_hz=st.max_rate_hz)
    sims = run_jobs([(m, params[i]) for m in [sd] + moved], ["T4"], opts)
    chi = [float(np.sum(residual_parts(m, s_, ["T4"], st.sweep_robust_c)[("T4", "y")] ** 2))
           for m, s_ in zip([sd] + moved, sims)]
    expected = float(np.sum(weights * (np.array(chi[1:]) - chi[0])) / np.sum(weights))
    assert mu > 20.0, mu                                        # T4's rise is sensitive to its instant here
    assert abs(expected - mu) <= 0.15 * mu, (expected, mu)


#: deep profile, session 16 (0741d44, MPC_DEEP_SCALE=0.25, unshrunk; in the crash test, which does not assert the
#: verdict): clean, 628 Hz, T2 and T6 absent, single-reading sweeps: `unexplained`, T8 blocked force z 6.05 carried by
#: W40-D60 (z 12.4; 1620 chi-square above its count at the true parameters). The current put T8's step instant 0.16 ms
#: (1.8 sd) early; the force, far more sensitive, pins it within 10 us. The fit tests' instants now have their
#: allowance (`fit_instant_allowance`): `none` (session 17)
T8_INSTANT_EARLY_628HZ = RigDescription(
    rates_hz=(628.0,) * 6, sweep_rate_hz=628.0, manifest_period=True, step_phase=0.318, clock_start_s=0.0,
    pre_trigger_s=0.5, record_s=4.29, t6_periods=2, t6_frequency_hz=1.9,
    sweep_gaps_mm=(25.0, 23.5, 22.0, 20.5, 19.0, 17.5, 16.0, 14.5, 13.0, 11.5, 10.0, 8.5, 7.0, 5.5, 4.0, 2.5, 1.0),
    sweep_hold_s=1.19, sweep_average_s=None, noise=(2.2, 0.63, 2.62), samples=((16, 25), (38, 60), (40, 60), (22, 35)),
    coil_radius_mm=11.98, field_per_amp_T_per_A=0.5, manifest_coil=True, step_gap_offset_mm=2.35,
    t6_gap_offset_mm=5.92, t8_gap_mm=2.15, absent=("T2", "T6"), effect=None, seed=1762)


def _only_instant(sd, name: str):
    """Sample data ``sd`` with every step instant's uncertainty but that of test ``name`` set to 0."""
    from dataclasses import replace as dc_replace
    return dc_replace(sd, tests={n: (dc_replace(t, sd_step_delay_s=0.0) if n != name and hasattr(t, "sd_step_delay_s")
                                     else t) for n, t in sd.tests.items()})


def _refit_one(st, sample, start):
    """(FitContext, ModelFit) of the paper model refitted to one sample's fit tests (tight) from log vector
    ``start``."""
    from harness.analysis.diagnosis.fitting import FitContext, ModelSpec
    ctx = FitContext([sample], st)
    ctx.set_bounds({0: start})
    ctx.tight = True
    return ctx, ctx.fit_many([ModelSpec((), {0: start}, None)])[0]


def test_fit_instant_allowance_is_the_mean_excess_of_refits_over_instant_draws(tmp_path):
    """The fit step tests' instant allowance against its definition, by refits instead of linear algebra: the
    expectation, over T8's step instant N(estimate, sd^2) (Gauss-Hermite quadrature, every node within the sample
    interval), of the increase of T8's blocked-force chi-square at the least-squares parameters refitted for that
    instant over the one at the estimate. W40-D60 of the T8_INSTANT_EARLY_628HZ data (T8's instant the only uncertain
    one), where the force pins the instant far better than the current."""
    from dataclasses import replace as dc_replace

    from harness.analysis.diagnosis.allowance import fit_instant_allowance
    st, samples, _, params, mf = _paper_model_at_truth(T8_INSTANT_EARLY_628HZ, tmp_path)
    i = [k for k, s in enumerate(samples) if s.sid == "W40-D60"][0]
    sd = _only_instant(samples[i], "T8")
    t8 = sd.tests["T8"]
    nodes, weights = np.polynomial.hermite_e.hermegauss(8)
    deltas = t8.step_delay_s + t8.sd_step_delay_s * nodes
    assert t8.sd_step_delay_s > 0 and deltas.min() > 0 and deltas.max() < t8.dt      # the case is what it claims
    ctx0, mf0 = _refit_one(st, sd, mf.base[i])
    mu = fit_instant_allowance(ctx0, mf0)[("T8", "y")][0]

    def t8_chi2(fit):
        return fit.fit_chi2[0][("T8", "y")][0]

    excess = [t8_chi2(_refit_one(st, dc_replace(sd, tests={**sd.tests, "T8": dc_replace(t8, step_delay_s=float(d))}),
                                 np.asarray(mf0.base[0]))[1]) - t8_chi2(mf0) for d in deltas]
    expected = float(np.sum(weights * np.array(excess)) / np.sum(weights))
    assert mu > 50.0, mu                                        # the force is sensitive to its instant here
    assert abs(expected - mu) <= 0.25 * mu, (expected, mu, excess)


def test_fit_step_instants_add_the_refits_spread_to_the_parameter_covariance(tmp_path):
    """The fit step tests' instant term of the allowance's parameter covariance against refits by hand: move T5's
    step instant by +/- up to its standard uncertainty sd, refit the sample's parameters by least squares each time,
    and their difference per 2 sd, d, must be the term's square root, S(with instants) - S(without) = d d^T (T5 the only
    instant with an uncertainty). W21-D50 of the T4_18KHZ_HELDOUT_QUANTIZED_LASER data (T5 at 870 Hz), whose L and m
    move by several times their noise sd per sd of the instant."""
    from dataclasses import replace as dc_replace

    from harness.analysis.diagnosis.allowance import parameter_covariances
    st, samples, _, params, mf = _paper_model_at_truth(T4_18KHZ_HELDOUT_QUANTIZED_LASER, tmp_path)
    i = [k for k, s in enumerate(samples) if s.sid == "W21-D50"][0]
    sd = _only_instant(samples[i], "T5")
    t5 = sd.tests["T5"]
    # a move of up to its sd, within its sample interval
    move = min(t5.sd_step_delay_s, 0.8 * t5.step_delay_s, 0.8 * (t5.dt - t5.step_delay_s))
    assert move > 0.3 * t5.sd_step_delay_s, (t5.step_delay_s, t5.sd_step_delay_s, t5.dt)

    ctx0, mf0 = _refit_one(st, sd, mf.base[i])
    x0 = np.asarray(mf0.base[0])
    moved = [_refit_one(st, dc_replace(sd, tests={**sd.tests, "T5": dc_replace(t5, step_delay_s=t5.step_delay_s
                                                                                + g * move)}), x0)[1].base[0]
             for g in (1.0, -1.0)]
    d = (np.asarray(moved[0]) - np.asarray(moved[1])) / (2.0 * move) * t5.sd_step_delay_s     # per sd of the instant
    with_t = parameter_covariances(ctx0, mf0)[0][1]
    without = parameter_covariances(ctx0, mf0, instants=False)[0][1]
    term = with_t - without
    big = np.abs(d) > 1e-3                                    # log-parameter moves far above the refits' tolerance
    assert big.sum() >= 2, d                                  # L and m at least: the case is what it claims to be
    assert np.allclose(np.sqrt(np.diag(term))[big], np.abs(d[big]), rtol=0.2), (np.sqrt(np.diag(term)), d)
    k, q = np.flatnonzero(big)[:2]
    assert np.sign(term[k, q]) == np.sign(d[k] * d[q]), (term[k, q], d)



#: deep profile, session 17 (5b073a4, MPC_DEEP_SCALE=0.5, unshrunk; the coverage test): clean and complete, 13.7 kHz,
#: records of 2.22 s (1.72 s after the step). W12-D55's T3 (its small 0.11 T step in laser noise) left the 2 % band
#: for the last time 1.51 s after the step, after the start of identify's steady window (the last half of the record
#: after the step, 0.863 s after it), so identify refused the dataset ("never settles within the record"), although
#: 0.21 s of the record (2900 readings, their halves' means 0.04 % of the step apart) lie after it. A step settling
#: after the default window's start is now averaged from its settling time on when at least a tenth of the record
#: after the step follows and those readings do not drift (identify._settling_checked)
SLOW_SETTLING_SHORT_RECORD_13689HZ = RigDescription(
    rates_hz=(13689.0,) * 6, sweep_rate_hz=13689.0, manifest_period=False, step_phase=0.0, clock_start_s=0.0,
    pre_trigger_s=0.495, record_s=2.22, t6_periods=1, t6_frequency_hz=1.6,
    sweep_gaps_mm=(21.0, 16.0, 12.5, 12.0, 11.0, 9.0), sweep_hold_s=0.89, sweep_average_s=None,
    noise=(0.49, 3.16, 0.23), samples=((12, 55), (15, 35), (14, 35), (35, 25)), coil_radius_mm=25.0,
    field_per_amp_T_per_A=0.345,
    manifest_coil=True, step_gap_offset_mm=4.64, t6_gap_offset_mm=2.01, t8_gap_mm=4.52, absent=("T2", "T6"),
    effect=None, seed=32402)


#: deep profile, session 16 (404d53f, MPC_DEEP_SCALE=0.6, unshrunk; here W33-D20 alone, which fails the same way):
#: clean, T3 at 705 Hz, T5 at 6.2 kHz, laser noise 5x. W33-D20 (20 mm, natural frequency 56 Hz, damping ratio 0.55)
#: barely moves, and its T3/T5 residuals bound m from above only: the deviance is 1 at m / 4 and 3.8 at the true m
#: (2.7x the least-squares point). The quadratic fitted over Delta < 12 was centred 1.1 in ln m below the least-squares
#: point, and identify reported m 1.27e-4 kg (true 1.244e-3) with a linear sd of 1.6e-4 and a 95 % interval reaching
#: below zero; the bound read it as 7 sd off. Now the point is the least-squares point (cm_profile's
#: CENTRE_TOLERANCE), the intervals of C and m are log-normal, and the bound is taken in ln C, ln m
#: (tests.independent.bounds): 2 sd. About 70 CPU-s: under the deep marker
M_BOUNDED_ABOVE_ONLY_20MM = RigDescription(
    rates_hz=(10477.0, 705.0, 3713.0, 6244.0, 100.0, 595.0), sweep_rate_hz=705.0, manifest_period=False,
    step_phase=0.533, clock_start_s=6.0, pre_trigger_s=0.131, record_s=3.82, t6_periods=2, t6_frequency_hz=1.16,
    sweep_gaps_mm=(21.5, 1.5, 13.5, 9.5, 5.5, 17.5), sweep_hold_s=1.5, sweep_average_s=None, noise=(5.0, 1.37, 1.0),
    samples=((33, 20),), coil_radius_mm=25.0, field_per_amp_T_per_A=0.5, manifest_coil=False, step_gap_offset_mm=4.67,
    t6_gap_offset_mm=1.52, t8_gap_mm=1.79, absent=(), effect=None, seed=2120)


@pytest.mark.deep
def test_shrunk_failure_m_bounded_from_above_only():
    """The session-16 failure of the within-bounds invariant (module comment above), and its 95 % interval of m
    positive."""
    invariant_within_bounds(M_BOUNDED_ABOVE_ONLY_20MM)
    a = _clean_analysis(M_BOUNDED_ABOVE_ONLY_20MM)
    lo, hi = a.identified["W33-D20"].interval_95["m_kg"]
    assert 0 < lo < a.identified["W33-D20"].params.m < hi


#: deep profile, session 16 (404d53f, MPC_DEEP_SCALE=0.6, unshrunk): a two-time-constant coil heating (1.87), 22.8
#: noise floors visible, four samples at 6.9 kHz, 4.8 s records, T2, T4, T6 absent (identify refuses it: the steps
#: never settle). The paper model's refit, with R near the records' mean hot resistance, kept chi-square 500 per
#: residual, and from there every candidate's screening rejected all its steps (heating added to the hot R makes
#: every current too low): all six screened out, "unexplained". coil_heating now also starts from the cold R that
#: its heating would raise to the reference's (candidates.extra_starts): "coil_heating + unexplained remainder".
#: About 80 CPU-s: under the deep marker
HEATING_FROM_HOT_R_6942HZ = RigDescription(
    rates_hz=(6942.0,) * 6, sweep_rate_hz=6942.0, manifest_period=True, step_phase=0.0, clock_start_s=0.0,
    pre_trigger_s=0.5, record_s=4.81, t6_periods=2, t6_frequency_hz=1.42,
    sweep_gaps_mm=(22.5, 18.5, 14.5, 10.5, 6.5, 2.5), sweep_hold_s=1.13, sweep_average_s=None, noise=(1.0, 1.0, 0.58),
    samples=((6, 30), (38, 60), (28, 75), (15, 35)), coil_radius_mm=11.38, field_per_amp_T_per_A=0.388,
    manifest_coil=False, step_gap_offset_mm=3.84, t6_gap_offset_mm=5.24, t8_gap_mm=4.07, absent=('T2', 'T4', 'T6'),
    effect=('coil_heating_2tau', 1.87), seed=31137)


#: deep profile, session 16 (1997815, MPC_DEEP_SCALE=0.35, unshrunk): clean, 262 Hz, two 20 mm samples that barely
#: deflect (K1 of W6-D20 3.3e7 +- 3.3e7 N/m^3, of W5-D20 at its bound 0 with sd 5.9e7). identify's estimates were all
#: within their intervals, but the bound's own propagation (tests.independent.bounds.cm_bound) took the principal axes
#: of the analytic covariance in SI, where the variances span 22 orders of magnitude: eigh's rounding at K1's scale put
#: an L step of the size of L itself into an axis, and the simulation refused "parameter L must be > 0, got 0.0". The
#: axes are now taken in the parameters' relative scale (K1 at 0: its sd), as harness's propagate does. About 110
#: CPU-s: under the deep marker
K1_UNDETERMINED_BOUND_SCALE_262HZ = RigDescription(
    rates_hz=(262.0,) * 6, sweep_rate_hz=262.0, manifest_period=False, step_phase=0.0, clock_start_s=0.0,
    pre_trigger_s=0.05, record_s=1.5, t6_periods=1, t6_frequency_hz=0.5, sweep_gaps_mm=(2.5, 2.0, 1.5, 1.0, 0.5, 0.0),
    sweep_hold_s=0.92, sweep_average_s=None, noise=(1.0, 1.0, 1.0), samples=((6, 30), (5, 50), (6, 20), (5, 20)),
    coil_radius_mm=10.0, field_per_amp_T_per_A=0.15, manifest_coil=False, step_gap_offset_mm=1.0,
    t6_gap_offset_mm=1.5, t8_gap_mm=4.19, absent=(), effect=None, seed=1)


#: deep-profile failures too slow for the default suite (each 80-110 CPU-s), checked against the invariant they broke
#: deep profile, session 16 (0741d44, MPC_DEEP_SCALE=0.25, unshrunk): clean, T4 at 18 kHz with laser noise 0.21x (below
#: 0.7 of the converter's step: a quantized channel), T3 478 Hz, T5 870 Hz, single-reading sweeps: `unexplained`, T4
#: displacement z 5.71, carried by W21-D50 alone (z 27.3; at the generator's true parameters z 1.1). The allowance's
#: parameter covariance left out the fit tests' own step instants, which at 478 and 870 Hz give 4x the noise's sd of L
#: and 6x that of m: with them, T4 z 0.47 and the verdict `none` (session 17)
T4_18KHZ_HELDOUT_QUANTIZED_LASER = RigDescription(
    rates_hz=(197.0, 478.0, 18019.0, 870.0, 316.0, 19622.0), sweep_rate_hz=478.0, manifest_period=True,
    step_phase=0.0, clock_start_s=0.0, pre_trigger_s=0.229, record_s=1.5, t6_periods=1, t6_frequency_hz=1.8,
    sweep_gaps_mm=(16.5, 21.5, 1.5, 4.0, 9.0, 19.0, 11.5, 6.5, 14.0), sweep_hold_s=0.94, sweep_average_s=None,
    noise=(0.21, 1.0, 4.2), samples=((21, 50), (9, 55), (31, 70), (31, 45)), coil_radius_mm=12.21,
    field_per_amp_T_per_A=0.373, manifest_coil=True, step_gap_offset_mm=1.39, t6_gap_offset_mm=1.5, t8_gap_mm=2.5,
    absent=(), effect=None, seed=188)


#: deep profile, session 17 (5b073a4, MPC_DEEP_SCALE=0.5, unshrunk): a two-time-constant creep (1.03) at 100 Hz, T4
#: and T6 absent. Its diagnosis took 165.9 CPU-s (its fit budget is 75): discovery drove heat_softening's lag to its
#: fixed 0.1 ms bound, where each simulation takes 2.7 CPU-s (steps of 0.3 tau) and one LM batch 116 s. A lag's time
#: constant is now bounded by a tenth of the shortest sample period (discovery.library.LAG_RESOLUTION; 1 ms here),
#: below which the readings see it as instantaneous: 71.6 CPU-s, the same cause. The CPU time is measured by
#: benchmarks/bench_diagnose_datasets.py ("100Hz-creep"), never asserted; here the cause it must name
CREEP_FAST_LAG_100HZ = RigDescription(
    rates_hz=(100.0,) * 6, sweep_rate_hz=100.0, manifest_period=True, step_phase=0.075, clock_start_s=66.247,
    pre_trigger_s=0.132, record_s=4.65, t6_periods=1, t6_frequency_hz=1.98,
    sweep_gaps_mm=(1.0, 2.0, 4.0, 5.0, 5.5, 8.5, 9.5, 10.0, 13.5, 16.0, 16.5, 18.5, 19.0, 19.5, 21.0, 21.5, 22.0, 24.5),
    sweep_hold_s=0.6, sweep_average_s=None, noise=(0.32, 1.0, 0.21), samples=((10, 65), (37, 50), (39, 50), (6, 80)),
    coil_radius_mm=15.79, field_per_amp_T_per_A=0.263, manifest_coil=True, step_gap_offset_mm=3.47,
    t6_gap_offset_mm=5.09, t8_gap_mm=1.31, absent=("T4", "T6"), effect=("creep_2tau", 1.03), seed=27)


#: deep profile, session 18 (16030c2, MPC_DEEP_SCALE=0.35, unshrunk; the clean test): clean, mixed rates (T2 at
#: 100 Hz), laser noise 2.4x. W7-D20 (natural frequency 53 Hz, damping ratio 0.55) barely moves: its T3/T5 deviance
#: falls by under 2 over a factor e^4 toward m -> 0 (the truth at 1.7). identify said so ("the T3/T5 residuals do not
#: determine C and m") and kept the Eq. 6 choice; the bound's own profile, started there, ran out of its fine grids
#: with the best point on the edge and said "the least-squares point of C and m was not found", which the invariant
#: took for a failure. cm_profile now says that the residuals do not determine C and m there (the 95 % region still
#: reaches the edge after its last grid), and the bound checks R, L, Em, K1, K2 alone
CM_VALLEY_TOWARD_ZERO_MASS_20MM = RigDescription(
    rates_hz=(8797.0, 100.0, 1268.0, 3692.0, 366.0, 256.0), sweep_rate_hz=100.0, manifest_period=True,
    step_phase=0.315, clock_start_s=99.939, pre_trigger_s=0.107, record_s=4.74, t6_periods=1, t6_frequency_hz=0.7,
    sweep_gaps_mm=(12.5, 11.5, 10.5, 9.5, 8.5, 7.5, 6.5, 5.5, 4.5, 3.5, 2.5, 1.5, 0.5), sweep_hold_s=1.48,
    sweep_average_s=None, noise=(2.41, 2.83, 1.0), samples=((37, 60), (7, 20), (36, 40)), coil_radius_mm=11.11,
    field_per_amp_T_per_A=0.5, manifest_coil=True, step_gap_offset_mm=4.66, t6_gap_offset_mm=4.32, t8_gap_mm=0.64,
    absent=("T2", "T4"), effect=None, seed=8905)


#: deep profile, session 18 (4050248, MPC_DEEP_SCALE=0.35, unshrunk; the clean test): clean, 143 Hz, laser noise 4x,
#: T6 absent. W9-D20 (9 wt %, 20 mm) barely moves in T3 (0.11 T): its steady displacement, 2.8 um, lies within 3
#: standard deviations of its window mean, and identify refused the dataset ("the steady displacement 0.002801 mm is
#: not a positive step toward the coil"; the previous main, 9a8e3d5, the same; a 3-sd rule still refuses it). A T3
#: the noise does not resolve, beside a resolved T5, now leaves K1 undetermined (0, its sd from the T3/T5
#: propagation: 1.4e11 N/m3) and takes K2 from T5 (78.0 +- 48 N/m, true 87.3), within the bounds
T3_STEP_WITHIN_NOISE_143HZ = RigDescription(
    rates_hz=(143.0,) * 6, sweep_rate_hz=143.0, manifest_period=True, step_phase=0.0, clock_start_s=58.205,
    pre_trigger_s=0.281, record_s=4.85, t6_periods=2, t6_frequency_hz=0.63,
    sweep_gaps_mm=(8.0, 10.0, 17.0, 18.5, 22.5, 24.0), sweep_hold_s=1.5, sweep_average_s=None, noise=(4.0, 0.32, 0.21),
    samples=((8, 60), (35, 45), (9, 20)), coil_radius_mm=20.04, field_per_amp_T_per_A=0.432, manifest_coil=True,
    step_gap_offset_mm=3.85, t6_gap_offset_mm=1.86, t8_gap_mm=4.84, absent=("T6",), effect=None, seed=65536)


#: deep profile, session 19 (9fb18ed, MPC_DEEP_SCALE=0.15, unshrunk): a tanh-shaped filler saturation (2.06) at
#: 1539 Hz, four samples, 4 s records. Its diagnosis took 123.2 CPU-s (fit budget 75): the budget was checked
#: between batches of 64 points, and one batch of the filler_saturation + even_spring joint fit cost 45 CPU-s. The
#: batches now shrink as the deadline nears (lsq.BUDGET_BATCH_SHARE). The CPU time is measured by
#: benchmarks/bench_diagnose_datasets.py ("1539Hz-tanh"), never asserted; here the cause it must name
SATURATION_TANH_1539HZ = RigDescription(
    rates_hz=(1539.0,) * 6, sweep_rate_hz=1539.0, manifest_period=True, step_phase=0.0, clock_start_s=35.376,
    pre_trigger_s=0.052, record_s=4.0, t6_periods=1, t6_frequency_hz=1.94,
    sweep_gaps_mm=(14.0, 8.0, 9.5, 0.5, 5.0, 6.5, 3.5, 2.0, 15.5, 11.0, 12.5), sweep_hold_s=1.18,
    sweep_average_s=0.445, noise=(0.99, 0.56, 0.27), samples=((28, 75), (34, 35), (31, 70), (25, 20)),
    coil_radius_mm=10.57, field_per_amp_T_per_A=0.323, manifest_coil=True, step_gap_offset_mm=3.17,
    t6_gap_offset_mm=2.81, t8_gap_mm=2.73, absent=(), effect=("saturation_tanh", 2.06), seed=17948)


#: deep profile, session 20 (7c20a73, MPC_DEEP_SCALE=0.25, unshrunk): a two-time-constant coil heating (1.3), 101.6
#: noise floors visible, four samples at 7457 Hz, 4.81 s records, T2, T4, T6 absent, the coil radius derived from
#: T7 (identify refuses it: the steps never settle). The paper model's refit carried the derived radius and so ran
#: to tight tolerances: 61 of the 75 CPU-s budget, cut short after 33 iterations, every candidate left at its start,
#: "unexplained" (the previous main too). The refit now goes on to tight tolerances only when it fits to within 4
#: per residual (run.TIGHT_MAX_CHI2_PER_RESIDUAL): refit 28 CPU-s, "coil_heating + unexplained remainder"
HEATING_2TAU_TIGHT_REFIT_7457HZ = RigDescription(
    rates_hz=(7457.0, 7457.0, 7457.0, 7457.0, 7457.0, 7457.0), sweep_rate_hz=7457.0, manifest_period=True,
    step_phase=0.597, clock_start_s=0.0, pre_trigger_s=0.328, record_s=4.81, t6_periods=2, t6_frequency_hz=1.96,
    sweep_gaps_mm=(24.5, 22.5, 18.5, 17.5, 17.0, 15.0, 14.5, 14.0, 12.5, 8.5, 7.0, 4.5, 2.0, 1.5, 0.0),
    sweep_hold_s=1.04, sweep_average_s=0.106, noise=(0.35, 0.64, 0.48), samples=((21, 70), (31, 75), (19, 30),
    (27, 25)), coil_radius_mm=23.84, field_per_amp_T_per_A=0.178, manifest_coil=False, step_gap_offset_mm=2.16,
    t6_gap_offset_mm=1.79, t8_gap_mm=4.08, absent=('T2', 'T4', 'T6'), effect=('coil_heating_2tau', 1.3),
    seed=26412)


#: deep profile, session 20 (3d6ce40, MPC_DEEP_SCALE=0.15, unshrunk): a tanh saturation (2.12) at mixed rates
#: (9988, 210, 100, 491, 1031, 1095 Hz), four samples. Named filler_saturation (+ a discovered F_creep), but its
#: diagnosis took 122.9 CPU-s with one worker, over the 120 s target (open). The CPU time is measured by
#: benchmarks/bench_diagnose_datasets.py ("mixed-rates-tanh"), never asserted; here the cause it must name
SATURATION_TANH_MIXED_RATES = RigDescription(
    rates_hz=(9988.0, 210.0, 100.0, 491.0, 1031.0, 1095.0), sweep_rate_hz=210.0, manifest_period=True,
    step_phase=0.861, clock_start_s=92.735, pre_trigger_s=0.219, record_s=2.96, t6_periods=2,
    t6_frequency_hz=1.83, sweep_gaps_mm=(23.5, 5.5, 13.0, 11.0, 15.0, 24.5, 0.5, 17.0, 18.0, 21.0, 9.5),
    sweep_hold_s=0.74, sweep_average_s=0.249, noise=(1.0, 0.24, 1.0), samples=((34, 40), (16, 35), (21, 60), (29,
    55)), coil_radius_mm=10.0, field_per_amp_T_per_A=0.2, manifest_coil=True, step_gap_offset_mm=3.98,
    t6_gap_offset_mm=3.91, t8_gap_mm=3.14, absent=(), effect=('saturation_tanh', 2.12), seed=65536)


DEEP_REGRESSIONS = {
    "clean-t4-18khz-heldout-quantized-laser": ("verdict_none", T4_18KHZ_HELDOUT_QUANTIZED_LASER),
    "clean-t8-instant-early-628hz": ("verdict_none", T8_INSTANT_EARLY_628HZ),
    "effect-heating-named-from-the-cold-resistance": ("effect_named", HEATING_FROM_HOT_R_6942HZ),
    "bound-of-a-sample-with-k1-undetermined": ("within_bounds", K1_UNDETERMINED_BOUND_SCALE_262HZ),
    "bound-of-a-step-settling-late-in-a-short-record": ("within_bounds", SLOW_SETTLING_SHORT_RECORD_13689HZ),
    "effect-creep-at-100hz-with-a-fast-discovery-lag": ("effect_named", CREEP_FAST_LAG_100HZ),
    "bound-where-the-residuals-fall-toward-zero-mass": ("within_bounds", CM_VALLEY_TOWARD_ZERO_MASS_20MM),
    "bound-of-a-t3-step-within-the-noise": ("within_bounds", T3_STEP_WITHIN_NOISE_143HZ),
    "effect-tanh-saturation-at-1539hz-in-a-dear-batch": ("effect_named", SATURATION_TANH_1539HZ),
    "effect-heating-2tau-at-7457hz-beside-a-misfit-refit": ("effect_named", HEATING_2TAU_TIGHT_REFIT_7457HZ),
    "effect-tanh-saturation-at-mixed-rates-over-120-cpu-s": ("effect_named", SATURATION_TANH_MIXED_RATES),
}


@pytest.mark.deep
@pytest.mark.parametrize("name", sorted(DEEP_REGRESSIONS))
def test_deep_shrunk_failure(name):
    """Each slow description a deep run once failed on, against the invariant it broke."""
    invariant, desc = DEEP_REGRESSIONS[name]
    {**CLEAN_INVARIANTS, "effect_named": invariant_effect_named}[invariant](desc)


#: deep profile, session 14 (fbec260, MPC_DEEP_SCALE=0.3, unshrunk): clean, 530 Hz, laser noise 5x. W5-D20 (5 wt %,
#: 20 mm) barely moves: its T3/T5 residuals hardly change with m, and identify's least-squares C, m search walked
#: toward m -> 0 (natural frequency 330 Hz and up), where every simulation is stiff and slow; identify was still
#: running after an hour. The profile now searches the identification's box widened 4x (f_n 0.25-400 Hz here) and
#: ends at its edge with the reason (identify 9 s; W5-D20 falls back to the Eq. 6 model, the others unchanged)
CM_UNDETERMINED_530HZ = RigDescription(
    rates_hz=(530.0,) * 6, sweep_rate_hz=530.0, manifest_period=True, step_phase=0.317, clock_start_s=0.0,
    pre_trigger_s=0.5, record_s=4.67, t6_periods=1, t6_frequency_hz=0.78,
    sweep_gaps_mm=(0.5, 2.0, 3.5, 5.0, 6.5, 8.0, 9.5, 11.0), sweep_hold_s=0.73, sweep_average_s=0.388,
    noise=(5.0, 0.25, 0.3), samples=((16, 70), (5, 20), (34, 25)), coil_radius_mm=20.83, field_per_amp_T_per_A=0.402,
    manifest_coil=True, step_gap_offset_mm=4.19, t6_gap_offset_mm=4.21, t8_gap_mm=1.41, absent=(), effect=None,
    seed=65536)


def test_shrunk_failure_cm_not_determined_ends_at_the_search_box():
    """The session-14 hang: identify ends, W5-D20's least-squares C and m are refused with the reason (the search
    box's edge, with its natural frequencies), the determined samples keep theirs (within their noise bounds)."""
    a = analyse(CM_UNDETERMINED_530HZ, diagnose=False)
    assert "identify" not in a.errors, _describe(a)
    ls = a.identified["W5-D20"].least_squares
    assert "error" in ls and "search box" in ls["error"] and "Hz" in ls["error"], ls
    assert a.identified["W5-D20"].paper_choice.get("fallback"), "the Eq. 6 model must be the fallback, said so"
    for sid in ("W16-D70", "W34-D25"):
        assert "error" not in a.identified[sid].least_squares, (sid, a.identified[sid].least_squares)
