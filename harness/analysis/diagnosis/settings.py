"""Frozen, validated settings of the diagnosis (:class:`DiagnoseSettings`)."""
from __future__ import annotations

import math
from dataclasses import dataclass


class DiagnoseSettingsError(ValueError):
    """Inconsistent diagnosis settings."""


@dataclass(frozen=True)
class DiagnoseSettings:
    """Settings of :func:`harness.analysis.diagnosis.diagnose` (see the package docstring for what they mean)."""
    fit_tests: tuple = ("T1", "T3", "T5", "T8")      # tests the fits use
    heldout_tests: tuple = ("T2", "T4", "T6", "T7")  # tests no fit uses: the decision and the gain
    max_shared_samples: int = 4      # samples whose data fit the shared effect parameters
    min_samples_holdout: int = 3     # from this many samples on, at least one is a held-out sample
    max_iter: int = 20               # Levenberg-Marquardt iterations per fit
    fine_s: float = 0.5              # [s] fine steps after each step input, then coarse (fits only)
    max_rate_hz: float = 2000.0      # [Hz] a faster rig is simulated and compared at every q-th sample
    #                                  (``jobs.decimation``): the cost stops growing with the sample rate
    sweep_sigma_floor: float = 0.5   # sweep-reading noise at least this x the sensor noise floor
    sweep_robust_c: float = 20.0     # c of the c*asinh(z/c) transform of sweep residuals
    bic_min: float = 10.0            # accept: BIC lower by more than this on the fit data ...
    heldout_min: float = 25.0        # ... and held-out chi-square lower by more than this
    z_struct: float = 5.0            # structure in the residuals: z = (chi2 - n)/sqrt(2n) above this
    workers: int = 2                 # processes for the candidate fits
    max_effects: int = 3             # greedy forward selection stops at this many effects
    screen_iter: int = 3             # iterations before a candidate must have paid for its parameters
    unseen: tuple | None = None      # sample ids declared unseen: held-out samples (``heldout`` module)
    discover: bool = True            # discovery (``harness.analysis.discovery``) after the catalogue stage when it
    #                                  leaves structure beyond the noise (off: the catalogue's verdict alone)
    max_terms: int = 2               # the discovery adds at most this many terms
    fit_budget_s: float = 75.0       # [s] CPU time of all the fits of one diagnosis (from its start) along its
    #                                  critical path (the wall time on idle cores, whatever the load:
    #                                  harness.analysis.core.cpu_clock): no Levenberg-Marquardt iteration starts
    #                                  after it; the fits it cut short are reported (``fits_cut_short``), never
    #                                  run on
    runoff_budget_s: float = 20.0    # [s] CPU time beyond fit_budget_s for a runoff: when the budget cut every
    #                                  candidate and the best one the fit data supported was not confirmed by the
    #                                  held-out tests, its fit alone goes on this long and is judged again
    #                                  (``decision.runoff``; 0: none, the verdict then names it undecided)

    def __post_init__(self):
        for name in ("fit_tests", "heldout_tests"):
            v = tuple(getattr(self, name))
            object.__setattr__(self, name, v)
        if self.unseen is not None:
            u = (self.unseen,) if isinstance(self.unseen, str) else self.unseen
            object.__setattr__(self, "unseen", tuple(str(x) for x in u))
        both = set(self.fit_tests) & set(self.heldout_tests)
        if both:
            raise DiagnoseSettingsError(f"tests {sorted(both)} are both fit and held-out tests")
        for name in ("T3", "T5", "T8"):
            if name not in self.fit_tests:
                raise DiagnoseSettingsError(
                    f"fit_tests must contain the identification tests T3, T5, T8 (missing {name})")
        if self.max_shared_samples < 1 or self.max_iter < 1 or self.workers < 1 or self.max_terms < 1:
            raise DiagnoseSettingsError("max_shared_samples, max_iter, workers and max_terms must be >= 1")
        if not (math.isfinite(self.max_rate_hz) and self.max_rate_hz > 0):
            raise DiagnoseSettingsError(f"max_rate_hz [Hz] must be > 0 and finite, got {self.max_rate_hz!r}")
        if not self.fit_budget_s > 0:
            raise DiagnoseSettingsError(f"fit_budget_s [s] must be > 0, got {self.fit_budget_s!r}")
        if not (math.isfinite(self.runoff_budget_s) and self.runoff_budget_s >= 0):
            raise DiagnoseSettingsError(f"runoff_budget_s [s] must be >= 0 and finite, got {self.runoff_budget_s!r}")
