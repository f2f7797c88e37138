"""The joint covariance of the seven identified parameters (harness.analysis.identification.cm_joint) and the choice of the
identified C, m.

* :func:`propagate` / :func:`joint_covariance` against the closed form of a linear least-squares toy problem;
* on a sample of the independent generator (one 45 mm sample, the fast clean member's conventions): the 7 x 7
  matrix is symmetric positive semi-definite, its C/m block is the fixed-analytic profile covariance plus a
  positive semi-definite part, and that part scales with the analytic parameters' covariance;
* old settings and files naming the paper's choice "eq6" still read.
"""
import dataclasses
import json

import numpy as np
import pytest

from harness.analysis.identification import cm_joint
from harness.analysis.identification.conventions import infer_conventions
from harness.analysis.identification.identify import analyse_sample, objective_for
from harness.analysis.identification.settings import IdentifySettings
from harness.analysis.identification.parameter_uncertainty import analytic_covariance
from harness.data import paramsjson, protocol
from harness.data.dataset import read_dataset
from tests.independent.bounds import blind
from tests.independent.generator import FAST_MATRIX, make_dataset


# --------------------------------------------------------------------------- linear toy problem
def _toy(seed=0, z0=(2.0e6, 3.0e-3)):
    """y = A x + B z + e: x estimated by least squares with z held at z0 (badly scaled z: the helper works in
    the parameters' relative scale)."""
    rng = np.random.default_rng(seed)
    n = 40
    A = rng.normal(size=(n, 2))
    B = rng.normal(size=(n, 2)) * np.array([1e-6, 1e2])          # both z of comparable effect on y
    P = np.linalg.solve(A.T @ A, A.T)                          # x_hat = P (y - B z)
    y = A @ np.array([1.0, -2.0]) + B @ np.asarray(z0) + 0.01 * rng.normal(size=n)
    return A, B, P, y, np.asarray(z0, dtype=float)


def test_propagation_on_a_linear_least_squares_problem_matches_the_closed_form():
    """x_hat(z) = P (y - B z), P = (A^T A)^-1 A^T, with z ~ (z0, S) held at z0 in the fit: by hand
    d x_hat / d z = -P B, so cov(x_hat) = sigma^2 (A^T A)^-1 + P B S B^T P^T, cov(x_hat, z) = -P B S, and the
    joint matrix is [[S, -S B^T P^T], [-P B S, sigma^2 (A^T A)^-1 + P B S B^T P^T]]."""
    A, B, P, y, z0 = _toy()
    sigma2 = 1e-4
    S = np.array([[1.0e10, 2.0e1], [2.0e1, 1.0e-7]])            # correlated, scales 1e5 and 3e-4
    fixed = sigma2 * np.linalg.inv(A.T @ A)
    cov, prop = cm_joint.joint_covariance(S, z0, fixed, lambda z: P @ (y - B @ z), lower=None)
    J = -P @ B
    expect = np.block([[S, S @ J.T], [J @ S, fixed + J @ S @ J.T]])
    assert np.allclose(prop, J @ S @ J.T, rtol=1e-8, atol=0)
    assert np.allclose(cov, expect, rtol=1e-8, atol=1e-12 * np.abs(expect).max())
    # a parameter at its lower bound (diagonal S: the clipped step stays on its axis): one-sided, still exact
    z1 = np.array([0.0, 3.0e-3])
    cy, cyx, cx = cm_joint.propagate(lambda z: P @ (y - B @ z), z1, np.diag([1.0e10, 1.0e-7]), lower=0.0)
    assert np.allclose(cy, J @ np.diag([1.0e10, 1.0e-7]) @ J.T, rtol=1e-8)
    assert np.allclose(cx, np.diag([1.0e10, 1.0e-7]), rtol=1e-12)
    # no uncertainty: nothing propagated
    cy, cyx, cx = cm_joint.propagate(lambda z: P @ (y - B @ z), z0, np.zeros((2, 2)))
    assert not cy.any() and not cyx.any() and not cx.any()
    with pytest.raises(ValueError, match="cov must be a finite"):
        cm_joint.propagate(lambda z: z, z0, np.eye(3))


# --------------------------------------------------------------------------- on generated data
@pytest.fixture(scope="module")
def sample_setup(tmp_path_factory):
    """(analysed sample, objective factory, cov5, truth) of W20-D45 made with the fast clean member's conventions."""
    m = FAST_MATRIX["fast-clean-400Hz-single"]
    ds = read_dataset(make_dataset(tmp_path_factory.mktemp("cmj") / "ds", m.conventions, seed=3,
                                   samples=[(20, 45)]))
    b = blind(ds)
    rig = infer_conventions(b).effective_rig(b.rig)
    an = analyse_sample(b.samples[0], rig, IdentifySettings())
    tight = IdentifySettings(settle_rtol=1e-8, rk_tol=1e-5)
    gaps = [float(b.samples[0].tests[n].gap_mm) / 1000.0 for n in protocol.IDENTIFICATION_TESTS]
    cov5 = analytic_covariance(an.result, gaps)
    truth = ds.rig["independent_truth"]["W20-D45"]
    make = lambda p: objective_for(dataclasses.replace(an, params=p), rig, tight, coil_step=True)  # noqa: E731
    make.rig = rig
    return an, make, cov5, truth


def _estimate(setup, cov5):
    an, make, _, truth = setup
    return cm_joint.least_squares_estimate(make, an.params, cov5, 1.1 * truth["C_N_s_per_m"], 0.9 * truth["m_kg"])


def test_the_joint_covariance_is_psd_and_propagation_only_adds_and_scales_with_the_analytic_covariance(sample_setup):
    cov5 = sample_setup[2]
    est = _estimate(sample_setup, cov5)
    assert est.ok, est.least_squares
    C = est.cov7
    assert C.shape == (7, 7) and np.allclose(C, C.T, rtol=0, atol=1e-15 * np.abs(C).max())
    # PSD in the parameters' relative scale (SI entries span 20 orders of magnitude)
    s = np.sqrt(np.diag(C))
    assert np.linalg.eigvalsh(C / np.outer(s, s)).min() > -1e-9
    assert np.allclose(C[:5, :5], cov5, rtol=1e-9, atol=1e-12 * np.sqrt(np.outer(np.diag(cov5), np.diag(cov5))).max())
    prof = est.profile.cov
    extra = C[5:, 5:] - prof
    assert np.allclose(extra, est.covariance_7["C_m_propagated_from_analytic"], rtol=1e-12)
    assert np.linalg.eigvalsh(extra).min() >= -1e-12 * np.abs(extra).max()
    assert C[5, 5] > prof[0, 0] and C[6, 6] > prof[1, 1]             # K1, K2 move m and C
    # four times the analytic covariance: the analytic block x4, the propagated part about x4 (linear to
    # the extent C_hat, m_hat are linear over two standard deviations of the analytic parameters)
    est4 = _estimate(sample_setup, 4.0 * cov5)
    assert np.allclose(est4.cov7[:5, :5], 4.0 * cov5, rtol=1e-9, atol=1e-12 * 4 * np.abs(cov5).max())
    extra4 = est4.cov7[5:, 5:] - est4.profile.cov
    for i in range(2):
        assert est4.cov7[5 + i, 5 + i] > C[5 + i, 5 + i]
        assert extra4[i, i] == pytest.approx(4.0 * extra[i, i], rel=0.25)
    # without the analytic covariance: the profile's alone, nothing propagated
    est0 = _estimate(sample_setup, None)
    assert np.array_equal(est0.cov7[5:, 5:], est0.profile.cov) and not est0.cov7[:5].any()


def test_covariance_and_intervals_json_name_the_parameters_with_units(sample_setup):
    est = _estimate(sample_setup, sample_setup[2])
    keys = ["R_Ohm", "L_H", "Em_N_m_per_T2", "K1_N_per_m3", "K2_N_per_m", "C_N_s_per_m", "m_kg"]
    assert est.covariance_7["parameters"] == keys
    assert np.array_equal(np.asarray(est.covariance_7["matrix"]), est.cov7)
    assert list(est.interval_95) == keys
    sd = np.sqrt(np.diag(est.cov7))
    # C and m log-normal about the least-squares point (geometric centre; half-width Z95 sd / value in ln)
    for i, key in ((5, "C_N_s_per_m"), (6, "m_kg")):
        lo, hi = est.interval_95[key]
        v = est.least_squares[key]
        assert np.sqrt(lo * hi) == pytest.approx(v, rel=1e-12)
        assert np.log(hi / lo) / 2 == pytest.approx(cm_joint.Z95 * sd[i] / v, rel=1e-12)
        assert 0 < lo < v < hi
    lo, hi = est.interval_95["K2_N_per_m"]                           # the analytic ones normal
    assert (lo + hi) / 2 == pytest.approx(sample_setup[0].params.K2, rel=1e-12)
    assert (hi - lo) / 2 == pytest.approx(cm_joint.Z95 * sd[4], rel=1e-12)
    json.dumps({"covariance_7": est.covariance_7, "interval_95": est.interval_95})


def test_the_paper_choice_is_reported_against_the_least_squares_estimate_and_is_the_fallback(sample_setup):
    est = _estimate(sample_setup, sample_setup[2])
    ls = est.least_squares
    sdC = float(np.sqrt(est.cov7[5, 5]))
    C, m, used, paper = cm_joint.identified_cm("least_squares", est, ls["C_N_s_per_m"] + 3 * sdC, 0.005, 7)
    assert (C, m, used) == (ls["C_N_s_per_m"], ls["m_kg"], "least_squares")
    assert paper["C_deviation_sd"] == pytest.approx(3.0, rel=1e-9) and paper["pareto_index"] == 7
    C, m, used, paper = cm_joint.identified_cm("paper", est, 0.5, 0.005, 7)
    assert (C, m, used) == (0.5, 0.005, "paper") and "fallback" not in paper
    failed = cm_joint.CMEstimate({"error": "no curvature"})
    C, m, used, paper = cm_joint.identified_cm("least_squares", failed, 0.5, 0.005, 7)
    assert (C, m, used) == (0.5, 0.005, "paper") and "no curvature" in paper["fallback"]
    assert "C_deviation_sd" not in paper


def test_old_settings_and_files_naming_eq6_still_read(tmp_path):
    assert IdentifySettings(choice="eq6").choice == "paper"
    assert IdentifySettings().choice == "least_squares"
    with pytest.raises(ValueError, match=r"choice must be one of least_squares, paper \(or eq6"):
        IdentifySettings(choice="least-squares-ish")
    # an identification.json of the old default: settings.choice "eq6", no paper_choice/covariance_7
    old = {"format": "mpc-actuator-identification/1", "synthetic": True,
           "settings": {**IdentifySettings().to_json(), "choice": "eq6"},
           "samples": {"W20-D45": {"wt_pct": 20, "diameter_mm": 45, "parameters": {
               "R_Ohm": 15.0, "L_H": 0.12, "Em_N_m_per_T2": 0.042, "K1_N_per_m3": 1.45e6, "K2_N_per_m": 52.0,
               "C_N_s_per_m": 0.56, "m_kg": 0.005, "a_m": 0.015, "D_m": 0.045, "kB_T_per_A": 0.29}}}}
    p = tmp_path / "identification.json"
    p.write_text(json.dumps(old))
    params = paramsjson.read_params_file(p)
    assert params["W20-D45"].C == 0.56 and params["W20-D45"].m == 0.005
    s = old["settings"]
    again = IdentifySettings(pop_size=s["pop_size"], n_gen=s["n_gen"], seed=s["seed"], choice=s["choice"])
    assert again.choice == "paper"


def test_the_least_squares_step_brings_the_coil_current_to_the_true_steps_value(sample_setup):
    """held_step_voltage(coil_tau_s=L/R): the interval holding the step (delay d before the first sample of the
    step) gets the voltage whose RL response from rest equals the true step's current at the interval's end,
    V (1 - exp(-d/tau)) / (1 - exp(-dt/tau)); the mean-voltage version (V d / dt) falls short of it."""
    from harness.analysis.identification.conventions import held_step_voltage
    an = sample_setup[0]
    ts = an.tests["T5"]
    tau = an.params.L / an.params.R
    v_mean, v_coil = held_step_voltage("T5", ts), held_step_voltage("T5", ts, tau)
    k = an.st["T5"].step
    dt = float(ts.time_s[k] - ts.time_s[k - 1])
    V = float(ts.voltage_V[k])
    d = v_mean[k - 1] / V * dt                                   # the delay the mean-voltage version used
    assert 0 < d < dt
    i_end = lambda v: v / an.params.R * (1 - np.exp(-dt / tau))  # RL current from rest after dt at held v
    assert i_end(v_coil[k - 1]) == pytest.approx(V / an.params.R * (1 - np.exp(-d / tau)), rel=1e-12)
    assert i_end(v_mean[k - 1]) < i_end(v_coil[k - 1])
    others = np.arange(ts.voltage_V.size) != k - 1
    assert np.array_equal(v_coil[others], v_mean[others])


def test_the_step_instants_uncertainty_is_propagated_into_c_and_m(sample_setup):
    """identify's estimate (:func:`harness.analysis.identification.identify.estimate_cm`) also carries the
    uncertainty of the T3 and T5 step instants its simulations start at: the same least-squares point, the
    same analytic block and cross-covariances, and a C/m block larger by exactly sum_i d_i d_i^T, with d_i
    the central difference of the least-squares point over +-1 sd of instant i, refitted here by hand."""
    from harness.analysis.identification import identify
    from harness.analysis.identification.cm_profile import cm_profile
    an, make, cov5, truth = sample_setup
    est0 = _estimate(sample_setup, cov5)
    names, Q = identify.instant_nuisance(an)
    assert names == ("T3", "T5") and np.all(np.diag(Q) > 0)
    tight = IdentifySettings(settle_rtol=1e-8, rk_tol=1e-5)
    est = identify.estimate_cm(an, make.rig, tight, an.params, cov5,
                               1.1 * truth["C_N_s_per_m"], 0.9 * truth["m_kg"])
    assert est.least_squares["m_kg"] == est0.least_squares["m_kg"]
    s0 = np.sqrt(np.diag(est0.cov7))
    corr = lambda c: c / np.outer(s0, s0)           # noqa: E731 - SI entries span 20 orders of magnitude
    assert np.allclose(corr(est.cov7)[:, :5], corr(est0.cov7)[:, :5], rtol=0, atol=1e-9)
    by_hand = np.zeros((2, 2))
    for i, name in enumerate(names):
        sd = float(np.sqrt(Q[i, i]))
        ends = []
        for sgn in (1.0, -1.0):
            shift = np.zeros(len(names))
            shift[i] = sgn * sd
            a = identify.shifted_instants(an, names, shift)
            assert a.step_instants[name].t_step_s == pytest.approx(an.step_instants[name].t_step_s + sgn * sd, abs=1e-15)
            pr = cm_profile(identify.objective_for(a, make.rig, tight, True),
                            est0.profile.C_hat, est0.profile.m_hat, n_grid=11)
            ends.append(np.array([pr.C_hat, pr.m_hat]))
        d = (ends[0] - ends[1]) / 2.0
        by_hand += np.outer(d, d)
    added = est.cov7[5:, 5:] - est0.cov7[5:, 5:]
    assert np.allclose(added, by_hand, rtol=1e-6, atol=1e-9 * np.abs(by_hand).max())
    assert added[1, 1] > 0
