"""The numba-compiled scalar integrator (fmu_src.integrator): one kernel evaluation, the same physics
function objects as the vectorized paths, and the numba cache the FMU ships."""
import os
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from scipy.integrate import quad

from fmu_src import effects as fx, field, integrator
from fmu_src.model import EffectDynamics
from fmu_src.specs import Params

P = Params()


def test_kernel_value_floats_arrays_and_compiled_against_spline_and_quadrature():
    k = field.make_kernel(P.a, P.D, P.kB, P.r0)
    args = (k.coef, 0, k.smax, k.dr, k.inv_dr, k.G0, k.dG0)
    r = np.linspace(0.0, k.r_max, 1999)
    # the table is scipy's spline: same values (up to rounding of the breakpoints)
    spline = k.spline(r)
    vec = field.kernel_value(r, *args)
    assert np.max(np.abs(vec - spline)) <= 1e-13 * np.max(np.abs(spline))
    # and the quadrature kernel to 1e-8
    exact = field.force_kernel(r, P.a, P.D, P.kB)
    assert np.max(np.abs(vec / exact - 1.0)) < 1e-8
    for ri in (0.0, 1e-4, 0.0031, 0.012):
        b = lambda th: -field.field_per_amp(ri, th, P.a, P.kB) * field.dfield_dr_per_amp(ri, th, P.a, P.kB)  # noqa
        q = quad(b, 0.0, np.arctan2(0.5 * P.D, ri), epsabs=0.0, epsrel=1e-12)[0]
        assert field.kernel_value(ri, *args) == pytest.approx(q, rel=1e-8)
    # floats (Python and compiled) equal the array evaluation exactly
    compiled = integrator.COMPILED_PHYSICS["kernel_value"]
    for ri, vi in zip(r[::37], vec[::37]):
        assert field.kernel_value(float(ri), *args) == vi
        assert compiled(float(ri), *args) == vi
        assert k(float(ri)) == vi
    assert np.array_equal(k.eval(r), vec)
    # r < 0: linear continuation G0 + dG0*r (as the spline's first derivative at 0)
    neg = np.array([-1e-3, -1e-4])
    assert np.allclose(field.kernel_value(neg, *args), k.G0 + k.dG0 * neg, rtol=1e-15, atol=0)
    assert compiled(-1e-3, *args) == pytest.approx(k.G0 - 1e-3 * k.dG0, rel=1e-15)
    assert k.G0 == pytest.approx(1.5 * P.kB ** 2 / P.a, rel=1e-9)
    # several tables stacked column-wise with per-element offsets (harness.analysis.diagnose) = each alone
    k2 = field.make_kernel(P.a, 0.060, P.kB, 0.004)
    coef = np.hstack([k.coef, k2.coef])
    rr = np.array([0.001, 0.002, 0.005, -0.0005])
    which = np.array([0, 1, 1, 0])
    pick = lambda a, b: np.where(which == 0, a, b)  # noqa: E731
    got = field.kernel_value(rr, coef, np.where(which == 0, 0, k.nseg), pick(k.smax, k2.smax), pick(k.dr, k2.dr),
                             pick(k.inv_dr, k2.inv_dr), pick(k.G0, k2.G0), pick(k.dG0, k2.dG0))
    want = np.array([k.eval(rr[i]) if w == 0 else k2.eval(rr[i]) for i, w in enumerate(which)], dtype=float)
    assert np.array_equal(got, want)


def test_integrator_compiles_the_very_functions_the_vector_paths_call():
    """One implementation of the physics: every compiled physics function of the integrator is made from the
    function object of fmu_src.effects / field (numba keeps it as py_func), and the integrator's
    right-hand side calls those compiled functions."""
    home = {"kernel_value": field, "axial_field": field}
    callers = (integrator.rhs, integrator.net_contact_force, integrator.force_at, integrator.outputs, integrator.kernel)
    # what the integrator's compiled functions call: the objects their global names resolve to
    called = {id(fn.py_func.__globals__[n]) for fn in callers for n in fn.py_func.__code__.co_names
              if n in fn.py_func.__globals__}
    for name, disp in integrator.COMPILED_PHYSICS.items():
        assert disp.py_func is getattr(home.get(name, fx), name), name
        assert id(disp) in called, name
    # and the compiled right-hand side equals the uncompiled core functions (the vector paths' physics)
    kw = dict(Rth=8.0, tau_th=0.5, ksat=3.0, Kc=8.0, tau_c=0.3, K5=1e9, lam=0.3, tau_s=0.005)
    p = P.with_(r0=0.004, **kw)
    dyn = EffectDynamics(p)
    y = [0.6, 0.0017, 0.12, 35.0, 0.0009, 0.0011, 0.2]
    I, x, v, dT, xc, xs, Fs = y
    r = p.r0 - x
    Rc = fx.resistance(p.R, dT)
    F = fx.magnetic_force(p.Em, I, dyn.kernel.eval(np.array([r]))[0], p.ksat, p.kB)
    want = [fx.current_rate(11.0, I, Rc, p.L, p.lam, p.a, r, v), v,
            fx.diaphragm_acceleration(x, v, F, p.K1, p.K2, p.C, p.m, fx.effect_spring_force(x, p.K5, p.Kc, xc)),
            fx.thermal_rate(dT, I, Rc, p.Rth, p.tau_th), fx.creep_rate(x, xc, p.tau_c),
            fx.sensor_rate(x, xs, p.tau_s), fx.sensor_rate(F, Fs, p.tau_s)]
    assert dyn.rhs(y, 11.0, integrator.FREE) == pytest.approx(want, rel=1e-13, abs=0)


def test_fresh_extraction_loads_the_shipped_numba_cache(fmu_path, tmp_path):
    """The FMU ships numba's cache of its integrator; an FMU extracted anew (as fmpy does on every simulate)
    loads it in a fresh process: numba reports loading the compiled code from the extracted resources and
    compiles and saves nothing (no new cache files)."""
    from fmpy import extract
    with zipfile.ZipFile(fmu_path) as z:
        shipped = {n.rsplit("/", 1)[1] for n in z.namelist()
                   if n.startswith("resources/fmu_src/__pycache__/") and n.endswith((".nbi", ".nbc"))}
    assert any(n.startswith("integrator.advance-") for n in shipped), shipped
    unzipdir = extract(str(fmu_path), unzipdir=str(tmp_path / "fresh"))
    cache_dir = os.path.join(unzipdir, "resources", "fmu_src", "__pycache__")
    script = ("import sys; from fmpy import simulate_fmu; "
              "r = simulate_fmu(sys.argv[1], stop_time=0.05, output_interval=1e-3); print('x_end', r['x'][-1])")
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env["NUMBA_DEBUG_CACHE"] = "1"
    proc = subprocess.run([sys.executable, "-c", script, unzipdir], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = proc.stdout + proc.stderr
    assert "x_end" in out
    for fn in ("advance", "view_outputs"):
        assert f"[cache] data loaded from '{os.path.join(cache_dir, 'integrator.' + fn)}-" in out, out[-3000:]
    assert "data saved" not in out, out[-3000:]
    now = {n for n in os.listdir(cache_dir) if n.endswith((".nbi", ".nbc"))}
    assert now == shipped
