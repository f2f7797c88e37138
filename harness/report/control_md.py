"""Report of the closed-loop control study (``harness.control``): figures (operating map and static inverse,
linearization step and Bode responses, closed-loop traces) and control.md, control_metrics.csv,
control.json, written into a folder.
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import control
import numpy as np
from harness.control.linearize import linearize
from harness.control.opmap import operating_map
from harness.control.study import StudyResult, StudySettings
from harness.report import style
from harness.report.figures import effect_text

METRIC_COLUMNS = ("rmse_m", "max_abs_error_m", "overshoot_m", "settling_s", "peak_V", "energy_J",
                  "contact_events", "min_gap_m", "max_x_m")


def _who(sample: str | None) -> str:
    """"Sample W20-D45: " for a title; a study's sample may name its parameter file ("W20-D45 of <path>"): the
    path is left to control.md."""
    return f"Sample {sample.split(' of ')[0]}: " if sample else ""


@style.styled
def plot_operating_map(path: Path, p, gaps_m, sample: str | None = None) -> Path:
    """Steady displacement against voltage per gap, the pull-in boundary, and the static inverse."""
    om = operating_map(p, gaps_m)
    fig = style.new_figure(7.2, 3.2)
    ax, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    vmax = 1.3 * max(c.V_pull_in_V for c in om.curves)
    for c in om.curves:
        V = np.linspace(0, vmax, 400)
        ax.plot(V, 1e3 * c.displacement(V), label=f"$r_0$ = {1e3 * c.r0_m:g} mm")
    ax.plot([c.V_pull_in_V for c in om.curves], [1e3 * c.x_pull_in_m for c in om.curves], "k--o", ms=3,
            label="pull-in (fold)")
    ax.set_xlabel(style.label("Voltage $V$", "V"))
    ax.set_ylabel(style.label("Steady displacement $x$", "mm"))
    ax.set_title("a) steady $x(V)$ per gap ($x$ = gap: contact)", loc="left")
    ax.legend(fontsize=6)
    c = next((c for c in om.curves if abs(c.r0_m - p.r0) < 1e-12), om.curves[-1])
    ax2.plot(1e3 * c.x_m, c.V_V, color=style.COLORS[0], label="$V$ that holds $x$ (stable)")
    ax2.axvspan(1e3 * c.x_pull_in_m, 1e3 * c.r0_m, color="0.85", label="not holdable open loop")
    ax2.set_xlim(0, 1e3 * c.r0_m)
    ax2.set_xlabel(style.label("Target displacement $x$", "mm"))
    ax2.set_ylabel(style.label("Static inverse $V$", "V"))
    ax2.set_title(f"b) static inverse at gap $r_0$ = {1e3 * c.r0_m:g} mm", loc="left")
    ax2.legend(fontsize=6)
    style.suptitle(fig, f"{_who(sample)}operating map and static inverse")
    return style.save(fig, path)


@style.styled
def plot_linearization(path: Path, p, xs_m, sample: str | None = None) -> Path:
    """Step responses (per volt) and Bode magnitude/phase of the linearizations at xs_m [m]."""
    fig = style.new_figure(7.2, 3.4)
    axd = fig.subplot_mosaic([["step", "mag"], ["step", "phase"]])
    ax, axm, axp = axd["step"], axd["mag"], axd["phase"]
    axp.sharex(axm)
    w = np.geomspace(1, 1e4, 300)
    for x in xs_m:
        lin = linearize(p, x)
        t = np.linspace(0, 0.25, 500)
        resp = control.step_response(lin.sys, t)
        ax.plot(resp.time, 1e6 * np.squeeze(resp.outputs), label=f"$x_0$ = {1e3 * x:.3g} mm")
        fr = control.frequency_response(lin.sys, w)
        axm.loglog(w, 1e6 * np.squeeze(fr.magnitude), label=f"$x_0$ = {1e3 * x:.3g} mm")
        axp.semilogx(w, np.degrees(np.unwrap(np.squeeze(fr.phase))))
    ax.set_xlabel(style.label("Time $t$", "s"))
    ax.set_ylabel(style.label("Step response $\\Delta x/\\Delta V$", "um/V"))
    ax.set_title("a) step response of the linearizations", loc="left")
    ax.legend(fontsize=6)
    axm.set_ylabel(style.label("$|\\Delta x/\\Delta V|$", "um/V"))
    axm.set_title("b) Bode diagram", loc="left")
    axm.tick_params(labelbottom=False)
    axp.set_ylabel(style.label("Phase", "deg"))
    axp.set_xlabel(style.label("Angular frequency $\\omega$", "rad/s"))
    style.suptitle(fig, f"{_who(sample)}linearizations about the operating points $x_0$")
    return style.save(fig, path)


@style.styled
def plot_loop(path: Path, res: StudyResult, plant: str, profile: str, sample: str | None = None) -> Path:
    """x_ref and x (top) and V (bottom) of every controller/model on one plant and profile; the file name is
    made safe (a plant with two effects, "a+b", is written "a-b")."""
    fig = style.new_figure(7.2, 4.6)
    ax, axv = fig.add_subplot(2, 1, 1), fig.add_subplot(2, 1, 2)
    first = True
    colors: dict = {}
    for (pl, model, ctl, prof), run in res.runs.items():
        if pl != plant or prof != profile:
            continue
        if first:
            ax.plot(run["t_s"], 1e3 * run["x_ref_m"], color="k", ls=":", lw=1.2, label="set-point", zorder=4)
            first = False
        lab = f"{ctl}, {model} model"
        # colour: the controller; line style: the model it is built on (paper solid, extended dashed)
        c = colors.setdefault(ctl, style.COLORS[len(colors) % len(style.COLORS)])
        ls = "-" if model == "paper" else "--"
        ax.plot(run["t_s"], 1e3 * run["x_m"], color=c, ls=ls, label=lab)
        axv.plot(run["t_s"], run["V_V"], color=c, ls=ls, label=lab)
    ax.set_ylabel(style.label("Displacement $x$", "mm"))
    ax.set_xlabel(style.label("Time $t$", "s"))
    ax.legend(fontsize=6, ncols=2)
    axv.set_ylabel(style.label("Voltage $V$", "V"))
    axv.set_xlabel(style.label("Time $t$", "s"))
    what = "clean" if plant == "clean" else effect_text(plant)
    style.suptitle(fig, f"{_who(sample)}closed loop on the {what} plant, {profile} profile")
    return style.save(fig, path)


def _f(v, digits=4) -> str:
    if isinstance(v, (int, np.integer)):
        return str(v)
    return "–" if v is None or not math.isfinite(v) else f"{v:.{digits}g}"


def _table(rows) -> str:
    head = ["plant", "model", "controller", "profile", "RMSE [um]", "max err [um]", "overshoot [um]",
            "settling [ms]", "peak V [V]", "energy [J]", "contacts", "min gap [mm]"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        out.append("| " + " | ".join([r["plant"], r["model"], r["controller"], r["profile"],
                                      _f(1e6 * r["rmse_m"]), _f(1e6 * r["max_abs_error_m"]),
                                      _f(1e6 * r["overshoot_m"]), _f(1e3 * r["settling_s"]), _f(r["peak_V"]),
                                      _f(r["energy_J"]), str(r["contact_events"]), _f(1e3 * r["min_gap_m"])]) + " |")
    return "\n".join(out)


def improvement_rows(res: StudyResult) -> list:
    """Per controller and profile on the hidden-effect plant: RMSE with the paper's model, with the extended
    model, and their ratio."""
    by = {(r["plant"], r["model"], r["controller"], r["profile"]): r for r in res.rows}
    out = []
    for (pl, model, ctl, prof), r in by.items():
        if pl == "clean" or model != "paper" or (pl, "extended", ctl, prof) not in by:
            continue
        e = by[(pl, "extended", ctl, prof)]
        out.append({"plant": pl, "controller": ctl, "profile": prof, "rmse_paper_m": r["rmse_m"],
                    "rmse_extended_m": e["rmse_m"], "ratio": r["rmse_m"] / e["rmse_m"]})
    return out


def margin_lines(res: StudyResult, pm_deg: float = 55.0, gm: float = 2.5) -> list:
    """One sentence per PI design that misses the tuning's margins (``tune_pi(best_effort=True)``)."""
    return [f"PI gains for the {m} model, {pr}: no crossover meets phase margin >= {pm_deg:g} deg and gain margin "
            f">= {gm:g}; the closest stable design is used (phase margin {g.phase_margin_deg:.1f} deg, gain margin "
            f"{g.gain_margin:.2f})." for (m, pr), g in res.gains.items()
            if g.phase_margin_deg < pm_deg or g.gain_margin < gm]


def solve_stats(solve_s) -> dict:
    """median, p95, max [s] and the number of steps of the MPC's per-step solve times after warm-up (None when
    there are none)."""
    solve = np.asarray(solve_s, dtype=float)
    if solve.size == 0:
        return {"median": None, "p95": None, "max": None, "steps": 0}
    return {"median": float(np.median(solve)), "p95": float(np.percentile(solve, 95)), "max": float(np.max(solve)),
            "steps": int(solve.size)}


def solve_time_line(res: StudyResult, period_s: float) -> str:
    """The report's sentence on the MPC's solve times: the first call (compilation / warm-up) apart."""
    st = solve_stats(res.solve_s)
    first = ("–" if res.first_call_s is None else f"{res.first_call_s:.2f} s")
    if st["steps"] == 0:
        return f"MPC first call (compilation / warm-up, not a control step): {first}; no further steps."
    return (f"MPC first call (numba compilation or cache loading: warm-up, not a control step): {first}. Solve time "
            f"per control step after it: median {1e3 * st['median']:.2f} ms, 95th percentile "
            f"{1e3 * st['p95']:.2f} ms, max {1e3 * st['max']:.2f} ms, against the control period "
            f"{1e3 * period_s:g} ms ({st['steps']} steps).")


def mpc_state_line(s: StudySettings) -> str:
    """The report's sentence on what the MPC knows of the plant's state."""
    if s.estimator == "none":
        return "MPC state: the plant's exact current, displacement reading and velocity every control period."
    return (f"MPC state ({s.mpc_name}): an extended Kalman filter on the MPC's model (harness.control.estimator) "
            f"from the plant's displacement reading and current plus white noise at {s.noise_factor:g}x the rig's "
            "noise floors; the velocity and every other state are estimated"
            + ("; offset-free: the filter's input disturbances (voltage offset, force gain, saturation offset) are "
               "in the MPC's prediction." if s.offset_free else "."))


def write_control_report(out: Path, res: StudyResult, s: StudySettings) -> list:
    """Write the figures, control.md, control_metrics.csv and control.json into ``out``; returns the paths."""
    out = Path(out)
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    p = s.base
    written = [plot_operating_map(fig_dir / "operating_map.png", p, [p.r0 * f for f in (0.33, 0.55, 0.78, 1.0, 1.22)],
                                  sample=s.sample),
               plot_linearization(fig_dir / "linearization.png", p,
                                  [0.2 * res.x_pull_in_m, 0.5 * res.x_pull_in_m, 0.9 * res.x_pull_in_m],
                                  sample=s.sample)]
    plants = sorted({k[0] for k in res.runs}, key=lambda n: n != "clean")
    profiles = sorted({k[3] for k in res.runs}, reverse=True)
    for pl in plants:
        for prof in profiles:
            written.append(plot_loop(fig_dir / f"loop_{pl}_{prof}.png", res, pl, prof, sample=s.sample))
    with open(out / "control_metrics.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["plant", "model", "controller", "profile", *METRIC_COLUMNS])
        for r in res.rows:
            w.writerow([r["plant"], r["model"], r["controller"], r["profile"], *(repr(r[c]) for c in METRIC_COLUMNS)])
    written.append(out / "control_metrics.csv")
    gains = {f"{m}/{pr}": {"Kp_V_per_m": g.Kp, "Ki_V_per_m_s": g.Ki, "Kd_V_s_per_m": g.Kd, "Tf_s": g.Tf,
                           "Tt_s": g.Tt, "crossover_rad_per_s": g.wc_rad_s, "phase_margin_deg": g.phase_margin_deg,
                           "gain_margin": g.gain_margin} for (m, pr), g in res.gains.items()}
    doc = {"sample": s.sample, "x_pull_in_m": res.x_pull_in_m, "V_pull_in_V": res.V_pull_in_V, "gap_m": p.r0,
           "holdable_range": {name: {"x_holdable_m": x, "V_at_x_holdable_V": V, "limited_by": lim}
                              for name, (x, V, lim) in res.holdable.items()},
           "setpoints_clipped": list(res.clipped), "pi_gains": gains,
           "mpc_first_call_s": res.first_call_s,
           "mpc_solve_time_s": solve_stats(res.solve_s) | {"control_period": s.mpc.dt_s},
           "runs": res.rows, "improvement": improvement_rows(res), "synthetic": True}
    (out / "control.json").write_text(json.dumps(doc, indent=2) + "\n")
    written.append(out / "control.json")
    imp = improvement_rows(res)
    md = [
        "# Closed-loop control of the actuator (synthetic plant: the actuator FMU)",
        "",
        f"Sample: {s.sample}. "
        f"Gap {1e3 * p.r0:g} mm: open-loop pull-in at x = {1e3 * res.x_pull_in_m:.3f} mm, V = "
        f"{res.V_pull_in_V:.2f} V (figures/operating_map.png). Voltage limits [{s.mpc.V_min_V:g}, "
        f"{s.mpc.V_max_V:g}] V; MPC no-contact margin {1e3 * s.mpc.margin_m:g} mm "
        f"(x <= {1e3 * (p.r0 - s.mpc.margin_m):g} mm).",
        "",
        f"Controllers: PI + static-inverse feed-forward in mpc_controller.fmu at {1e3 * s.pi_dt_s:g} ms "
        f"(gains from the linearization, control.json `pi_gains`); nonlinear MPC at {1e3 * s.mpc.dt_s:g} ms, "
        f"horizon {s.mpc.horizon} periods, blocks {list(s.mpc.blocks)}, predicting with the FMU's own integrator.",
        mpc_state_line(s),
        solve_time_line(res, s.mpc.dt_s),
        *margin_lines(res),
        "",
        "Profiles: `stroke` = drug-pump trapezoid "
        f"0 -> {1e3 * s.stroke_m:g} mm at {s.freq_Hz:g} Hz; `staircase` = setpoints at 25, 50, 70, 85, 95 % of "
        "the pull-in displacement, 0.3 s each. Overshoot and settling (band 20 um) over the first half of "
        "each hold after a rise.",
        "",
        "Holdable range at V <= " + f"{s.mpc.V_max_V:g} V (the largest stroke a voltage up to the limit holds in "
        "a stable steady state): " + "; ".join(f"{n} plant {1e3 * x:.3f} mm at {V:.3g} V ({lim})"
                                                for n, (x, V, lim) in res.holdable.items()) + ".",
        "",
        *([f"**Setpoints clipped** to the plant's holdable range: {c}." for c in res.clipped] + [""]
          if res.clipped else []),
        _table(res.rows),
        "",
    ]
    if imp:
        md += ["## The diagnosis pays off in control", "",
               f"Plant with the effect(s) `{s.plant_name}`; controllers built on the paper's model vs on the "
               "extended model (paper + the effect's parameters).", "",
               "| controller | profile | RMSE paper model [um] | RMSE extended model [um] | improvement |",
               "|---|---|---|---|---|"]
        md += [f"| {r['controller']} | {r['profile']} | {_f(1e6 * r['rmse_paper_m'])} | "
               f"{_f(1e6 * r['rmse_extended_m'])} | {r['ratio']:.2f}x |" for r in imp]
        md.append("")
    md += ["Figures: " + ", ".join(f"`figures/{q.name}`" for q in written if q.suffix == ".png"), ""]
    (out / "control.md").write_text("\n".join(md))
    written.append(out / "control.md")
    return written
