"""harness.analysis.identification.selection: Eq. 6 and the residual check of its choice, by hand."""
import math

import numpy as np
import pytest

from harness.analysis.identification import selection


def test_residual_check_by_hand_from_residual_vectors():
    """Deviance of each front model from explicit residual vectors: SSE = sum of squares over T3 and T5,
    sigma^2 = SSE_min / (n - 2), deviance = (SSE - SSE_min) / sigma^2; 95 % limit chi2(2) = 5.99."""
    rng = np.random.default_rng(5)
    n3, n5 = 120, 80
    base3, base5 = rng.normal(0, 5e-6, n3), rng.normal(0, 5e-6, n5)          # residuals [m]
    models = [(base3, base5), (1.02 * base3, base5), (1.3 * base3, 1.1 * base5)]
    rms = lambda r: math.sqrt(np.mean(r ** 2)) * 1e3                         # noqa: E731  [mm]
    F = np.array([[0.0, rms(a), 0.0, rms(b)] for a, b in models])
    sse = np.array([np.sum(a ** 2) + np.sum(b ** 2) for a, b in models])
    s2 = sse[0] / (n3 + n5 - 2)
    for k in range(3):
        r = selection.residual_check(F, [n3, n5], k, [1.0, 2.0, 3.0], [0.1, 0.2, 0.3])
        assert r["chosen_deviance"] == pytest.approx((sse[k] - sse[0]) / s2, rel=1e-9)
        assert r["least_squares_front_model"] == {"index": 0, "C_N_s_per_m": 1.0, "m_kg": 0.1}
        assert r["chosen_consistent_with_residuals"] == ((sse[k] - sse[0]) / s2 <= 5.991464547107979)
    assert selection.residual_check(F, [n3, n5], 1, [1, 2, 3], [1, 2, 3])["chosen_consistent_with_residuals"]
    assert not selection.residual_check(F, [n3, n5], 2, [1, 2, 3], [1, 2, 3])["chosen_consistent_with_residuals"]
    assert selection.residual_check(F, [n3, n5], 0, [1, 2, 3], [1, 2, 3])["front_models_consistent"] == 2
