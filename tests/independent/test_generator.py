"""The independent test-data generator, checked against hand formulas (not against the project's physics).

Fast tests check the physics and the conventions; the generation of whole matrix members is marked
``slow`` (excluded by default; run with ``-m slow``).
"""
from __future__ import annotations

import ast
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from harness.data.dataset import read_dataset
from tests.independent import physics as ph
from tests.independent.generator import (ALL_SAMPLES, EFFECT_FORMS, MATRIX, RigConventions, SensorSpec,
                                         make_dataset, make_member, sample_times_s, sweep, time_series,
                                         true_params, with_effects)

HERE = Path(__file__).resolve().parent
EXACT = SensorSpec("noiseless", 0.0, 1e-12)          # no noise, quantization far below any tolerance
NOISELESS = dict(laser=EXACT, force=EXACT, current=EXACT)
P = true_params(20, 45)
V_023 = P.R_Ohm * 0.23 / P.kB_T_per_A                  # steady current kB*I = 0.23 T


def G_quad(r_m: float, p=P) -> float:
    """The force kernel by adaptive quadrature of Eq. 3 with a numerical dB/dr (central difference)."""
    h = 1e-7

    def integrand(th):
        B = ph.field_B_T(r_m, th, p.a_m, p.kB_T_per_A, 1.0)
        dB = (ph.field_B_T(r_m + h, th, p.a_m, p.kB_T_per_A, 1.0)
              - ph.field_B_T(r_m - h, th, p.a_m, p.kB_T_per_A, 1.0)) / (2 * h)
        return B * dB
    upper = math.atan(p.D_m / (2 * r_m))
    return -quad(integrand, 0.0, upper, epsabs=0.0, epsrel=1e-11, limit=200)[0]


# ================================================================ independence
@pytest.mark.parametrize("module", ["physics.py", "generator.py"])
def test_imports_none_of_the_projects_physics(module):
    tree = ast.parse((HERE / module).read_text())
    names = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    names += [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module]
    assert not [n for n in names if n.startswith(("fmu_src", "harness.sim", "harness.analysis", "harness.data.rig"))]
    assert all(n == "harness.data.dataset" for n in names if n.startswith("harness"))


# ================================================================ field and force kernel
def test_on_axis_field_against_biot_savart():
    a, kB, I = P.a_m, P.kB_T_per_A, 0.8
    mu0N = 2 * a * kB
    phi = np.linspace(0.0, 2 * np.pi, 4001)[:-1]
    dphi = 2 * np.pi / phi.size
    pts = np.column_stack([a * np.cos(phi), a * np.sin(phi), np.zeros_like(phi)])
    dl = np.column_stack([-a * np.sin(phi), a * np.cos(phi), np.zeros_like(phi)]) * dphi
    for z in (0.0, 0.003, 0.009, 0.02):
        rvec = np.array([0.0, 0.0, z]) - pts
        dist = np.linalg.norm(rvec, axis=1)[:, None]
        B = mu0N * I / (4 * np.pi) * np.sum(np.cross(dl, rvec) / dist**3, axis=0)
        assert abs(B[0]) < 1e-12 and abs(B[1]) < 1e-12
        assert ph.field_B_T(z, 0.0, a, kB, I) == pytest.approx(B[2], rel=1e-10)
        assert ph.on_axis_loop_field_T(z, a, kB, I) == pytest.approx(B[2], rel=1e-10)
    assert ph.field_B_T(0.0, 0.0, a, kB, 1.0) == pytest.approx(kB, rel=1e-14)   # kB: field per ampere at the face


def test_force_kernel_against_adaptive_quadrature_and_closed_form_at_contact():
    tab = ph.kernel_table(P.a_m, P.D_m, P.kB_T_per_A)
    assert ph.kernel_G(0.0, P.a_m, P.D_m, P.kB_T_per_A) == pytest.approx(1.5 * P.kB_T_per_A**2 / P.a_m, rel=1e-12)
    assert tab(0.0) == pytest.approx(1.5 * P.kB_T_per_A**2 / P.a_m, rel=1e-12)
    for r in (0.0004, 0.002, 0.00537, 0.011, 0.027):
        ref = G_quad(r)
        assert ph.kernel_G(r, P.a_m, P.D_m, P.kB_T_per_A) == pytest.approx(ref, rel=1e-7)
        assert tab(r) == pytest.approx(ref, rel=1e-7)
        assert tab.array(np.array([r]))[0] == pytest.approx(ref, rel=1e-7)


# ================================================================ coil
def test_steady_current_and_rl_rise_at_sample_instants_for_a_step_between_samples():
    conv = RigConventions(sample_rate_hz=250.0, step_phase=0.37, clock_start_s=12.0, record_s=0.3,
                          pre_trigger_s=0.02, **NOISELESS)
    t_clock, t_rel = sample_times_s(conv, conv.record_s)
    t_step = 0.02 + 0.37 / 250.0
    assert conv.step_delay_s == pytest.approx(t_step, rel=1e-15)
    r = ph.simulate(P, 0.002, True, ph.step_drive(t_step, V_023), t_rel)
    tau = P.L_H / P.R_Ohm
    expect = np.where(t_rel >= t_step, V_023 / P.R_Ohm * (1 - np.exp(-(t_rel - t_step) / tau)), 0.0)
    np.testing.assert_allclose(r["I_A"], expect, rtol=1e-6, atol=1e-9)
    assert r["I_A"][-1] == pytest.approx(V_023 / P.R_Ohm, rel=1e-6)       # 37 time constants: V/R
    # the recorded columns: clock, period, zero-order-hold voltage, current from the sample after the step
    ts = time_series(P, conv, "T8", 2.0, np.random.default_rng(0))
    assert ts["time_s"][0] == 12.0
    np.testing.assert_allclose(np.diff(ts["time_s"]), 1 / 250.0, rtol=1e-9)
    k_on = int(np.argmax(ts["voltage_V"] > 0))
    assert k_on == 6                                       # samples at 0, 4, ..., 20 ms read 0; 24 ms reads V
    assert (ts["voltage_V"][:k_on] == 0).all() and (ts["voltage_V"][k_on:] == V_023).all()
    first = (1 - 0.37) / 250.0                             # the step came 0.63 periods before sample k_on
    assert ts["current_A"][k_on] == pytest.approx(V_023 / P.R_Ohm * (1 - math.exp(-first / tau)), rel=1e-6)
    assert ts["force_N"][-1] == pytest.approx(P.Em_N_m_per_T2 * (V_023 / P.R_Ohm) ** 2 * G_quad(0.002), rel=1e-6)


# ================================================================ diaphragm
def test_static_equilibrium_by_brentq():
    gap = 0.005
    I = V_023 / P.R_Ohm
    r = ph.simulate(P, gap, False, ph.step_drive(0.2, V_023), np.arange(0, 3001) * 1e-3)
    net = lambda x: P.Em_N_m_per_T2 * I**2 * G_quad(gap - x) - (P.K1_N_per_m3 * x**3 + P.K2_N_per_m * x)
    x_eq = brentq(net, 0.0, 0.004, xtol=1e-14)
    assert r["x_m"][-1] == pytest.approx(x_eq, rel=1e-5)
    assert r["x_m"][199] == 0.0 and r["events"] == []


def test_pull_in_rests_at_the_coil_and_releases_when_the_net_force_changes_sign():
    gap, t_off = 0.002, 0.5
    drive = ph.Drive(((0.0, lambda t: V_023), (t_off, lambda t: 0.0)))
    t = np.arange(0, 1001) * 1e-3
    r = ph.simulate(P, gap, False, drive, t)
    kinds = [k for _, k in r["events"]]
    assert kinds[:2] == ["contact", "release"]
    on = (t > r["events"][0][0]) & (t < r["events"][1][0])
    assert (r["x_m"][on] == gap).all()                                     # rests exactly at x = r0
    I0 = V_023 / P.R_Ohm
    I_rel = math.sqrt((P.K1_N_per_m3 * gap**3 + P.K2_N_per_m * gap) / (P.Em_N_m_per_T2 * 1.5 * P.kB_T_per_A**2 / P.a_m))
    t_rel = t_off + P.L_H / P.R_Ohm * math.log(I0 / I_rel)                  # I decays as exp(-(t - t_off) R/L)
    assert r["events"][1][0] == pytest.approx(t_rel, abs=2e-6)
    assert r["x_m"][-1] < 1e-4                                             # back near rest after release


def test_blocked_force_with_tanh_and_langevin_saturation_by_hand():
    I = V_023 / P.R_Ohm
    F0 = P.Em_N_m_per_T2 * I**2 * G_quad(0.002)
    t = np.array([0.0, 0.5])
    for name, factor in (("saturation_tanh", math.tanh(0.23 / 0.45) / (0.23 / 0.45)),
                         ("saturation_langevin", 3 * (1 / math.tanh(3 * 0.23 / 0.35) - 0.35 / (3 * 0.23))
                          / (3 * 0.23 / 0.35)),
                         ("filler_saturation", 1 / (1 + 3 * 0.23**2))):
        p = with_effects(P, {name: 1.0})
        r = ph.simulate(p, 0.002, True, ph.step_drive(0.0, V_023), t)
        assert r["F_N"][-1] == pytest.approx(F0 * factor, rel=1e-6), name


def test_two_time_constant_heating_reaches_the_thermal_fixed_point():
    p = with_effects(P, {"coil_heating_2tau": 1.0})
    r = ph.simulate(p, 0.002, True, ph.step_drive(0.0, V_023), np.array([0.0, 400.0]))
    # steady: dT = (Rth1 + Rth2) V I, V = R0 (1 + alpha dT) I  ->  alpha Rth V R0 I^2 + R0 I - V = 0
    k = ph.ALPHA_CU_PER_K * sum(p.Rth_K_per_W) * V_023 * P.R_Ohm
    I = (-P.R_Ohm + math.sqrt(P.R_Ohm**2 + 4 * k * V_023)) / (2 * k)
    assert r["I_A"][-1] == pytest.approx(I, rel=1e-6)
    assert I < 0.85 * V_023 / P.R_Ohm


def test_two_branch_creep_relaxes_to_the_plain_equilibrium():
    p = with_effects(P, {"creep_2tau": 1.0})
    t = np.array([0.0, 0.2 + 0.15, 60.0])
    r = ph.simulate(p, 0.005, False, ph.step_drive(0.2, V_023), t)
    plain = ph.simulate(P, 0.005, False, ph.step_drive(0.2, V_023), t)
    assert r["x_m"][1] < 0.95 * plain["x_m"][1]                 # stiffer at first
    assert r["x_m"][2] == pytest.approx(plain["x_m"][2], rel=1e-5)   # both branches relaxed after 15 tau


# ================================================================ sensors, sweeps, datasets
def test_sweep_averaging_reduces_the_noise_by_sqrt_n():
    sens = SensorSpec("force", 0.002, 1e-12)
    gaps = (20.0,) * 150
    base = RigConventions(sample_rate_hz=500.0, sweep_gaps_mm=gaps, sweep_hold_s=0.4, force=sens, current=sens)
    single = sweep(P, replace(base, sweep_average_s=None), "T7", np.random.default_rng(1))
    avg = sweep(P, replace(base, sweep_average_s=0.05), "T7", np.random.default_rng(2))
    truth = P.Em_N_m_per_T2 * (V_023 / P.R_Ohm) ** 2 * G_quad(0.020)
    n = 25                                                      # 0.05 s at 500 Hz
    s1 = np.std(single["force_N"] - truth)
    sn = np.std(avg["force_N"] - truth)
    assert s1 == pytest.approx(0.002, rel=0.2)
    assert s1 / sn == pytest.approx(math.sqrt(n), rel=0.2)


def test_dataset_conventions_appear_as_specified_and_pass_read_dataset(tmp_path):
    conv = RigConventions(sample_rate_hz=400.0, step_phase=0.6, clock_start_s=7.25, pre_trigger_s=0.1,
                          record_s=0.8, t6_periods=1, sweep_gaps_mm=(9.0, 6.5, 4.0, 2.5), sweep_hold_s=0.5,
                          sweep_average_s=None, manifest_coil=False)
    out = make_dataset(tmp_path / "ds", conv, samples=[(20, 45)], seed=3)
    ds = read_dataset(out)
    assert "coil_radius_mm" not in ds.rig and "field_per_amp_T_per_A" not in ds.rig
    assert ds.rig["sweep_single_reading"] is True and "sweep_average_s" not in ds.rig
    assert ds.rig["sample_period_s"] == 1 / 400.0 and ds.rig["sweep_hold_s"] == 0.5
    s = ds.sample("W20-D45")
    assert list(s.test("T1").gap_mm) == [9.0, 6.5, 4.0, 2.5]
    for name in ("T2", "T3", "T4", "T5", "T6", "T8"):
        t = s.test(name).time_s
        assert t[0] == 7.25
        np.testing.assert_allclose(np.diff(t), 1 / 400.0, rtol=1e-9)
    t5 = s.test("T5")
    assert t5.time_s.size == round(0.8 * 400) + 1
    assert int(np.argmax(t5.voltage_V > 0)) == 41                # step at 0.1 s + 0.6/400 s: first sample 41/400 s
    assert t5.gap_mm == float(s.test("T1").gap_mm[np.argmax(s.test("T1").displacement_mm)]) + 2.0
    assert s.test("T6").time_s.size == round(1.1 * 400) + 1
    averaged = make_dataset(tmp_path / "ds2", replace(conv, sweep_average_s=0.1, manifest_coil=True),
                            samples=[(10, 30)], seed=3)
    ds2 = read_dataset(averaged)
    assert ds2.rig["sweep_average_s"] == 0.1 and ds2.rig["coil_radius_mm"] == 15.0
    assert ds2.rig["field_per_amp_T_per_A"] == 0.29


def test_same_seed_same_bytes(tmp_path):
    conv = RigConventions(sample_rate_hz=200.0, record_s=0.5, pre_trigger_s=0.05, t6_periods=1,
                          sweep_gaps_mm=(8.0, 4.0), sweep_hold_s=0.3)
    a = make_dataset(tmp_path / "a", conv, samples=[(30, 60)], seed=5)
    b = make_dataset(tmp_path / "b", conv, samples=[(30, 60)], seed=5)
    files = sorted(p.relative_to(a) for p in a.rglob("*.csv"))
    assert files and all((a / f).read_bytes() == (b / f).read_bytes() for f in files)


def test_the_matrix_spans_the_conventions_and_effect_forms():
    convs = [m.conventions for m in MATRIX.values()]
    rates = {c.sample_rate_hz for c in convs}
    assert min(rates) == 200.0 and max(rates) == 10000.0
    scales = {c.laser.sigma / 0.005 for c in convs} | {c.current.sigma / 0.002 for c in convs}
    assert min(scales) == pytest.approx(0.3) and max(scales) == pytest.approx(5.0)
    assert any(c.sweep_average_s is None for c in convs) and any(c.sweep_average_s for c in convs)
    assert any(c.clock_start_s > 0 for c in convs) and any(0 < c.step_phase < 1 for c in convs)
    assert any(not c.manifest_coil for c in convs)
    assert any(any(g % 1 for g in c.sweep_gaps_mm) for c in convs)
    used = {e for m in MATRIX.values() for e in m.effects}
    assert used == set(EFFECT_FORMS)
    assert len(ALL_SAMPLES) == 11


def test_true_parameters_retyped_from_the_readme_table():
    p = true_params(30, 60)
    assert (p.Em_N_m_per_T2, p.K2_N_per_m, p.K1_N_per_m3, p.m_kg) == pytest.approx(
        (0.1059, 30 * 1.6, 4e5 * 1.3, 0.004 * (60 / 45) ** 2 * 1.5), rel=1e-12)
    assert p.C_N_s_per_m / (2 * math.sqrt(p.K2_N_per_m * p.m_kg)) == pytest.approx(0.55, rel=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(MATRIX))
def test_matrix_member_generates_and_reads(name, tmp_path):
    out = make_member(name, tmp_path / name)
    ds = read_dataset(out)
    m = MATRIX[name]
    assert len(ds.samples) == (11 if m.samples is None else len(m.samples))
    assert ds.rig["independent_effects"] == m.effects
    t5 = ds.samples[0].test("T5")
    np.testing.assert_allclose(np.diff(t5.time_s), 1 / m.conventions.sample_rate_hz, rtol=1e-9)


def test_a_sample_exactly_at_the_step_reads_the_new_voltage():
    """Right-continuous zero-order hold: with step_phase 0 the sample at the step instant reads V_on."""
    conv = RigConventions(sample_rate_hz=100.0, step_phase=0.0, pre_trigger_s=0.05, record_s=0.1, **NOISELESS)
    ts = time_series(P, conv, "T8", 2.0, np.random.default_rng(0))
    assert int(np.argmax(ts["voltage_V"] > 0)) == 5 and ts["current_A"][5] == pytest.approx(0.0, abs=1e-9)
    d = ph.step_drive(0.05, 3.0)
    assert d.voltage_V(0.05) == 3.0 and d.voltage_V(np.nextafter(0.05, 0.0)) == 0.0
