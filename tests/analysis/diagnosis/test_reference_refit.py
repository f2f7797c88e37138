"""The reference refit's tolerances (``harness.analysis.diagnosis.run.reference_refit``).

A refit that carries a nuisance parameter (a derived coil radius) goes on to tight tolerances only when the paper
model fits to within ``TIGHT_MAX_CHI2_PER_RESIDUAL`` per residual: a 100-noise-floor coil heating at 7457 Hz
(deep profile, session 20) spent its whole fit budget on a tight refit and left every candidate at its start.
The context is a stand-in that records what it was asked to fit (the fits themselves are tested elsewhere).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest

from harness.analysis.diagnosis import run
from harness.analysis.diagnosis.fitting import ModelSpec


@dataclass
class Fit:
    chi2_fit: float
    n_fit: int
    base: dict
    shared: dict
    cut_short: tuple = ()

    def chi2(self, which="fit"):
        assert which == "fit"
        return self.chi2_fit

    def n(self, which="fit"):
        assert which == "fit"
        return self.n_fit


@dataclass
class Ctx:
    nuisance: list
    chi2_per_residual: float
    tight: bool = False
    calls: list = field(default_factory=list)

    def fit_many(self, specs):
        (spec,) = specs
        self.calls.append((spec, self.tight))
        r = self.chi2_per_residual if len(self.calls) == 1 else 1.0
        return [Fit(r * 1000, 1000, {0: np.asarray(spec.start_base[0]) + 1.0}, {"a_coil": 0.5 * len(self.calls)})]


START = {0: np.zeros(3)}


@pytest.mark.parametrize("chi2_per_residual", [run.TIGHT_MAX_CHI2_PER_RESIDUAL * 1.01, 40.0, 1e4])
def test_a_misfit_reference_is_not_refitted_to_tight_tolerances(chi2_per_residual):
    ctx = Ctx(nuisance=["a_coil"], chi2_per_residual=chi2_per_residual)
    out = run.reference_refit(ctx, START)
    assert [t for _, t in ctx.calls] == [False] and not ctx.tight
    assert out.chi2() == pytest.approx(chi2_per_residual * 1000)


@pytest.mark.parametrize("chi2_per_residual", [0.8, 1.0, run.TIGHT_MAX_CHI2_PER_RESIDUAL * 0.99])
def test_a_reference_within_the_noise_goes_on_to_tight_tolerances_from_where_it_stopped(chi2_per_residual):
    ctx = Ctx(nuisance=["a_coil"], chi2_per_residual=chi2_per_residual)
    out = run.reference_refit(ctx, START)
    assert [t for _, t in ctx.calls] == [False, True] and not ctx.tight
    second: ModelSpec = ctx.calls[1][0]
    np.testing.assert_array_equal(second.start_base[0], np.ones(3))      # the first fit's end
    assert second.shared_init == {"a_coil": 0.5} and second.effects == ()
    assert out.shared == {"a_coil": 1.0}                                    # the tight fit's result


def test_without_a_nuisance_parameter_the_refit_keeps_the_default_tolerances():
    ctx = Ctx(nuisance=[], chi2_per_residual=1.0)
    run.reference_refit(ctx, START)
    assert [t for _, t in ctx.calls] == [False]
