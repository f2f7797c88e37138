"""Which further start a candidate is fitted from (``decision.best_extra_start``): the lowest chi-square of its
starts; for an effect of ``candidates.STARTS_ONLY_WHEN_BETTER`` only when that beats the refit itself. Test doubles
of the fit context and the refit: the chi-square of a start is a number set by hand per start."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from harness.analysis.diagnosis import decision
from harness.analysis.diagnosis.candidates import STARTS_ONLY_WHEN_BETTER


def _setup(monkeypatch, effect: str, chi2_of_starts: list, chi2_refit: float):
    starts = [({0: np.full(7, float(k))}, {"tag": k}) for k in range(len(chi2_of_starts))]
    monkeypatch.setattr(decision, "extra_starts", lambda e, samples, base, shared: starts if e == effect else [])
    monkeypatch.setattr(decision, "make_params", lambda sd, b, sh: sh["tag"])
    ctx = SimpleNamespace(samples=[None], clip_base=lambda i, b: b,
                          fit_chi2_of=lambda params: {0: {("T3", "y"): (chi2_of_starts[params[0]], 100)}})
    refit = SimpleNamespace(base={0: np.zeros(7)}, shared={}, chi2=lambda which="fit": chi2_refit)
    return ctx, refit


def test_heating_starts_are_fitted_only_when_they_beat_the_refit(monkeypatch):
    assert "coil_heating" in STARTS_ONLY_WHEN_BETTER
    ctx, refit = _setup(monkeypatch, "coil_heating", [120.0, 150.0], 100.0)
    assert decision.best_extra_start(ctx, "coil_heating", refit) == []
    ctx, refit = _setup(monkeypatch, "coil_heating", [120.0, 90.0], 100.0)
    got = decision.best_extra_start(ctx, "coil_heating", refit)
    assert len(got) == 1 and got[0][1]["tag"] == 1
    ctx, refit = _setup(monkeypatch, "coil_heating", [99.0], 100.0)          # a single start is gated too
    assert decision.best_extra_start(ctx, "coil_heating", refit)[0][1]["tag"] == 0
    ctx, refit = _setup(monkeypatch, "coil_heating", [101.0], 100.0)
    assert decision.best_extra_start(ctx, "coil_heating", refit) == []


@pytest.mark.parametrize("effect", ["edge_stiffening", "filler_saturation"])
def test_other_starts_are_fitted_from_the_best_even_when_worse_than_the_refit(monkeypatch, effect):
    """A re-solved spring or Em start may lie above the refit's chi-square and still lead to the effect's basin."""
    assert effect not in STARTS_ONLY_WHEN_BETTER
    ctx, refit = _setup(monkeypatch, effect, [300.0, 200.0, 250.0], 100.0)
    got = decision.best_extra_start(ctx, effect, refit)
    assert len(got) == 1 and got[0][1]["tag"] == 1
    assert decision.best_extra_start(ctx, "sensor_lag", refit) == []
