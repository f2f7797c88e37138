"""The settings of the identification (:class:`IdentifySettings`): NSGA-II size, the Eq. 6 weights, the search
space of (C, m), the settling band and tolerances, and which (C, m) is handed downstream. Read by
:mod:`harness.analysis.identification.identify` and every job that identifies."""
from __future__ import annotations

import math
from dataclasses import dataclass

from harness.analysis.core.nsga import NSGAConfig
from harness.analysis.identification.cm_joint import CHOICE_ALIASES, CHOICES
from harness.analysis.identification.objectives import OBJECTIVE_NAMES, ObjectiveSettings
from harness.analysis.identification.selection import validate_weights

__all__ = ["IdentifySettings"]


@dataclass(frozen=True)
class IdentifySettings:
    """Settings of the identification (paper section 3), checked when made.

    Parameters
    ----------
    pop_size : int
        NSGA-II population size (paper: 200, see :meth:`paper`; the default 64 reaches the same chosen model
        with 60 generations, see the tests).
    n_gen : int
        NSGA-II generations (paper: 200).
    seed : int
        Random seed of NSGA-II; each sample's run is seeded alike and is independent of the other samples.
    weights : tuple of float
        Eq. 6 weights alpha_1..alpha_4 of (T3 STE, T3 RMSE, T5 STE, T5 RMSE) [-].
    f_n_range_hz : tuple of float
        (lo, hi) of the small-signal natural frequency f_n = sqrt(K2/m) / (2 pi) the search spans [Hz].
    zeta_range : tuple of float
        (lo, hi) of the damping ratio zeta = C / (2 sqrt(K2 m)) the search spans [-].
    band : float
        Settling band [-] (0.02 = 2 %).
    steady_fraction : float
        Part of the post-step record averaged for the steady values [-], in (0, 0.9].
    settle_rtol : float
        Relative tolerance of the settling detection in the batched integration [-]
        (:mod:`harness.analysis.identification.objectives`).
    rk_tol : float
        Tolerance of the batched Runge-Kutta integration [-].
    ste_resolution_s : float or None
        Settling-time errors are rounded to this resolution [s] (None: the sample period, below which settling
        times are not resolved; without it, differences of a fraction of a millisecond between noisy measured
        and simulated settling times put far-off models on the front and decide Eq. 6).
    choice : str
        Which (C, m) becomes the identified model handed downstream: "least_squares" (default: the
        profile-likelihood estimate from the T3 and T5 displacement residuals) or "paper" (Eq. 6 on the Pareto
        front; "eq6" is read as "paper"), both written either way. Eq. 6 is biased (several sd off the
        least-squares estimate on clean data, ``paper_choice`` says how far); a failed least-squares estimate
        falls back to it, the reason recorded.

    Raises
    ------
    ValueError
        A setting out of range; the message names it.
    """
    pop_size: int = 64
    n_gen: int = 60
    seed: int = 1
    weights: tuple = (1.0, 1.0, 1.0, 1.0)
    f_n_range_hz: tuple = (1.0, 100.0)
    zeta_range: tuple = (0.05, 5.0)
    band: float = 0.02
    steady_fraction: float = 0.5
    settle_rtol: float = 1e-4
    rk_tol: float = 1e-3
    ste_resolution_s: float | None = None
    choice: str = "least_squares"

    def __post_init__(self):
        object.__setattr__(self, "weights", validate_weights(self.weights))
        self.nsga()                                  # checks pop_size and n_gen
        for name in ("f_n_range_hz", "zeta_range"):
            lo, hi = (float(v) for v in getattr(self, name))
            if not (0 < lo < hi and math.isfinite(hi)):
                raise ValueError(f"{name} must be (lo, hi) with 0 < lo < hi, got {getattr(self, name)!r}")
            object.__setattr__(self, name, (lo, hi))
        if not (0 < self.band < 1):
            raise ValueError(f"band must be in (0, 1), got {self.band!r}")
        object.__setattr__(self, "choice", CHOICE_ALIASES.get(self.choice, self.choice))
        if self.choice not in CHOICES:
            raise ValueError(f"choice must be one of {', '.join(CHOICES)} (or eq6, the old name of paper), "
                             f"got {self.choice!r}")
        if not (0 < self.steady_fraction <= 0.9):
            raise ValueError(f"steady_fraction must be in (0, 0.9], got {self.steady_fraction!r}")

    def nsga(self) -> NSGAConfig:
        """The NSGA-II part: population, generations, seed."""
        return NSGAConfig(pop_size=self.pop_size, n_gen=self.n_gen, seed=self.seed)

    def objective(self) -> ObjectiveSettings:
        """The objectives' part: search space, settling band, integration tolerances, STE resolution."""
        return ObjectiveSettings(f_n_range_hz=self.f_n_range_hz, zeta_range=self.zeta_range, band=self.band,
                                 settle_rtol=self.settle_rtol, rk_tol=self.rk_tol,
                                 ste_resolution_s=self.ste_resolution_s)

    @classmethod
    def paper(cls, **kw) -> "IdentifySettings":
        """The paper's NSGA-II settings: population 200, 200 generations.

        Parameters
        ----------
        **kw
            Any other setting (the fields above but ``pop_size`` and ``n_gen``).
        """
        return cls(pop_size=200, n_gen=200, **kw)

    def to_json(self) -> dict:
        """The settings as written into ``identification.json`` (units in the keys).

        Returns
        -------
        dict
            ``pop_size``, ``n_gen``, ``seed``, ``weights`` ({objective name: alpha}), ``f_n_range_Hz``,
            ``zeta_range``, ``settling_band``, ``steady_fraction``, ``settle_rtol``, ``rk_tol``,
            ``ste_resolution_s``, ``choice``.
        """
        return {"pop_size": int(self.pop_size), "n_gen": int(self.n_gen), "seed": int(self.seed),
                "weights": {n: w for n, w in zip(OBJECTIVE_NAMES, self.weights)},
                "f_n_range_Hz": list(self.f_n_range_hz), "zeta_range": list(self.zeta_range),
                "settling_band": self.band, "steady_fraction": self.steady_fraction,
                "settle_rtol": self.settle_rtol, "rk_tol": self.rk_tol,
                "ste_resolution_s": self.ste_resolution_s, "choice": self.choice}
