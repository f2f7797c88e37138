"""Discovery beyond the catalogue (issue 22) on data of the independent generator (its own physics, never the
project's simulator): effects outside the catalogue must be found as terms of the right kind and halve the
held-out RMSE; clean data must stay ``none``.

Default suite (seconds): a reduced member (three 45 mm samples, 400 Hz, 2.4 s records) whose laser reading
carries a nonlinearity planted here (x_reading = x + k x^2, x in m; the generator's data post-processed, so the
planted law is written independently of ``fmu_src.terms``), the same member clean, and the extended FMU. The members with the generator's own hidden effects outside the catalogue
(several kinds) and the 20 clean rigs are in the slow profile (``pytest -m slow tests/independent/test_discovery.py``).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from harness.analysis import diagnosis as dg
from tests.independent.bounds import blind


def planted_reading(ds, k_x_per_m: float = 0.0, k_F_per_N: float = 0.0):
    """The dataset with the readings bent: displacement x_mm -> x_mm + k_x (x_mm/1000)^2 1000; force F -> F + k_F F^2."""
    samples = []
    for s in ds.samples:
        tests = {}
        for n, t in s.tests.items():
            kw = {}
            if t.displacement_mm is not None and k_x_per_m:
                x = np.asarray(t.displacement_mm, dtype=float)
                kw["displacement_mm"] = x + k_x_per_m * (x / 1000.0) ** 2 * 1000.0
            if t.force_N is not None and k_F_per_N:
                F = np.asarray(t.force_N, dtype=float)
                kw["force_N"] = F + k_F_per_N * F ** 2
            tests[n] = dataclasses.replace(t, **kw) if kw else t
        samples.append(dataclasses.replace(s, tests=tests))
    return dataclasses.replace(ds, samples=samples)


def describe(diag) -> str:
    ov = diag.gain["overall_normalized_rmse"]
    disc = diag.discovery or {}
    rounds = [{n: (c["accepted"], c["delta_bic"], c["delta_chi2_heldout"]) for n, c in r["candidates"].items()}
              for r in disc.get("rounds", [])]
    return (f"verdict {diag.verdict!r}; held-out RMSE / noise floor {ov}; terms "
            f"{[t.summary() for t in diag.discovered]}; remainder {diag.remainder.get('where')}; rounds {rounds}")


def check_discovered(diag, kind: str, equation: str | None = None):
    """A term of ``kind`` (and ``equation``) discovered, and the held-out RMSE at least halved where the paper
    model's is at least three noise floors."""
    msg = describe(diag)
    assert diag.discovered, msg
    assert diag.discovered[0].kind == kind, msg
    if equation is not None:
        assert equation in diag.discovered[0].equation, msg
    ov = diag.gain["overall_normalized_rmse"]
    if ov["before"] >= 3.0:
        assert ov["after"] <= 0.5 * ov["before"], msg


def test_planted_displacement_sensor_nonlinearity_is_a_reading_term(member):
    ds = planted_reading(blind(member("fast-clean-400Hz-single")), k_x_per_m=8.0)
    diag = dg.diagnose(ds, dg.DiagnoseSettings(workers=1))
    check_discovered(diag, "reading", "x_reading")
    t = diag.discovered[0]
    assert t.name in ("x_quadratic", "x_cubic"), describe(diag)


def test_clean_member_discovers_nothing(member):
    diag = dg.diagnose(blind(member("fast-clean-400Hz-single")), dg.DiagnoseSettings(workers=1))
    assert diag.verdict == "none" and diag.discovered == [] and diag.discovery == {}, describe(diag)


# ----------------------------------------------------------------------------- the extended FMU
FMU_RTOL = 1e-7          # the FMU's default rtol parameter (tests/fmu/test_fmu.py)


def fmu_reproduces(diag, ds, out_dir, fmu_path, max_samples: int | None = None) -> list:
    """Run the extended FMU (fmpy, parameters read back from the diagnosis's extended_params.json) on every
    held-out step test of every sample and compare it with (1) the diagnosis's extended model simulated by the
    project's reference integrator (``fmu_src.model.simulate``, the FMU's rtol) on the same grid: relative error
    (max |difference| / max |signal|) per test and signal, and (2) the diagnosis's own held-out traces (the
    vectorized simulator read at the measured samples), in noise floors. Returns rows (sample, test, signal,
    relative error vs the reference, error vs the trace in noise floors)."""
    import json

    from fmu_src.model import simulate as model_simulate
    from harness.analysis.diagnosis.jobs import lagrange_at, sim_period
    from harness.analysis.diagnosis.prepare import prepare
    from harness.data.rig import params_from_json
    from harness.report.diagnosis_md import write_diagnosis
    from harness.sim import fmurun

    write_diagnosis(diag, out_dir, max_figures=0)
    ext = json.loads((out_dir / "extended_params.json").read_text())
    prep = prepare(ds, diag.settings)
    rows = []
    for sd in prep.samples[:max_samples]:
        p = params_from_json(ext["samples"][sd.sid]["parameters"]).validated()
        for t in diag.discovered:                 # the discovered coefficients made it into the file
            assert getattr(p, t.coefficient_name) == pytest.approx(t.coefficient[sd.sid][0], rel=1e-12)
        for name in diag.settings.heldout_tests:
            test = sd.tests.get(name)
            if test is None or not hasattr(test, "k_on") or test.V_on is None:
                continue
            h = sim_period(test.dt, diag.settings.max_rate_hz)
            n_loc = test.t.size - test.k_on
            T = (n_loc - 1) * test.dt + test.step_delay_s
            grid = np.arange(int(np.ceil(T / h - 1e-9)) + 4) * h
            q = p.with_(r0=test.r0, blocked=test.blocked)
            fmu = fmurun.run(q, grid, test.V_on, fmu_path=fmu_path, outputs=("I", "x_sensor", "F_sensor"))
            fmu_sv = dict(fmurun.start_values(q))
            assert all(fmu_sv.get(t.coefficient_name) == getattr(q, t.coefficient_name) for t in diag.discovered)
            ref = model_simulate(q, grid, test.V_on, rtol=FMU_RTOL)
            ych = "F_sensor" if test.blocked else "x_sensor"
            tr = diag.traces[sd.sid]["after"][name]
            tl = np.arange(n_loc) * test.dt + test.step_delay_s
            for sig, key, meas_sig in (("reading", ych, test.sig_y), ("current", "I", test.sig_I)):
                a, b = np.asarray(fmu[key], float), np.asarray(ref[key], float)
                rel = float(np.max(np.abs(a - b)) / np.max(np.abs(b)))
                at = lagrange_at(grid, a, tl)
                want = (tr.y_sim if sig == "reading" else tr.I_sim)[test.k_on:]
                rows.append((sd.sid, name, sig, rel, float(np.max(np.abs(at - want)) / meas_sig)))
    return rows


def test_extended_fmu_reproduces_the_diagnosis_with_a_discovered_term(member, fmu_path, tmp_path):
    """Done criterion: the FMU built from this tree, with the discovered term's parameters from
    extended_params.json, reproduces the diagnosis's extended model (the project's integrator at the FMU's rtol)
    to 1e-6 relative on the held-out tests, and the diagnosis's held-out traces (its vectorized simulator) within
    0.05 noise floors (that simulator's accuracy bound, tests/sim/test_simulator.py)."""
    ds = planted_reading(blind(member("fast-clean-400Hz-single")), k_x_per_m=8.0)
    diag = dg.diagnose(ds, dg.DiagnoseSettings(workers=1))
    assert diag.discovered, describe(diag)
    rows = fmu_reproduces(diag, ds, tmp_path / "diag", fmu_path, max_samples=1)
    assert {r[1] for r in rows} >= {"T2", "T4"}, rows
    bad = [r for r in rows if not (r[3] <= 1e-6 and r[4] <= 0.05)]
    assert not bad, bad


# ----------------------------------------------------------------------------- no false discoveries (slow)
N_CLEAN_RIGS = 20
#: [CPU-s] fit budget of the slow diagnoses: a fit cut short by the default budget (75 CPU-s) is no verdict on the
#: method; these tests measure the method (the default budget's own tests: tests/analysis/diagnosis/test_budget.py)
SLOW_BUDGET_S = 3600.0


@pytest.mark.slow
def test_clean_rigs_give_none(tmp_path):
    """Done criterion: over 20 clean datasets of varied rigs (the space of ``tests.independent.space``: rates up to
    1 kHz, any noise 0.2-5x, 3 samples of any wt% and diameter, any coil, T2/T4/T6 possibly absent, 1.5-3 s records;
    drawn reproducibly), the verdict is ``none`` in at least 19."""
    from hypothesis import HealthCheck, Phase, given, settings

    from harness.data.dataset import read_dataset
    from tests.independent.space import make_from_description, rig_descriptions

    got = []

    @settings(max_examples=N_CLEAN_RIGS, derandomize=True, database=None, phases=[Phase.generate], deadline=None,
              suppress_health_check=list(HealthCheck))
    @given(rig_descriptions(max_rate_hz=1000.0, max_samples=3, max_record_s=3.0, complete=True, effect=False))
    def run(d):
        out = tmp_path / f"rig{len(got)}"
        ds = blind(read_dataset(make_from_description(out, d)))
        diag = dg.diagnose(ds, dg.DiagnoseSettings(workers=1, fit_budget_s=SLOW_BUDGET_S))
        got.append((d, diag.verdict, [t.name for t in diag.discovered], describe(diag)))
        print(f"clean rig {len(got) - 1}: {diag.verdict!r} ({describe(diag)}; {d!r})", flush=True)   # with -s

    run()
    assert len(got) == N_CLEAN_RIGS
    none = sum(v == "none" for _, v, _, _ in got)
    msg = "\n".join(f"{v}: {d!r}\n   {why}" for d, v, _, why in got if v != "none")
    assert none >= N_CLEAN_RIGS - 1, msg


# ----------------------------------------------------------------------------- hidden effects outside the catalogue (slow)
#: the reduced rig of the slow members: three 45 mm samples at 500 Hz, 2.4 s records (the space's defaults)
def outside_rig(form: str, magnitude: float = 1.0):
    from tests.independent.space import RigDescription
    return RigDescription(rates_hz=(500.0,) * 6, sweep_rate_hz=500.0, effect=(form, magnitude))


def _outside_forms():
    from tests.independent.generator import OUTSIDE_FORMS
    return sorted(OUTSIDE_FORMS)


def test_the_outside_forms_span_the_kinds():
    """The data of the done criterion: at least five hidden forms of at least three physical kinds, each a kind
    the term library has terms of."""
    from fmu_src.terms import TERMS
    from tests.independent.generator import OUTSIDE_KIND
    assert len(OUTSIDE_KIND) >= 5 and len(set(OUTSIDE_KIND.values())) >= 3
    assert set(OUTSIDE_KIND.values()) <= {t.kind for t in TERMS.values()}


@pytest.mark.slow
@pytest.mark.parametrize("form", _outside_forms())
def test_outside_effect_is_discovered_with_its_kind(form, tmp_path):
    """Done criterion: with the independent generator's hidden effect outside the catalogue, a discovered term of
    the hidden effect's physical kind, and the held-out RMSE at least halved where the paper model's is at least
    three noise floors."""
    from harness.data.dataset import read_dataset
    from tests.independent.generator import OUTSIDE_KIND
    from tests.independent.space import make_from_description
    ds = blind(read_dataset(make_from_description(tmp_path / form, outside_rig(form))))
    diag = dg.diagnose(ds, dg.DiagnoseSettings(workers=2, fit_budget_s=SLOW_BUDGET_S))
    assert not [c for c in diag.fits_cut_short if c["stop"] == "time_budget"], describe(diag)
    check_discovered(diag, OUTSIDE_KIND[form])


# ----------------------------------------------------------------------------- RMSE halving, per test and signal (slow)
#: criterion (a) of issue 22, measured per held-out test and signal: the hidden forms outside the catalogue and the
#: magnitudes (of ``tests.independent.generator``) at which the paper model misses by at least three noise floors in
#: some held-out test and signal, with what the magnitude means physically (docs/discovery.md has the measured table)
HALVING_CASES = {
    "clamp_friction": (1.0, "Dahl friction in the clamping: sliding force Fc = 3 mN, presliding length 10 um"),
    "silicone_heating": (1.0, "silicone stiffness -0.4 %/K, warmed through 6 K/W by the coil's loss (tau 2 s, 1 s)"),
    "fluid_drag": (1.5, "a pumped liquid: orifice drag 30 C/(1 m/s) * v|v| (the viscous damping at 33 mm/s) and an "
                        "added mass 0.45 m"),
    "dome_prestress": (3.0, "a pre-stressed dome: the quadratic spring term is 45 % of the linear one at D/20"),
    "eddy_currents": (2.0, "a solid iron core: shorted secondary with coupling k^2 = 0.8, Le/Re = 20 ms"),
    "loadcell_creep": (4.0, "a polymer (piezoresistive) force sensor: creep 12 % with 0.3 s and 8 % with 3 s"),
}
#: the paper model misses a held-out test and signal when its RMSE is at least this many noise floors
MISS_FLOORS = 3.0


def missed_signals(gain: dict, floors: float = MISS_FLOORS) -> list:
    """Where the paper model misses: rows (test, signal, paper RMSE, extended RMSE), both in noise floors, of every
    held-out test and signal (reading: displacement or blocked force; current) whose paper-model RMSE (pooled RMS
    over the samples of RMSE / noise floor: ``gain["per_test"]``) is at least ``floors``."""
    rows = []
    for test, entry in gain["per_test"].items():
        for key, v in entry.items():
            if key.endswith("_rmse_per_noise_floor") and v.get("before") is not None and v["before"] >= floors:
                rows.append((test, key[: -len("_rmse_per_noise_floor")], v["before"], v["after"]))
    return rows


def test_halving_cases_span_five_forms_of_three_kinds():
    from tests.independent.generator import OUTSIDE_KIND
    assert len(HALVING_CASES) >= 5 and len({OUTSIDE_KIND[f] for f in HALVING_CASES}) >= 3


def test_missed_signals_by_hand():
    """The definition on a hand-made gain block: only (test, signal) pairs with the paper model at >= 3 floors."""
    gain = {"per_test": {"T2": {"displacement_rmse_per_noise_floor": {"before": 8.0, "after": 1.1},
                                "current_rmse_per_noise_floor": {"before": 1.0, "after": 1.0},
                                "displacement_rmse_mm": {"before": 80.0, "after": 1.0}},
                         "T7": {"blocked_force_rmse_per_noise_floor": {"before": 3.0, "after": 2.0}}}}
    assert missed_signals(gain) == [("T2", "displacement", 8.0, 1.1), ("T7", "blocked_force", 3.0, 2.0)]


@pytest.mark.slow
@pytest.mark.parametrize("form", sorted(HALVING_CASES))
def test_discovery_halves_the_heldout_rmse_where_the_paper_model_misses(form, tmp_path):
    """Done criterion (a), per test and signal: at a magnitude where the paper model misses by at least three noise
    floors, the first discovered term is of the hidden effect's kind and every held-out test and signal the paper
    model misses has its RMSE at least halved by the extended model."""
    from harness.data.dataset import read_dataset
    from tests.independent.generator import OUTSIDE_KIND
    from tests.independent.space import make_from_description
    mag, _ = HALVING_CASES[form]
    ds = blind(read_dataset(make_from_description(tmp_path / form, outside_rig(form, mag))))
    diag = dg.diagnose(ds, dg.DiagnoseSettings(workers=2, fit_budget_s=SLOW_BUDGET_S))
    assert not [c for c in diag.fits_cut_short if c["stop"] == "time_budget"], describe(diag)
    missed = missed_signals(diag.gain)
    assert missed, describe(diag)                      # the magnitude is one the paper model misses
    assert diag.discovered and diag.discovered[0].kind == OUTSIDE_KIND[form], describe(diag)
    bad = [r for r in missed if not r[3] <= 0.5 * r[2]]
    assert not bad, (bad, describe(diag))
