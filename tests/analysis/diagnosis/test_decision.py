"""Decision rule of the diagnosis (harness.analysis.diagnosis.decision) on hand-made chi-square tables."""
from __future__ import annotations

import pytest

from harness.analysis.diagnosis import DiagnoseSettings
from harness.analysis.diagnosis.candidates import shared_defs
from harness.analysis.diagnosis.decision import compare
from harness.analysis.diagnosis.fitting import ModelFit


def test_decision_rule():
    """Accepted only with BIC support on the fit data AND a held-out improvement."""
    st = DiagnoseSettings()

    def mf(effects, fit, held):
        return ModelFit(effects=effects, shared={d.key: 0.0 for d in shared_defs(effects)}, base={},
                        params={}, fit_chi2={0: {("T5", "y"): (fit, 1000)}},
                        heldout={0: {("T2", "y"): (held, 1000)}})

    ref = mf((), 5000.0, 5000.0)
    n = 10000
    ok = compare(ref, mf(("sensor_lag",), 1000.0, 1100.0), st, n, "sensor_lag")
    assert ok.accepted and ok.d_bic < -st.bic_min and ok.d_heldout > st.heldout_min
    overfit = compare(ref, mf(("sensor_lag",), 1000.0, 5000.0), st, n, "sensor_lag")
    assert not overfit.accepted and "held-out" in overfit.reason
    small = compare(ref, mf(("coil_heating",), 4985.0, 4000.0), st, n, "coil_heating")   # 15 < 2 ln n + 10
    assert not small.accepted and "BIC" in small.reason
    with pytest.raises(ValueError, match="both fit and held-out"):
        DiagnoseSettings(heldout_tests=("T1", "T2"))
    with pytest.raises(ValueError, match="T3, T5, T8"):
        DiagnoseSettings(fit_tests=("T1", "T3", "T5"))


def test_verdict_none_unexplained_cause_and_remainder():
    """The verdict rule: none / unexplained / causes / causes + unexplained remainder, by the structure z."""
    from harness.analysis.diagnosis.decision import REMAINDER, verdict
    quiet = {("T5", "y"): 1.2, ("T5", "I"): -0.4, ("T1", "y"): -9.0}
    loud = {("T5", "y"): 40.0, ("T5", "I"): 7.5, ("T1", "y"): 2.0}
    v = verdict([], quiet, quiet, 5.0)
    assert (v.cause, v.label, v.remainder, v.has_remainder) == ("none", "none", (), False)
    v = verdict([], loud, loud, 5.0)
    assert (v.cause, v.label) == ("unexplained", "unexplained") and not v.has_remainder
    assert v.remainder == (("T5", "y", 40.0), ("T5", "I", 7.5))            # largest first, only z > 5
    v = verdict(["coil_heating"], loud, quiet, 5.0)
    assert (v.cause, v.label, v.remainder) == ("coil_heating", "coil_heating", ())
    v = verdict(["coil_heating", "viscoelastic_creep"], loud, {("T5", "y"): 6.0, ("T3", "y"): 5.0}, 5.0)
    assert v.cause == "coil_heating" and v.has_remainder
    assert v.label == f"coil_heating + viscoelastic_creep + {REMAINDER}" and v.remainder == (("T5", "y", 6.0),)
    assert "6" in v.reason and "T5 reading" in v.reason
    # the threshold is the setting's, not a constant
    assert verdict(["coil_heating"], loud, {("T5", "y"): 6.0}, 10.0).label == "coil_heating"


def test_verdict_with_discovered_terms():
    """Discovered terms join the verdict after the catalogue causes ("discovered:<term>"); cause "discovered" when
    only terms were accepted; the remainder rule is the same."""
    from harness.analysis.diagnosis.decision import REMAINDER, verdict
    quiet = {("T5", "y"): 1.2, ("T5", "I"): -0.4}
    loud = {("T5", "y"): 40.0, ("T5", "I"): 7.5}
    v = verdict([], loud, quiet, 5.0, terms=["quad_drag"])
    assert (v.cause, v.label, v.causes, v.terms, v.remainder) == ("discovered", "discovered:quad_drag", (),
                                                                  ("quad_drag",), ())
    v = verdict(["coil_heating"], loud, loud, 5.0, terms=["quad_drag", "x_cubic"])
    assert v.cause == "coil_heating"
    assert v.label == f"coil_heating + discovered:quad_drag + discovered:x_cubic + {REMAINDER}"
    assert v.has_remainder and v.remainder[0][:2] == ("T5", "y")
    # without terms: the catalogue's verdicts unchanged
    assert verdict([], loud, loud, 5.0).label == "unexplained" and verdict([], loud, loud, 5.0).needs_discovery
    assert verdict([], quiet, quiet, 5.0).label == "none" and not verdict([], quiet, quiet, 5.0).needs_discovery
    assert verdict(["sensor_lag"], loud, loud, 5.0).needs_discovery


def test_a_candidate_the_budget_cut_is_reported_undecided_not_rejected():
    """budget_bound: a candidate the fit data supported (BIC lower by more than bic_min) but the held-out tests did
    not confirm is undecided when the time budget cut its fit; not when its fit converged (the data decided), not
    when the fit data did not support it, not when it was accepted. The verdict's label stays, its reason names
    the undecided candidates (deep profile, session 20: a 100-noise-floor coil heating at 7457 Hz said
    "unexplained" when its fit was cut after 2 iterations, and named coil_heating in a run with more of them)."""
    from harness.analysis.diagnosis.decision import Comparison, budget_bound, verdict, with_undecided
    st = DiagnoseSettings()
    cut = ({"fit": "joint fit", "stop": "time_budget", "iterations": 2},
           {"fit": "fit of sample S4", "stop": "time_budget", "iterations": 9})
    at_limit = ({"fit": "joint fit", "stop": "max_iter", "iterations": 20},)

    def comp(name, d_bic, accepted=False, cut_short=()):
        return Comparison(name=name, effects=(name,), k=1, d_fit=-d_bic, d_bic=d_bic, d_heldout=-4.3e4,
                          score=-1.0, accepted=accepted, reason="", cut_short=cut_short)

    comps = [comp("coil_heating", -3.5e5, cut_short=cut), comp("sensor_lag", -3.5e5, cut_short=at_limit),
             comp("filler_saturation", -5.0, cut_short=cut), comp("viscoelastic_creep", -2e3, accepted=True,
                                                                   cut_short=cut),
             comp("motional_emf", -st.bic_min, cut_short=cut), comp("eddy", float("nan"), cut_short=cut)]
    assert budget_bound(comps, st.bic_min) == (("coil_heating", 2),)
    loud = {("T5", "y"): 40.0}
    v = with_undecided(verdict([], loud, loud, st.z_struct), budget_bound(comps, st.bic_min))
    assert (v.label, v.undecided) == ("unexplained", (("coil_heating", 2),))
    assert "not decided within the fit budget" in v.reason and "coil_heating (cut after 2 iterations)" in v.reason
    plain = verdict([], loud, loud, st.z_struct)
    assert with_undecided(plain, ()) is plain


class _RunoffCtx:
    """A stand-in FitContext for decision.runoff: records the specs and the deadline of the fit it is asked for,
    and returns a prepared fit."""

    def __init__(self, settings, result, now_s=100.0, deadline_s=90.0):
        self.settings, self.result, self.now_s, self.deadline_s = settings, result, now_s, deadline_s
        self.calls = []

    def fit_many(self, specs):
        self.calls.append((list(specs), self.deadline_s))
        return [self.result]

    def evaluate(self, mfs):
        return list(mfs)


def _mf(effects, fit, held, cut_short=(), base=None, shared=None):
    return ModelFit(effects=effects, shared=shared if shared is not None else {d.key: 0.0 for d in shared_defs(effects)},
                    base=base or {}, params={}, fit_chi2={0: {("T5", "y"): (fit, 1000)}},
                    heldout={0: {("T2", "y"): (held, 1000)}}, cut_short=cut_short)


@pytest.mark.parametrize("held_after, accepted", [(1100.0, True), (9000.0, False)])
def test_the_runoff_goes_on_with_the_best_supported_cut_candidate_alone(monkeypatch, held_after, accepted):
    """runoff: nothing accepted and the budget cut candidates the fit data supported -> the one with the largest
    BIC support is fitted on alone (from where it was cut, with runoff_budget_s more CPU time; the round's deadline
    is restored after) and judged again; it is accepted only if the held-out tests now confirm it, and it is
    undecided afterwards only if the runoff was cut too."""
    from harness.analysis.core import cpu_clock
    from harness.analysis.diagnosis.decision import budget_bound, compare, runoff
    monkeypatch.setattr(cpu_clock, "now", lambda: 100.0)
    st = DiagnoseSettings()
    cut = ({"fit": "joint fit", "stop": "time_budget", "iterations": 2},)
    ref = _mf((), 5000.0, 5000.0)
    base = {0: [1.0, 2.0]}
    sh = {d.key: 0.3 for d in shared_defs(("coil_heating",))}              # where the budget cut its fit
    fits = [_mf(("coil_heating",), 1000.0, 9000.0, cut, base=base, shared=sh),
            _mf(("sensor_lag",), 3000.0, 9000.0, cut), _mf(("filler_saturation",), 4999.0, 4000.0, cut)]
    n = 10000
    comps = [compare(ref, f, st, n, f.effects[0]) for f in fits]
    assert [c.accepted for c in comps] == [False] * 3
    assert [u[0] for u in budget_bound(comps, st.bic_min)] == ["coil_heating", "sensor_lag"]
    after = _mf(("coil_heating",), 990.0, held_after)                      # converged: nothing cut
    ctx = _RunoffCtx(st, after)
    q = runoff(ctx, ref, comps, fits, n)
    (specs, deadline_s), = ctx.calls
    assert deadline_s == 100.0 + st.runoff_budget_s and ctx.deadline_s == 90.0
    assert specs[0].effects == ("coil_heating",) and specs[0].start_base is base
    assert specs[0].shared_init == sh
    assert (q == 0) is accepted and comps[0].accepted is accepted and fits[0] is after
    assert comps[0].reason.startswith("runoff") and "after 2 iteration(s)" in comps[0].reason
    assert [u[0] for u in budget_bound(comps, st.bic_min)] == ["sensor_lag"]


def test_no_runoff_without_budget_or_without_a_cut_supported_candidate(monkeypatch):
    from harness.analysis.core import cpu_clock
    from harness.analysis.diagnosis.decision import compare, runoff
    monkeypatch.setattr(cpu_clock, "now", lambda: 100.0)
    cut = ({"fit": "joint fit", "stop": "time_budget", "iterations": 2},)
    ref = _mf((), 5000.0, 5000.0)
    for st, fit in [(DiagnoseSettings(runoff_budget_s=0.0), _mf(("coil_heating",), 1000.0, 9000.0, cut)),
                    (DiagnoseSettings(), _mf(("coil_heating",), 1000.0, 9000.0)),            # converged: decided
                    (DiagnoseSettings(), _mf(("coil_heating",), 4999.0, 4000.0, cut))]:      # no BIC support
        comps, fits = [compare(ref, fit, st, 10000, "coil_heating")], [fit]
        ctx = _RunoffCtx(st, None)
        assert runoff(ctx, ref, comps, fits, 10000) is None and ctx.calls == [] and fits[0] is fit
    with pytest.raises(ValueError, match="runoff_budget_s"):
        DiagnoseSettings(runoff_budget_s=-1.0)
