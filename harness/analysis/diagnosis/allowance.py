"""The held-out prediction allowance: the chi-square a held-out test gains from the fitted parameters' own uncertainty.

A held-out test can be far more sensitive to the parameters than the fit tests resolve them (a T6 that drives the
diaphragm near the coil face moves by hundreds of chi-square units for a 0.1 % change in Em). Per sample, the
covariance S of its log base parameters (and of the derived coil radius, with its prior) comes from its fit tests
alone, their noise and their own step instants (:func:`parameter_covariances`); the Jacobian J of each held-out
test's residuals then gives the mean tr(A S) and the variance 2 tr((A S)^2), A = J^T J, of the chi-square a
prediction error J d, d ~ N(0, S), adds (:func:`prediction_allowance`). A held-out step test also carries the
uncertainty of its own step instant, estimated from its current's RL rise (at 100 Hz, 1-2 samples on an 8 ms
rise: sd 0.8 ms), which moves its predicted rise (:func:`step_instant_allowance`), and a fit step test the part of
its own instant's uncertainty that the fitted parameters cannot take up (:func:`fit_instant_allowance`).
``ModelFit.structure`` subtracts the mean and adds the variance.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from harness.analysis.core.lsq import check_length

from .candidates import make_params
from .fitting import Evaluator, FitContext, ModelFit
from .jobs import JobOptions, residual_parts, run_jobs

#: central-difference step in the logarithms of the parameters
REL_STEP = 1e-4
#: central-difference step of a step instant, as a fraction of its standard uncertainty
STEP_INSTANT_STEP = 0.1


def points(ctx: FitContext, mf: ModelFit, i: int, xs) -> list:
    """Params of sample i at log parameter vectors xs = [its base vector, then the shared nuisance values]."""
    nb = len(mf.base[i])
    nuis = [d for d in ctx.nuisance if d.key in mf.shared]
    out = []
    for x in xs:
        sh = dict(mf.shared)
        sh.update({d.key: float(x[nb + j]) for j, d in enumerate(nuis)})
        out.append(make_params(ctx.samples[i], np.asarray(x[:nb], dtype=float), sh))
    return out


def _perturbed(ctx: FitContext, mf: ModelFit, rel_step: float):
    """Central-difference points of every sample: (jobs [(i, Params)], {i: (x0, [job index of +, of -] per
    parameter)})."""
    nuis = [d for d in ctx.nuisance if d.key in mf.shared]
    jobs, where = [], {}
    for i in range(len(ctx.samples)):
        x0 = np.concatenate([np.asarray(mf.base[i], dtype=float), [mf.shared[d.key] for d in nuis]])
        xs = []
        for k in range(x0.size):
            for sgn in (1.0, -1.0):
                x = x0.copy()
                x[k] += sgn * rel_step
                xs.append(x)
        where[i] = (x0, list(range(len(jobs), len(jobs) + len(xs))))
        jobs += [(i, p) for p in points(ctx, mf, i, xs)]
    return jobs, where


def _central_jacobian(values, idx: list, rel_step: float) -> np.ndarray:
    """Columns (v+ - v-) / (2 rel_step) of the vectors ``values`` (indexable by job index) at the +/- points
    ``idx`` of each parameter."""
    return np.column_stack([(values[idx[2 * k]] - values[idx[2 * k + 1]]) / (2 * rel_step)
                            for k in range(len(idx) // 2)])


def _instant_moves(ctx: FitContext, names) -> tuple:
    """The step instants of the step tests ``names`` moved by +/- h: (moved samples, [(sample index, test, sd, h, +
    index, - index)]).

    Every such test with an estimated instant uncertainty sd (``Series.sd_step_delay_s``) of every sample, its
    instant moved by h = :data:`STEP_INSTANT_STEP` sd (within its sample interval) each way."""
    moved, where = [], []
    for i, sd in enumerate(ctx.samples):
        for name in names:
            t = sd.tests.get(name)
            s = float(getattr(t, "sd_step_delay_s", 0.0) or 0.0)
            if t is None or not s > 0 or t.V_on is None:
                continue
            h = min(STEP_INSTANT_STEP * s, 0.45 * t.step_delay_s, 0.45 * (t.dt - t.step_delay_s))
            if not h > 1e-9:
                continue
            where.append((i, name, s, h, len(moved), len(moved) + 1))
            moved += [replace(sd, tests={**sd.tests, name: replace(t, step_delay_s=t.step_delay_s + sg * h)})
                      for sg in (1.0, -1.0)]
    return moved, where


def _instant_gradients(ctx: FitContext, mf: ModelFit) -> dict:
    """{sample index: [(sd, {(test, channel): g})]}: g = d (fit residuals) / d t of each fit step test's instant t
    (central differences of :func:`_instant_moves`, one simulation batch), sd its standard uncertainty [s]."""
    moved, where = _instant_moves(ctx, ctx.fit_names)
    if not moved:
        return {}
    ev = Evaluator(moved, ctx.fit_names, ctx.settings)
    parts = ev.parts([(k, mf.params[i]) for i, _, _, _, a, b in where for k in (a, b)])
    out = {}
    for q, (i, _, s, h, _, _) in enumerate(where):
        plus, minus = parts[2 * q], parts[2 * q + 1]
        g = {}
        for key in sorted(plus):
            check_length(f"sample {ctx.samples[i].sid}, test {key[0]}, signal {key[1]} with a moved step instant",
                         plus[key].size, minus[key].size)
            g[key] = (plus[key] - minus[key]) / (2.0 * h)
        out.setdefault(i, []).append((s, g))
    return out


def _covariances(ctx: FitContext, mf: ModelFit, jobs: list, where: dict, rel_step: float,
                 instants: bool = True) -> tuple:
    """(:func:`parameter_covariances`, :func:`fit_instant_allowance`) on the perturbed points of :func:`_perturbed`
    (computed once by the caller); the second is empty without ``instants``."""
    vecs = ctx.ev.vectors([[j] for j in jobs])
    nuis = [d for d in ctx.nuisance if d.key in mf.shared]
    grads = _instant_gradients(ctx, mf) if instants else {}
    out, fit_al = {}, {}
    for i, (x0, idx) in where.items():
        p, nb = x0.size, len(mf.base[i])
        Jf = _central_jacobian(vecs, idx, rel_step)
        info = Jf.T @ Jf
        for j, d in enumerate(nuis):
            if d.prior_sd:
                info[nb + j, nb + j] += 1.0 / d.prior_sd ** 2
        s2 = max(1.0, sum(c for c, _ in mf.fit_chi2[i].values()) / max(1, Jf.shape[0] - p))
        inv = np.linalg.pinv(info)
        cov = s2 * inv
        for s, parts in grads.get(i, ()):
            g = np.concatenate([parts[k] for k in sorted(parts)])    # the fit vector's layout (sorted keys)
            check_length(f"sample {ctx.samples[i].sid}, fit residuals of a moved step instant", Jf.shape[0], g.size)
            u = inv @ (Jf.T @ g)            # d (least-squares parameters) / d t, up to its sign
            cov = cov + (s * s) * np.outer(u, u)
            r, pos = g - Jf @ u, 0          # what the refit cannot take up: the residuals' own move per second
            for key in sorted(parts):
                a = float(np.sum(r[pos:pos + parts[key].size] ** 2)) * s * s
                pos += parts[key].size
                mu, var = fit_al.get(key, (0.0, 0.0))
                fit_al[key] = (mu + a, var + 2.0 * a * a)
        out[i] = (x0, cov)
    return out, fit_al


def parameter_covariances(ctx: FitContext, mf: ModelFit, rel_step: float = REL_STEP, instants: bool = True) -> dict:
    """{sample index: (x0, S)}: each sample's log base parameters followed by the shared nuisance ones (the
    derived coil radius) at ``mf``, and their covariance from its fit tests alone,
    S = s^2 (J_f^T J_f + P)^-1 + sum_t sd_t^2 u_t u_t^T:
    J_f the Jacobian of its fit-test residuals (noise units; central differences of ``rel_step``), P the
    nuisance's Gaussian prior, s^2 = max(1, chi2/dof). The effect parameters of ``mf`` are held fixed.

    ``instants``: the second term, the fit step tests' own step instants. Each instant t is estimated from its
    test's current within a sample interval with standard uncertainty sd_t (``Series.sd_step_delay_s``) and
    held in the fit; u_t = (J_f^T J_f + P)^-1 J_f^T g_t, g_t = d residuals / d t, is how far the least-squares
    parameters move per second of its error. Deep profile, session 16: at 478 Hz (T3) and 870 Hz (T5) it is 4x
    the noise's sd of L and 6x that of m, and without it a clean held-out T4 at 18 kHz read as structure
    (W21-D50, z 27)."""
    return _covariances(ctx, mf, *_perturbed(ctx, mf, rel_step), rel_step, instants=instants)[0]


def fit_instant_allowance(ctx: FitContext, mf: ModelFit, rel_step: float = REL_STEP) -> dict:
    """{(fit test, channel): (mean, variance)} of the chi-square that the fit step tests' own step instants add to
    the fit tests at the least-squares parameters (summed over the samples).

    An instant t, estimated from its test's current with standard uncertainty sd (``Series.sd_step_delay_s``) and
    held in the fit, moves the residuals by g d for an error d; the refit takes up the part J_f u (u as in
    :func:`parameter_covariances`), and r = g - J_f u remains: d ~ N(0, sd^2) adds sd^2 |r_k|^2 to the expected
    chi-square of each (test, channel) k and 2 (sd^2 |r_k|^2)^2 to its variance. Deep profile, session 16: a clean
    628 Hz blocked-force T8 whose instant the current put 1.8 sd early (0.16 ms), where the force pins it to 10 us,
    read as structure the model misses (W40-D60, T8 force z 12; chi-square 1620 above its count at the true
    parameters)."""
    return _covariances(ctx, mf, *_perturbed(ctx, mf, rel_step), rel_step)[1]


def heldout_parts(ctx: FitContext, jobs) -> list:
    """Held-out residual parts {(test, channel): z} of [(sample index, Params)] (one simulation batch)."""
    sims = run_jobs([(ctx.samples[i], p) for i, p in jobs], ctx.heldout_names,
                    JobOptions(full=True, max_rate_hz=ctx.settings.max_rate_hz))
    return [residual_parts(ctx.samples[i], s, ctx.heldout_names, ctx.settings.sweep_robust_c)
            for (i, _), s in zip(jobs, sims)]


def prediction_allowance(ctx: FitContext, mf: ModelFit, rel_step: float = REL_STEP) -> dict:
    """{(test, channel): (mean, variance)} of the chi-square that the uncertainty of the fitted parameters adds to
    the held-out tests of model ``mf``, and that the step instants add to the held-out
    (:func:`step_instant_allowance`) and the fit tests (:func:`fit_instant_allowance`) (linearized; summed over the
    samples).

    Per sample, S from :func:`parameter_covariances` (its base parameters and the derived coil radius, from its
    fit tests), J_h the Jacobian of a held-out test's residuals: a prediction error J_h d, d ~ N(0, S), adds
    tr(A S) to that test's expected chi-square and 2 tr((A S)^2) to its variance (A = J_h^T J_h). A held-out
    test far more sensitive to the parameters than the fit tests resolve them (a diaphragm driven near the coil
    face, where a 0.1 % error in Em moves T6 by many noise floors) is then not taken for structure the model
    misses. Central differences of ``rel_step`` in the logarithms; the effect parameters of ``mf`` are held at
    their values (their uncertainty is not allowed for)."""
    jobs, where = _perturbed(ctx, mf, rel_step)
    covs, fit_al = _covariances(ctx, mf, jobs, where, rel_step)
    held = heldout_parts(ctx, jobs)
    out = {**fit_al, **step_instant_allowance(ctx, mf)}
    for i, (x0, idx) in where.items():
        cov = covs[i][1]
        for key in held[idx[0]]:
            Jh = _central_jacobian({q: held[q][key] for q in idx}, idx, rel_step)
            AS = (Jh.T @ Jh) @ cov
            mu, var = out.get(key, (0.0, 0.0))
            out[key] = (mu + float(np.trace(AS)), var + 2.0 * float(np.trace(AS @ AS)))
    return out


def step_instant_allowance(ctx: FitContext, mf: ModelFit) -> dict:
    """{(held-out test, channel): (mean, variance)} of the chi-square that the uncertainty of the held-out step tests'
    own step instants adds (summed over the samples): the instant t is estimated from the test's current within its
    sample interval with standard uncertainty s (``Series.sd_step_delay_s``); with j = d residuals / d t (central
    differences of :data:`STEP_INSTANT_STEP` s, within the interval), an error d ~ N(0, s^2) adds |j|^2 s^2 to the
    expected chi-square and 2 (|j|^2 s^2)^2 to its variance. Deep profile, session 13: a clean 100 Hz T4 whose instant
    lay 1.8 ms (2.3 sd) late read as structure (z 11.3 on one sample)."""
    moved, where = _instant_moves(ctx, ctx.heldout_names)
    opts = JobOptions(full=True, max_rate_hz=ctx.settings.max_rate_hz)
    out = {}
    for name in ctx.heldout_names:          # one simulation batch per test, of that test alone
        mine = [w for w in where if w[1] == name]
        if not mine:
            continue
        sims = run_jobs([(moved[k], mf.params[i]) for i, _, _, _, a, b in mine for k in (a, b)], [name], opts)
        for q, (i, _, s, h, a, b) in enumerate(mine):
            plus, minus = (residual_parts(moved[k], sims[2 * q + r], [name], ctx.settings.sweep_robust_c)
                           for r, k in enumerate((a, b)))
            for key in plus:
                d = float(np.sum(((plus[key] - minus[key]) / (2.0 * h)) ** 2)) * s * s
                mu, var = out.get(key, (0.0, 0.0))
                out[key] = (mu + d, var + 2.0 * d * d)
    return out
