"""Model-error diagnosis: which effect that the paper's model leaves out hides in a dataset?

``diagnose(dataset, settings) -> Diagnosis`` runs blind: it reads the measured tests and the rig
description (coil radius, field per ampere, sensor noise), never ``rig.effects``,
``rig.true_parameters`` or ``rig.effect_definitions``. ``harness.report.diagnosis_md.write_diagnosis(diag,
out_dir)`` writes ``diagnosis.json``, ``diagnosis.md`` (with residual figures), ``extended_params.json`` and
paper-style tables (``harness.report.tables``) of the paper model and of the extended model.

Modules (data flow top to bottom): ``settings`` (DiagnoseSettings), ``heldout`` (which samples fit the shared
effect parameters, which are held out), ``prepare`` (dataset -> prepared samples
and tests, noise floors), ``jobs`` (simulation jobs -> the simulator; residuals and traces on the measured
grids), ``candidates`` (the catalogue's parametrization: the one effect-specific module), ``baseline`` (the
paper's analytic identification steps), ``fitting`` (model fits with ``harness.analysis.core.lsq``, candidates in
parallel processes), ``decision`` (comparison, BIC/held-out rule, greedy forward selection), ``evidence``
(residual features), ``result`` (Diagnosis, gain blocks, JSON), ``run`` (``diagnose``: the procedure).

Procedure
---------
1. **Paper model, identified as in the paper** (the "before" model), per sample: R = V/I over the
   steady part of T5, L from the T5 current rise, Em from the steady T8 blocked force, K1 and K2
   from the static balance at the T3 and T5 steady displacements (the analytic steps of
   ``harness.analysis.identification.identify``); C and m by least squares on the T3 and T5 displacement (instead of
   NSGA-II; it also works where ``harness.analysis.identification.identify``'s settling check rejects drifting records).
2. **Refit**: the paper model re-fitted by least squares on the *fit tests* (default T1, T3, T5,
   T8: the identification tests plus the gap sweep T1, the only test that spans the deflection at
   a fixed field, without which field-law and spring-law effects cannot be told apart). Every
   candidate is nested in it, so it is the reference of every comparison.
3. **Candidates** (``fmu_src.effects``): each is the refitted model plus the effect, all base
   parameters (R, L, Em, K1, K2, damping ratio, m) re-fitted per sample and the effect parameters
   *shared* by the samples where physical (``SHARED_DEFS``): one coil (Rth, tau_th), one filler
   (ksat), one matrix material (Kc/K2, tau_c), one plate law (K5 D^2/K1), one coil-diaphragm
   coupling (lam), one rig (tau_s). The shared parameters are fitted jointly with the base
   parameters of up to ``max_shared_samples`` samples spread over the diameters and fractions;
   every other sample, and always those the user declared unseen (``DiagnoseSettings.unseen``,
   ``--unseen``), is a *held-out sample* (rule: ``heldout``): its base parameters are then
   fitted to its own fit tests with the effect parameters fixed. Fits start from the refit with
   the effect off (strength 0), so a candidate can only improve on the model it extends;
   weighted least squares (residuals / noise), Levenberg-Marquardt with forward-difference
   Jacobians (``harness.analysis.core.lsq``), several problems in lock-step so that one simulation batch
   serves them all, the candidates spread over ``workers`` processes. A candidate that has not paid
   for its parameters (chi-square decrease < k ln n) after ``screen_iter`` iterations is dropped.
   Uncertainties of the shared parameters: s^2 (J^T J)^-1 of the joint fit, s^2 = max(1, chi2/dof).
4. **Decision** on data the fits never used, the *held-out tests* (default T2, T4, T6, T7 of every
   sample), together with BIC on the fit data: a candidate is accepted when its BIC is lower than
   the reference's by more than ``bic_min`` (10) AND its held-out chi-square is lower by more than
   ``heldout_min`` (25). The accepted candidate with the largest score (held-out chi-square
   decrease - BIC change) is the cause; while the selected model's residuals still show structure
   (some test/signal with z > ``z_struct``), each remaining candidate is added to it in turn
   (greedy forward selection, same rule against the selected model) -> ranked ``causes``. No
   candidate accepted: ``none`` when the refit's residuals are noise (every z <= ``z_struct``),
   else ``unexplained``; causes accepted but the extended model still with some z > ``z_struct``:
   the causes + ``unexplained remainder`` (with where and in which samples). One function states this
   verdict: ``decision.verdict``. z = (chi2 - n)/sqrt(2n) per test and signal summed over the samples
   (a held-out test's z net of the chi-square its parameters' own uncertainty adds, when computed:
   ``allowance.prediction_allowance``).
5. **Evidence**: residual features of the paper model, each in noise units (``evidence``):
   current drift during the holds (heating), displacement drift at steady current (creep),
   steady residual vs field and blocked force per I^2 during the T8 rise (saturation), T1
   residual at the largest deflections (edge stiffening), current residual vs the back-EMF shape
   and the inductance by gap (motional EMF), delay of the readings with matching steady state
   (sensor lag); plus, per candidate, the tests and signals whose chi-square it lowers most.
6. **Gain**: RMSE before (paper identification), refit and after (extended model) on every
   held-out test and signal, in units and divided by the sensor noise floor; overall = RMS over
   samples, tests and signals of the normalized RMSE; the same for the held-out samples.

Noise model: time series, white noise at the sensor noise floor (manifest rig.sensors, else
estimated from the quiet part before the steps); sweep readings (means over the averaging
window of each hold) floor/sqrt(n), at least ``sweep_sigma_floor`` x floor, passed through
c*asinh(z/c) (a pull-in mismatch at one gap must not outweigh everything else).

Simulation: every fit and evaluation runs the vectorized simulator of ``harness.sim`` (one batch for
hundreds of runs: samples x tests x gaps x parameter sets), called from ``jobs`` only; its physics
are ``fmu_src.effects``' core functions, the same the FMU runs.

diagnosis.json (``diagnosis_to_json``)
--------------------------------------
``format`` "mpc-actuator-diagnosis/1", ``synthetic``, ``cause`` (catalogue name | "none" |
"unexplained"), ``verdict`` (the whole answer: "none" | "unexplained" | "A" | "A + B" | "A + unexplained
remainder"; ``decision.verdict``), ``unexplained_remainder`` {present, of_model, reason, where [{test,
signal, z}], per_sample_z {id: {"<test>_<signal>": z}}}, ``causes`` [{rank, name, score, delta_bic, delta_chi2_heldout, reason, shows_in
[{test, signal, delta_chi2}], evidence_features}], ``effects``, ``effect_parameters``
{"<name>_<unit>": {value, std, effect, description}, "per_sample": {id: {"Kc_N_per_m": ...}}},
``gain`` {heldout_tests, per_test {T: {"displacement_rmse_mm" | "blocked_force_rmse_N" |
"current_rmse_A" | "..._rmse_per_noise_floor": {before, refit, after}}}, overall_normalized_rmse
{before, refit, after, after_over_before}, heldout_samples {...}, declared_unseen_samples {...} (when
declared), fit_tests {...}, per_sample,
noise_floors, models}, ``candidates`` {name: {delta_bic, delta_chi2_fit, delta_chi2_heldout, score,
accepted, reason, shared_parameters, shows_in}}, ``evidence`` {features, baseline_structure_z,
final_structure_z, remaining_structure, uncertainty_allowance}, ``decision`` {rule, thresholds, fit_tests,
heldout_tests, shared_fit_samples, heldout_samples, heldout_sample_choice {declared_unseen, source, rule, ...}, rounds},
``samples`` [{id, wt_pct, diameter_mm, role, declared_unseen}], ``parameters`` {extended,
paper_identification, paper_refit: {id: {unit keys}}}, ``settings``, ``timing_s``.

extended_params.json (``extended_params_json``)
-----------------------------------------------
{"format": "mpc-actuator-params/1", "cause", "effects", "shared_effect_parameters",
"samples": {id: {"wt_pct", "diameter_mm", "role", "parameters": {"a_m", "D_m", "kB_T_per_A",
"R_Ohm", "L_H", "Em_N_m_per_T2", "K1_N_per_m3", "K2_N_per_m", "C_N_s_per_m", "m_kg",
"Rth_K_per_W", "tau_th_s", "ksat_per_T2", "Kc_N_per_m", "tau_c_s", "K5_N_per_m5", "lam_1",
"tau_s_s"}}}}: every FMU parameter except the per-test gap r0 (effects off = 0); the layout of
rig.true_parameters (``harness.data.rig.params_from_json`` and ``harness.cli.load_params_file`` read it).
"""
from .candidates import CANDIDATES, SHARED_DEFS
from .heldout import UnseenSampleError, declared_unseen
from .result import Diagnosis, diagnosis_to_json, extended_params_json
from .run import diagnose
from .settings import DiagnoseSettings, DiagnoseSettingsError

__all__ = ["CANDIDATES", "SHARED_DEFS", "DiagnoseSettings", "DiagnoseSettingsError", "Diagnosis", "diagnose",
           "diagnosis_to_json", "extended_params_json", "UnseenSampleError", "declared_unseen"]
