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
