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
