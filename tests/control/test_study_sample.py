"""`control` on any identified sample and any extended model (issue 21): the sample's own parameters for the paper
model, the plant and the extended model; setpoints beyond a plant's holdable range clipped and reported (one
warning), never an exception; bad input one line naming the option, file and sample.

The clipped setpoint is checked against the independent static inverse of tests/fmu/test_statics.py (brentq on
V = R*sqrt(K/(Em*G - ksat*kB^2*K)) = V_max with the kernel of tests/independent/physics.py)."""
from __future__ import annotations

import json
import math
import sys
import warnings
from pathlib import Path

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from fmu_src.specs import EFFECTS, Params
from harness import cli, jobs, jobs_control
from harness.control.mpc import MpcSettings
from harness.control.study import StudySettings, TargetClippedWarning, plan_study
from harness.data import rig
from harness.data.paramsjson import params_to_json

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "independent"))
from physics import kernel_G  # noqa: E402  (independent: imports nothing of the project)

V_MAX = 30.0
_COMMON = dict(deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])


def v_hold_indep(p, x, ksat):
    K = (p.K1 * x * x + p.K2) * x
    return p.R * math.sqrt(K / (p.Em * kernel_G(p.r0 - x, p.a, p.D, p.kB) - ksat * p.kB ** 2 * K))


def write_params(path, samples: dict) -> Path:
    path.write_text(json.dumps({"samples": {sid: {"parameters": params_to_json(p)} for sid, p in samples.items()}}))
    return path


W10, W30 = rig.true_params(10, 45), rig.true_params(30, 60)


def settings_for(**kw):
    return StudySettings(actuator_fmu="", controller_fmu="", **kw)


# ------------------------------------------------------------------ the sample's own parameters
def test_an_identified_sample_is_the_paper_model_and_the_plant_gets_the_hidden_effect(tmp_path):
    f = write_params(tmp_path / "identification.json", {"W10-D45": W10, "W30-D60": W30})
    s = jobs_control.control_settings(settings_for(), params_file=f, sample="W30-D60")
    assert s.base == W30 and s.sample_effects is None and s.effect == "filler_saturation"
    assert s.plant_with_effect() == W30.with_(ksat=3.0) == s.extended_model()   # rig magnitude 1, perfect diagnosis
    assert "W30-D60" in s.sample


def test_a_diagnosed_sample_is_the_plant_and_the_extended_model_with_its_own_effects(tmp_path):
    diagnosed = W10.with_(ksat=5.53, lam=0.54)
    f = write_params(tmp_path / "extended_params.json", {"W10-D45": diagnosed, "W30-D60": W30})
    s = jobs_control.control_settings(settings_for(), params_file=f, sample="W10-D45")
    assert s.base == W10                                           # the paper model: the same sample, no effects
    assert s.plant_with_effect() == diagnosed == s.extended_model()
    assert s.plant_name == "filler_saturation+motional_emf" and s.effect is None
    with pytest.raises(jobs.PipelineError, match=r"--effect filler_saturation: sample W10-D45 of --params .*"
                                                 r"has effects of its own \(filler_saturation, motional_emf\)"):
        jobs_control.control_settings(settings_for(), params_file=f, sample="W10-D45", effect_asked=True)


def test_extended_params_alone_is_that_samples_model_not_the_default_samples(tmp_path):
    """The bug of issue 21: --extended-params put the diagnosis's effects on the default sample."""
    diagnosed = W30.with_(ksat=2.6)
    f = write_params(tmp_path / "extended_params.json", {"W30-D60": diagnosed})
    s = jobs_control.control_settings(settings_for(), extended_file=f)
    assert s.base == W30 and s.extended_model() == diagnosed
    assert s.plant_with_effect() == W30.with_(ksat=3.0)          # the hidden effect's truth on the same sample


# ------------------------------------------------------------------ clipping
def test_setpoints_beyond_the_plants_range_are_clipped_once_and_reported():
    p = Params()
    s = settings_for(effect=None, sample_effects={"ksat": 10.0}, stroke_m=1.5e-3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plan = plan_study(s)
    clip = [w for w in caught if issubclass(w.category, TargetClippedWarning)]
    assert len(clip) == 1
    x_v = brentq(lambda x: v_hold_indep(p, x, 10.0) - V_MAX, 1e-5, 1.7e-3, xtol=1e-13)  # hand-solved end of range
    name = "filler_saturation"
    assert plan.profiles[(name, "stroke")].stroke_m == pytest.approx(x_v, rel=1e-6)
    assert max(plan.profiles[(name, "staircase")].levels_m) == pytest.approx(x_v, rel=1e-6)
    assert plan.profiles[("clean", "stroke")].stroke_m == 1.5e-3                # the clean plant holds it
    assert len(plan.clipped) == 2 and all(n.startswith("filler_saturation plant") for n in plan.clipped)
    assert f"clipped to {1e3 * x_v:.3g} mm" in plan.clipped[0] and "voltage limit" in plan.clipped[0]
    assert str(clip[0].message) == "; ".join(plan.clipped)


def test_the_default_study_clips_nothing():
    with warnings.catch_warnings():
        warnings.simplefilter("error", TargetClippedWarning)
        plan = plan_study(settings_for())
    assert plan.clipped == []


@st.composite
def sample_files(draw):
    w, d = draw(st.sampled_from(rig.ALL_SAMPLES))
    base = rig.true_params(w, d)
    kw = {}
    for n in draw(st.lists(st.sampled_from(sorted(EFFECTS)), min_size=1, max_size=2, unique=True)):
        kw.update(rig.effect_params(n, draw(st.floats(0.1, 30.0)), base))
    return base.with_(**kw).validated()


def check_plan(p):
    s = settings_for(effect=None, sample_effects={k: getattr(p, k) for e in EFFECTS.values() for k in e.params},
                     base=p.with_(**{k: 0.0 for e in EFFECTS.values() for k in e.params}),
                     mpc=MpcSettings(V_max_V=V_MAX))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plan = plan_study(s)
    assert len([w for w in caught if issubclass(w.category, TargetClippedWarning)]) == (1 if plan.clipped else 0)
    for (plant, _prof), prof in plan.profiles.items():
        top = prof.stroke_m if prof.kind == "trapezoid" else max(prof.levels_m)
        assert 0.0 <= top <= plan.ranges[plant][0]


@settings(max_examples=4, derandomize=True, **_COMMON)
@given(p=sample_files())
@example(p=Params(ksat=10.0))
def test_any_diagnosed_sample_plans_without_an_exception(p):
    check_plan(p)


@pytest.mark.deep
@settings(max_examples=150, **_COMMON)
@given(p=sample_files())
def test_deep_any_diagnosed_sample_plans_without_an_exception(p):
    check_plan(p)


# ------------------------------------------------------------------ the command line
@pytest.fixture
def two_samples(tmp_path):
    return write_params(tmp_path / "identification.json", {"W10-D45": W10, "W30-D60": W30})


@pytest.mark.parametrize("args, msg", [
    (["--params", "{f}", "--sample", "W99-D45"],
     r"^error: --sample: sample W99-D45 is not in --params .*identification.json \(it holds W10-D45, W30-D60\)$"),
    (["--params", "{f}"], r"^error: --sample: --params .*identification.json holds 2 samples \(W10-D45, W30-D60\); "
                          r"choose one with --sample$"),
    (["--params", "{missing}", "--sample", "W10-D45"], r"^error: --params .*missing.json: cannot read: "),
    (["--extended-params", "{missing}", "--sample", "W10-D45"], r"^error: --extended-params .*missing.json: cannot "),
    (["--extended-params", "{f}", "--sample", "W20-D30"], r"^error: --sample: sample W20-D30 is not in "
                                                          r"--extended-params .*identification.json"),
    (["--sample", "W10-D45"], r"^error: --sample W10-D45: give the parameter file that holds it with --params$"),
])
def test_bad_sample_input_is_one_line(tmp_path, two_samples, args, msg):
    args = [a.format(f=two_samples, missing=tmp_path / "missing.json") for a in args]
    with pytest.raises(SystemExit, match=msg) as e:
        cli.main(["control", "--out", str(tmp_path / "out"), *args])
    assert "\n" not in str(e.value.code)
    assert not (tmp_path / "out").exists()


def test_an_effect_on_a_diagnosed_sample_is_one_line(tmp_path):
    f = write_params(tmp_path / "extended_params.json", {"W10-D45": W10.with_(ksat=5.53)})
    with pytest.raises(SystemExit, match=r"^error: --effect coil_heating: sample W10-D45 of --params .* has "
                                         r"effects of its own \(filler_saturation\)") as e:
        cli.main(["control", "--out", str(tmp_path / "out"), "--params", str(f),
                  "--effect", "coil_heating"])
    assert "\n" not in str(e.value.code) and not (tmp_path / "out").exists()


def test_paper_model_apart_from_the_plant():
    """``paper_model``: the paper controllers are built on it (e.g. a diagnosis's refit), the plants keep ``base``."""
    from fmu_src.specs import Params
    from harness.control.study import StudySettings, plan_study
    base = Params()
    refit = base.with_(K2=base.K2 * 1.05, Em=base.Em * 0.97)
    s = StudySettings(actuator_fmu="a.fmu", controller_fmu="c.fmu", base=base, effect="filler_saturation",
                      paper_model=refit)
    cases = plan_study(s).cases
    assert [(c[0], c[2]) for c in cases] == [("clean", "paper"), ("filler_saturation", "paper"),
                                             ("filler_saturation", "extended")]
    assert cases[0][1] == base.validated() and cases[0][3] == refit and cases[1][3] == refit
    assert cases[1][1].ksat > 0 and cases[2][3].ksat > 0          # the effect plant and the perfect extended model
    assert plan_study(StudySettings(actuator_fmu="a", controller_fmu="c", base=base, effect=None)).cases[0][3] == base
