"""What a reviewer checks in a figure, read from the matplotlib objects (not pixels): every axis label names a
quantity with its unit in parentheses and no raw key (``time_s``, ``T3_ste_s``) or bracketed unit; titles name
the sample and the test; uncertainty bands are drawn opaque enough, with edges, and magnified about the median;
a constant voltage is not auto-zoomed into its noise; "before" and "after" residuals both stay visible; sizes fit
a printed page; file names are safe; every figure function draws in the one style
(:mod:`harness.report.style`). The label and unit typesetting is tested over its input space (Hypothesis)."""
from __future__ import annotations

import re
import string
import types

import matplotlib as mpl
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from matplotlib.collections import PolyCollection

from fmu_src.specs import ALL_SPECS, Params
from harness.analysis.uncertainty.bands import Band
from harness.report import control_md, design_report, figures, style, uncertainty_report

from test_figures import synthetic_runs  # noqa: E402  (same folder, pytest rootdir import)

RAW_KEY = re.compile(r"[A-Za-z0-9]_(s|ms|mm|um|m|N|V|A|W|Hz|T|pct|deg|kg)\b")
UNIT_IN_PARENS = re.compile(r"\([^()]+\)\s*$")


# --------------------------------------------------------------------------- capture the drawn figures
@pytest.fixture
def drawn(monkeypatch):
    """The Figure objects the figure functions hand to ``style.save`` (still written, so the save runs)."""
    figs = []
    real = style.save

    def capture(fig, path):
        figs.append(fig)
        return real(fig, path)
    monkeypatch.setattr(style, "save", capture)
    return figs


def _axes(fig):
    return [ax for ax in fig.axes if ax.get_visible()]


def _outside_math(text: str) -> str:
    return re.sub(r"\$[^$]*\$", "", text)


def assert_labels_fit_for_print(fig):
    """Every non-empty axis label (colour bars included) ends with a unit in parentheses, shows no raw key and no
    bracketed unit; every visible axes has a y label; the figure has at least one x label."""
    xlabels = 0
    for ax in _axes(fig):
        labels = [ax.get_xlabel(), ax.get_ylabel()]
        if hasattr(ax, "get_zlabel"):
            labels.append(ax.get_zlabel())
        for lab in labels:
            if not lab:
                continue
            assert UNIT_IN_PARENS.search(lab), f"no unit in parentheses: {lab!r}"
            assert not RAW_KEY.search(_outside_math(lab)), f"raw key in label: {lab!r}"
            assert "[" not in lab and "_" not in _outside_math(lab), f"not print notation: {lab!r}"
        xlabels += bool(ax.get_xlabel())
        is_colorbar = ax.get_label() == "<colorbar>"
        if not is_colorbar and not hasattr(ax, "get_zlabel"):
            assert ax.get_ylabel(), f"axes {ax.get_title()!r} has no y label"
    assert xlabels >= 1


def assert_print_size(fig):
    w, h = fig.get_size_inches()
    assert 3.0 <= w <= style.MAX_SIZE_IN[0] and 2.0 <= h <= style.MAX_SIZE_IN[1], (w, h)
    assert h / w <= 1.6, f"{w} x {h} in: a strip, not a figure"


def suptitle(fig) -> str:
    return fig.get_suptitle()


# --------------------------------------------------------------------------- per figure
def test_sample_figure_names_sample_and_tests_with_units(tmp_path, drawn):
    figures.plot_sample_figure(tmp_path / "s.png", "W20-D45", synthetic_runs(), synthetic=True)
    fig = drawn[-1]
    assert_labels_fit_for_print(fig)
    assert_print_size(fig)
    assert "W20-D45" in suptitle(fig) and "T1–T8" in suptitle(fig) and "synthetic" in suptitle(fig)
    titles = [ax.get_title(loc="left") for ax in _axes(fig) if ax.get_title(loc="left")]
    assert len(titles) == 9 and all(re.search(r"T[1-8]", t) for t in titles)


def test_default_step_voltage_is_not_zoomed_into_its_noise(tmp_path, drawn):
    """A constant 11.9 V (with rounding noise of 1e-9 V) is drawn at its height above a zero-based axis: the
    axis spans 0 and 11.9 V, the level sits in its top fifth (auto-scaling gave 11.25-12.5 V, level mid-axis)."""
    t = np.linspace(0.0, 1.0, 1001)
    V = 11.9 + 1e-9 * np.sin(t)
    i = 0.8 * (1 - np.exp(-t / 0.008))
    figures.plot_default_step(tmp_path / "d.png", figures.StepTraces(t, V, i, 0.74 * (1 - np.exp(-t / 0.02)),
                                                                      0.047 * i ** 2))
    fig = drawn[-1]
    assert_labels_fit_for_print(fig)
    assert_print_size(fig)
    vax = fig.axes[0]
    assert "Voltage" in vax.get_ylabel()
    lo, hi = vax.get_ylim()
    assert lo <= 0.0 and hi >= 11.9
    assert (11.9 - lo) / (hi - lo) > 0.8
    assert "11.9 V" in suptitle(fig)


def test_residuals_before_and_after_both_visible_and_page_sized(tmp_path, drawn):
    """Ten panels (8 tests + 2 currents) on a page (was 825 x 2486 px); "before" is broader and under "after", so
    identical residuals still show both; one legend names the models; RMS of both sets in each title."""
    rng = np.random.default_rng(1)
    t = np.linspace(0, 1, 500)
    res = {k: (t, 0.01 * rng.standard_normal(t.size)) for k in
           ("T2", "T3", "T4", "T5", "T6", "T8", "T5 current", "T8 current")}
    res.update({k: (np.arange(26.0), 0.01 * rng.standard_normal(26)) for k in ("T1", "T7")})
    units = {"T5 current": "mA", "T8 current": "mA"}
    figures.plot_residuals(tmp_path / "r.png", res, res, units=units, title="Sample W10-D30: residuals",
                           labels=("paper model", "paper model + filler saturation"))
    fig = drawn[-1]
    assert_labels_fit_for_print(fig)
    assert_print_size(fig)
    assert len(_axes(fig)) == 10
    for ax in _axes(fig):
        before, after = [ln for ln in ax.get_lines() if ln.get_label() in ("paper model",
                                                                          "paper model + filler saturation")]
        assert before.get_zorder() < after.get_zorder()
        assert before.get_linewidth() >= 1.5 * after.get_linewidth() or before.get_marker() not in ("None", None)
        assert (before.get_alpha() or 1.0) < 1.0 and (after.get_alpha() or 1.0) > 0.5
        assert re.search(r"RMS \S+ → \S+", ax.get_title(loc="left"))
        assert re.match(r"T[1-8]", ax.get_title(loc="left"))
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["paper model", "paper model + filler saturation"]


def test_pareto_from_raw_keys_names_sample_and_units(tmp_path, drawn):
    F = np.random.default_rng(0).random((30, 4))
    figures.plot_pareto(tmp_path / "p.png", F, 3, ["T3_ste_s", "T3_rmse_mm", "T5_ste_s", "T5_rmse_mm"],
                        sample_id="W30-D60")
    fig = drawn[-1]
    assert_labels_fit_for_print(fig)
    assert_print_size(fig)
    assert "W30-D60" in suptitle(fig)
    assert fig.axes[0].get_xlabel() == "T3 settling-time error (s)"


def test_pareto_small_objectives_take_a_smaller_unit(tmp_path, drawn):
    """Settling-time errors of 1-4 ms and RMSEs of 5 um (as the identification gives them in s and mm) are drawn
    in ms and um, the data scaled by 1e3, not with a "1e-3" axis offset."""
    F = np.array([[0.001, 0.00508, 0.004, 0.00521], [0.003, 0.00514, 0.0, 0.00545]])
    figures.plot_pareto(tmp_path / "p.png", F, 0, ["T3_ste_s", "T3_rmse_mm", "T5_ste_s", "T5_rmse_mm"])
    ax = drawn[-1].axes[0]                                           # T3 STE (x) against T3 RMSE (y)
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("T3 settling-time error (ms)", "T3 RMSE (µm)")
    np.testing.assert_allclose(ax.collections[0].get_offsets(), [[1.0, 5.08], [3.0, 5.14]])


def test_surface_names_parameter_samples_and_typeset_unit(tmp_path, drawn):
    wt, d = np.meshgrid([10.0, 20.0, 30.0], [30.0, 45.0, 60.0])
    data = figures.SurfaceData("Em", "N.m/T2", wt.ravel(), d.ravel(), (1e-3 * wt * d).ravel(), ["W10-D30", "W30-D60"])
    figures.plot_surface(tmp_path / "e.png", data, lambda W, D: 1e-3 * W * D)
    fig = drawn[-1]
    assert_labels_fit_for_print(fig)
    assert_print_size(fig)
    text = " ".join([suptitle(fig)] + [ax.get_title(loc="left") for ax in fig.axes] +
                    [ax.get_ylabel() for ax in fig.axes])
    assert "N·m/T²" in text and "N.m/T2" not in text and "W10-D30" in suptitle(fig)


def _band(test, axis_name, column, n, scale, noise, inside):
    x = np.linspace(0, 3, n) if axis_name == "time_s" else np.arange(float(n))
    med = scale * (1 - np.exp(-x / 0.3))
    half = 1e-3 * scale                                  # a band 0.2 % of the response: invisible at full scale
    meas = med + noise * np.random.default_rng(0).standard_normal(n)
    return Band(test, column, axis_name, x, med - half, med, med + half, meas, noise, inside)


def test_bands_legible_and_coverage_explained(tmp_path, drawn):
    """The parameter band (0.2 % of the response) is filled (alpha >= 0.2) with edges and, in the panel below,
    magnified about the median so it spans at least a tenth of that axis; titles give the coverage, the figure
    title says what the prediction band is; labels are quantities, not `time_s`/`displacement_mm`."""
    bands = {"T1": _band("T1", "gap_mm", "displacement_mm", 26, 2.0, 0.01, 50.0),
             "T5": _band("T5", "time_s", "displacement_mm", 3000, 1.3, 0.003, 95.4),
             "T8": _band("T8", "time_s", "force_N", 3000, 0.1, 0.0005, 43.0)}
    uncertainty_report.plot_bands(tmp_path / "b.png", "W20-D45", bands)
    fig = drawn[-1]
    assert_labels_fit_for_print(fig)
    assert_print_size(fig)
    assert "W20-D45" in suptitle(fig) and "1.96" in suptitle(fig) and "model error" in suptitle(fig)
    titled = [ax for ax in fig.axes if ax.get_title(loc="left")]
    assert [re.search(r"(\d+) % of points in the prediction band", ax.get_title(loc="left")).group(1)
            for ax in titled] == ["50", "95", "43"]
    assert all(re.match(r"T[158]", ax.get_title(loc="left")) for ax in titled)
    for ax in fig.axes:
        fills = [c for c in ax.collections if isinstance(c, PolyCollection)]
        assert any(c.get_alpha() is not None and c.get_alpha() >= 0.2 for c in fills)


def test_bands_magnified_panel_spans_the_band(tmp_path, drawn):
    b = _band("T5", "time_s", "displacement_mm", 2000, 1.3, 0.0, 95.0)   # no noise: only the parameter band
    uncertainty_report.plot_bands(tmp_path / "b.png", "W10-D30", {"T5": b})
    top, below = drawn[-1].axes[:2]
    width = float((b.hi - b.lo).max())
    assert width / np.ptp(top.get_ylim()) < 0.01                 # a hairline at full scale ...
    assert width / np.ptp(below.get_ylim()) > 0.5                # ... fills the magnified panel


def test_control_figures_units_sample_and_safe_names(tmp_path, drawn):
    p = Params()
    control_md.plot_operating_map(tmp_path / "m.png", p, [0.005, 0.009], sample="W20-D45")
    control_md.plot_linearization(tmp_path / "l.png", p, [1e-3, 3e-3], sample="W20-D45")
    t = np.linspace(0, 0.5, 200)
    run = {"t_s": t, "x_ref_m": 1e-3 * (t > 0.1), "x_m": 1e-3 * (t > 0.12), "V_V": 5.0 * (t > 0.1)}
    res = types.SimpleNamespace(runs={("filler_saturation+coil_heating", "paper", "MPC", "stroke"): run})
    path = control_md.plot_loop(tmp_path / "loop_filler_saturation+coil_heating_stroke.png", res,
                                "filler_saturation+coil_heating", "stroke", sample="W20-D45")
    assert path.name == "loop_filler_saturation-coil_heating_stroke.png" and path.is_file()
    for fig in drawn:
        assert_labels_fit_for_print(fig)
        assert_print_size(fig)
        assert "W20-D45" in suptitle(fig)
    assert "filler saturation + coil heating" in suptitle(drawn[-1])


def test_design_figures_units_and_spec(tmp_path, drawn):
    from harness.analysis.design.evaluate import METRICS
    from harness.analysis.design.run import DesignResult, DesignSettings
    from harness.analysis.design.space import Axis, DesignSpace, Targets
    sp = DesignSpace(Axis("wt_pct", 10, 30, 3), Axis("diameter_mm", 30, 60, 3), Axis("gap_mm", 5, 5, 1),
                     Axis("voltage_V", 2, 4, 2))
    m = {k: np.linspace(0.5, 1.5, int(np.prod(sp.shape))).reshape(sp.shape) for k in METRICS}
    m["contact"] = np.zeros(sp.shape, bool)
    row = {"source": "grid", "wt_pct": 20.0, "diameter_mm": 45.0, "gap_mm": 5.0, "voltage_V": 3.0,
           **{k: 0.001 for k in METRICS}, "contact": False, "power_W": 1.0, "margin_pct": 1.0,
           "probability_linearised": 0.9, "probability_mc": None, "probability_mc_se": None}
    res = DesignResult(sp, Targets(stroke_mm=1.0), m, np.ones(sp.shape, bool), [row], "hull", DesignSettings(),
                       front=[0])
    design_report.write_design_outputs(res, tmp_path)
    assert len(drawn) == 3
    for fig in drawn:
        assert_labels_fit_for_print(fig)
        assert_print_size(fig)
        assert "stroke ≥ 1.00 mm" in suptitle(fig)


# --------------------------------------------------------------------------- the one style
FIGURE_FUNCTIONS = [figures.plot_default_step, figures.plot_sample_figure, figures.plot_residuals,
                    figures.plot_surface, figures.plot_pareto, uncertainty_report.plot_bands,
                    control_md.plot_operating_map, control_md.plot_linearization, control_md.plot_loop,
                    design_report.plot_tradeoff_front, design_report.plot_feasible_region, design_report.plot_tradeoffs]


@pytest.mark.parametrize("fn", FIGURE_FUNCTIONS, ids=lambda f: f.__qualname__)
def test_every_figure_function_draws_in_the_style(fn):
    assert getattr(fn, "__styled__", False), f"{fn.__module__}.{fn.__qualname__} is not @style.styled"


def test_style_applies_inside_and_does_not_leak(tmp_path, drawn):
    """The figure is drawn in RC whatever the caller's rcParams, and the caller's rcParams are as they were."""
    t = np.linspace(0, 1, 50)
    caller = {"axes.labelsize": 13.0, "font.size": 13.0, "axes.grid": False}
    with mpl.rc_context(caller):
        figures.plot_default_step(tmp_path / "d.png", figures.StepTraces(t, t, t, t, t))
        assert {k: mpl.rcParams[k] for k in caller} == caller
    fig = drawn[-1]
    assert fig.axes[0].yaxis.label.get_fontsize() == style.RC["axes.labelsize"] != 13.0
    png = (tmp_path / "d.png").read_bytes()
    w, h = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")
    assert (w, h) == tuple(round(v * style.DPI) for v in fig.get_size_inches())


# --------------------------------------------------------------------------- label typesetting, the whole space
_SYMBOLS = ["N", "m", "s", "T", "A", "V", "W", "kg", "K", "H", "Ohm", "Hz", "mm"]
_PRETTY = {"Ohm": "Ω"}
_SUP = dict(zip("2345", "²³⁴⁵"))
_RESERVED = {"per", "pct", "um", "us", "ms", "mA", "rad", "deg", "J", *_SYMBOLS}

terms = st.tuples(st.sampled_from(_SYMBOLS), st.sampled_from(["", "2", "3", "4", "5"]))
# a product is spelled only in a quotient's numerator ("N.m/T2", "N.s/m"), as in every key of the project: a bare
# product "N_m" would be ambiguous with a name ending in a unit symbol ("tau_s_s": tau_s in s)
units = st.one_of(st.tuples(st.lists(terms, min_size=1, max_size=1), st.just([]), st.just(False)),
                  st.tuples(st.lists(terms, min_size=1, max_size=2), st.lists(terms, min_size=1, max_size=2),
                            st.booleans()))
names = st.lists(st.text(string.ascii_letters, min_size=2, max_size=6).filter(
    lambda w: w not in _RESERVED and not re.fullmatch(r"(m|s|N|T|A|V|W|K|Hz)\d", w)), min_size=1, max_size=2)

FAST = settings(max_examples=150, deadline=None, derandomize=True, database=None)
DEEP = settings(max_examples=5000, deadline=None)


def _unit_string(num, den, one_over):
    """The unit as the specs write it ("N.m/T2"), and as print shows it ("N·m/T²"), written independently."""
    def spec(ts):
        return ".".join(s + e for s, e in ts)

    def pretty(ts):
        return "·".join(_PRETTY.get(s, s) + "".join(_SUP[c] for c in e) for s, e in ts)
    if den:
        n_spec, n_pretty = ("1", "1") if one_over else (spec(num), pretty(num))
        return f"{n_spec}/{spec(den)}", f"{n_pretty}/{pretty(den)}"
    return spec(num), pretty(num)


def _key(name_tokens, unit):
    """The key spelling of paramsjson ("N.m/T2" -> "N_m_per_T2", "1/T2" -> "per_T2"), written independently."""
    num, _, den = unit.partition("/")
    spelled = ("" if num == "1" else num.replace(".", "_") + "_") + "per_" + den.replace(".", "_") if den \
        else num.replace(".", "_")
    return "_".join(name_tokens) + "_" + spelled


def _check_key(name_tokens, u):
    unit, shown = _unit_string(*u)
    key = _key(name_tokens, unit)
    assert style.split_key(key) == ("_".join(name_tokens), unit)
    assert style.unit_text(unit) == shown
    lab = style.key_label(key)
    assert lab.endswith(f"({shown})"), (key, lab)
    assert "_" not in _outside_math(lab) and not RAW_KEY.search(_outside_math(lab))
    assert not re.search(r"[A-Za-z]\d", shown) and "." not in shown


@FAST
@given(names, units)
def test_key_label_typesets_any_unit_key(name_tokens, u):
    _check_key(name_tokens, u)


@pytest.mark.deep
@DEEP
@given(names, units)
def test_key_label_typesets_any_unit_key_deep(name_tokens, u):
    _check_key(name_tokens, u)


@pytest.mark.parametrize("spec", ALL_SPECS, ids=lambda s: s.name)
def test_every_model_unit_is_typeset(spec):
    shown = style.unit_text(spec.unit)
    assert "." not in shown and not re.search(r"[A-Za-z]\d", shown) and "Ohm" not in shown, shown


@pytest.mark.parametrize("key,label", [
    ("time_s", "Time $t$ (s)"), ("T3_ste_s", "T3 settling-time error (s)"), ("T5_rmse_mm", "T5 RMSE (mm)"),
    ("displacement_mm", "Displacement $x$ (mm)"), ("force_N", "Force $F$ (N)"), ("gap_mm", "Gap $r_0$ (mm)"),
    ("Em_N_m_per_T2", "Em (N·m/T²)"), ("ksat_per_T2", "ksat (1/T²)"), ("wt_pct", "Filler fraction (wt%)"),
    ("R_Ohm", "R (Ω)"), ("lam_1", "lam (–)"), ("tau_th_s", "tau th (s)")])
def test_key_label_examples(key, label):
    assert style.key_label(key) == label


@FAST
@given(st.text(max_size=40))
def test_safe_name_is_a_safe_file_name(text):
    out = style.safe_name(text)
    assert re.fullmatch(r"[A-Za-z0-9._-]+", out) and not out.startswith(".")
    assert style.safe_name(out) == out
    if re.fullmatch(r"[A-Za-z0-9_-]+", text) and text.strip("-"):
        assert out == text.strip("-")


@pytest.mark.parametrize("unit,values,expected", [
    ("N", [3e-5, -5e-5], ("µN", 1e6)), ("N", [0.004], ("mN", 1e3)), ("N", [0.2], ("N", 1.0)),
    ("mm", [0.012], ("µm", 1e3)), ("mm", [0.5], ("mm", 1.0)), ("mA", [0.002], ("mA", 1.0)),
    ("N", [0.0], ("N", 1.0)), ("N", [np.nan], ("N", 1.0)), ("N", [1e-9], ("µN", 1e6))])
def test_prefixed_unit_hand_computed(unit, values, expected):
    assert style.prefixed_unit(unit, values) == expected


def test_small_residuals_are_shown_in_a_smaller_unit_not_an_offset(tmp_path, drawn):
    """T7 residuals of at most 5e-5 N: the axis reads µN and the drawn data are the residuals x 1e6 (both sets)."""
    gap = np.arange(26.0)
    r = 5e-5 * np.sin(gap)
    figures.plot_residuals(tmp_path / "r.png", {"T7": (gap, r)}, {"T7": (gap, 0.5 * r)})
    ax = drawn[-1].axes[0]
    assert ax.get_ylabel() == "Residual (µN)"
    before, after = ax.get_lines()[:2]
    np.testing.assert_allclose(before.get_ydata(), 1e6 * r)
    np.testing.assert_allclose(after.get_ydata(), 0.5e6 * r)
    assert "µN" in ax.get_title(loc="left")


@settings(max_examples=200, deadline=None)
@given(y=hnp.arrays(np.float64, st.integers(1, 3000), elements=st.floats(-1e3, 1e3)),
       max_points=st.integers(2, 500))
def test_envelope_keeps_every_buckets_extremes(y, max_points):
    """style.envelope: at most max_points points (a trace no longer than that: itself), in time order, taken from
    the trace, and every bucket's minimum and maximum among them, so the drawn band is the trace's own."""
    from harness.report.style import envelope
    x = np.arange(y.size) * 1e-3
    xs, ys = envelope(x, y, max_points=max_points)
    if y.size <= max_points:
        assert np.array_equal(xs, x) and np.array_equal(ys, y)
        return
    assert xs.size <= max_points and np.all(np.diff(xs) > 0)
    idx = np.rint(xs / 1e-3).astype(int)
    assert np.array_equal(ys, y[idx])
    edges = np.linspace(0, y.size, max_points // 2 + 1).astype(int)
    for a, b in zip(edges[:-1], edges[1:]):
        inside = ys[(idx >= a) & (idx < b)]
        assert inside.min() == y[a:b].min() and inside.max() == y[a:b].max()
