"""The inputs, options, results and error of the analytic identification (:mod:`.analytic`, which re-exports them)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fmu_src.specs import Params


class AnalyticError(ValueError):
    """Data the analytic identification cannot use; ``test`` names the test (or None), ``reason`` says why."""

    def __init__(self, test: str | None, reason: str):
        self.test, self.reason = test, reason
        super().__init__(f"test {test}: {reason}" if test else reason)


# ============================================================================ inputs
@dataclass(frozen=True, eq=False)
class StepTest:
    """One measured step test in SI units.

    name: test name (for messages); time_s [s], voltage_V [V], current_A [A]: (n,) arrays;
    response: (n,) displacement [m] toward the coil (T3, T5) or blocked force [N] (T8);
    gap_m: gap r0 [m] at rest; field_T: nominal field [T] of the test (used for kB when the
    manifest gives none); response_name: name of the response column in messages;
    step: index of the first sample of the step, None for the protocol's onset rule
    (:func:`harness.data.protocol.step_onset`: first sample above half the maximum voltage);
    steady_start: index of the first sample of the steady window, None for the last ``steady_fraction``
    of the record after the step (set where the response settles later than that window's start).
    """
    name: str
    time_s: np.ndarray
    voltage_V: np.ndarray
    current_A: np.ndarray
    response: np.ndarray
    gap_m: float
    field_T: float = float("nan")
    response_name: str = "response"
    step: int | None = None
    steady_start: int | None = None


@dataclass(frozen=True, eq=False)
class AnalyticInput:
    """The three tests of one sample and the geometry.

    T3, T5: displacement steps (0.11 T, 0.23 T); T8: blocked-force step (0.23 T);
    a_m: loop radius a [m] of the electromagnet; D_m: diaphragm diameter D [m];
    kB_T_per_A: field per ampere [T/A] (the manifest's), None to derive it from T5;
    sd_a_m: standard uncertainty [m] of a (0: known, e.g. from the manifest; else the T7 derivation's,
    ``harness.analysis.identification.conventions.coil_radius_from_t7``), propagated into Em, K1 and K2.
    """
    T3: StepTest
    T5: StepTest
    T8: StepTest
    a_m: float
    D_m: float
    kB_T_per_A: float | None = None
    sd_a_m: float = 0.0


_CHOICES = {
    "initial_current": ("pre_step_mean", "zero"),
    "tau_start": ("crossing", "grid"),
    "tau_scaling": ("unit", "jacobian"),
    "kernel_range": ("shared", "per_test"),
    "nonphysical": ("raise", "fallback"),
    "step_instant": ("fit", "sample"),
}


@dataclass(frozen=True)
class AnalyticOptions:
    """Choices of the analytic identification (module docstring has the table).

    steady_fraction: part of the post-step record averaged for steady values (0, 0.9];
    initial_current, tau_start, tau_scaling: the RL fit; kernel_range: force-kernel table;
    nonphysical: what non-physical stiffness (and implausible data) do; step_instant: "fit" (the step
    instant within the sample interval fitted jointly with L/R) or "sample" (at the first sample of the step).
    """
    steady_fraction: float = 0.5
    initial_current: str = "pre_step_mean"
    tau_start: str = "crossing"
    tau_scaling: str = "unit"
    kernel_range: str = "shared"
    nonphysical: str = "raise"
    step_instant: str = "fit"

    def __post_init__(self):
        if not (0 < self.steady_fraction <= 0.9):
            raise ValueError(f"steady_fraction must be in (0, 0.9], got {self.steady_fraction!r}")
        for name, allowed in _CHOICES.items():
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name} must be one of {allowed}, got {getattr(self, name)!r}")

    @classmethod
    def diagnosis_baseline(cls, steady_fraction: float = 0.5) -> "AnalyticOptions":
        """The choices of the former copy in ``harness.analysis.diagnose`` (its numbers unchanged)."""
        return cls(steady_fraction=steady_fraction, initial_current="zero", tau_start="grid",
                   tau_scaling="jacobian", kernel_range="per_test", nonphysical="fallback")


# ============================================================================ results
@dataclass(frozen=True)
class SteadyState:
    """Steady part of a step test: window [start, end of record) and its means with standard uncertainties.

    step, start: sample indices of the step and of the steady window; t_step_s [s]: time of the step;
    voltage_V [V], current_A [A], response (the test's unit: m or N): window means;
    sd_*: their standard uncertainties, std / sqrt(n) of the window.
    """
    step: int
    start: int
    t_step_s: float
    voltage_V: float
    current_A: float
    response: float
    sd_voltage_V: float
    sd_current_A: float
    sd_response: float


@dataclass(frozen=True)
class RLFit:
    """RL fit of a step's current: tau_s = L/R [s], L_H [H], sd_L_H [H] (standard uncertainty from the fit),
    I0_A [A] the initial current of the fitted response; t_step_s [s] the step instant (sd_t_step_s its
    standard uncertainty), step_delay_s [s] = time of the first sample of the step - t_step_s (0 ..
    sample_period_s [s], the period of the record at the step)."""
    tau_s: float
    L_H: float
    sd_L_H: float
    I0_A: float
    t_step_s: float = float("nan")
    sd_t_step_s: float = 0.0
    step_delay_s: float = 0.0
    sample_period_s: float = float("nan")


@dataclass(frozen=True)
class AnalyticResult:
    """Analytic parameters of one sample (SI) with standard uncertainties ``sd_*`` (same units).

    a_m, D_m [m]; kB_T_per_A [T/A] and kB_source ("manifest" or "T5 field_T / steady current");
    R_Ohm, L_H, Em_N_m_per_T2, K1_N_per_m3, K2_N_per_m; steady: {"T3", "T5", "T8": SteadyState};
    notes: what the "fallback" policy changed, or a negative K1 within its noise set to 0 (empty otherwise);
    rl_T5: the RL fit of T5 (step instant); contact: the tests ("T5", or "T3" and "T5") whose steady displacement
    is at the coil face (at least :data:`harness.analysis.identification.analytic.CONTACT_GAP_FRACTION` of the gap; "fallback" policy only: "raise" refuses
    them), where the static balance does not hold: with T5 alone in contact, K1 is the largest value the contact
    allows on T3's balance line (an upper bound; :func:`harness.analysis.identification.analytic.k2_on_t3_line` gives K2 for any smaller K1), and the
    diagnosis fits it on the trajectories; static_points: {"T3", "T5": (steady displacement x [m], magnetic
    force F [N] there)}.
    """
    a_m: float
    D_m: float
    kB_T_per_A: float
    kB_source: str
    R_Ohm: float
    L_H: float
    Em_N_m_per_T2: float
    K1_N_per_m3: float
    K2_N_per_m: float
    sd_R_Ohm: float
    sd_L_H: float
    sd_Em_N_m_per_T2: float
    sd_K1_N_per_m3: float
    sd_K2_N_per_m: float
    steady: dict = field(default_factory=dict)
    notes: tuple = ()
    rl_T5: RLFit | None = None
    sd_a_m: float = 0.0
    contact: tuple = ()
    static_points: dict = field(default_factory=dict)

    def params(self, **kw) -> Params:
        """:class:`fmu_src.specs.Params` with these values (C, m, r0 at their defaults unless given in kw)."""
        return Params(a=self.a_m, D=self.D_m, kB=self.kB_T_per_A, R=self.R_Ohm, L=self.L_H, Em=self.Em_N_m_per_T2,
                      K1=self.K1_N_per_m3, K2=self.K2_N_per_m, **kw)

    def uncertainty(self) -> dict:
        """{"R", "L", "Em", "K1", "K2": standard uncertainty} (the units of the parameters)."""
        return {"R": self.sd_R_Ohm, "L": self.sd_L_H, "Em": self.sd_Em_N_m_per_T2, "K1": self.sd_K1_N_per_m3,
                "K2": self.sd_K2_N_per_m}
