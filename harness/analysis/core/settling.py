"""Step-response metrics: 2 % settling time (also of many responses at once, and robust to noise),
settling-time error STE = |Ts_sim - Ts_meas| and the step metrics of tests T2-T5 and T8
(paper sections 3 and 6). Public through :mod:`harness.analysis.core.metrics`.

Settling time on noisy data
---------------------------
The settling time is the time, measured from the step instant, after which the
response stays inside the band ``|y - y_final| <= band * |y_final - y0|`` until
the end of the record. The crossing into the band is located by linear
interpolation between the last sample outside the band and the next one.

With sensor noise of 1-3 % of the step the raw samples leave a 2 % band at
random until the end of the record, so a pointwise test reports the end of the
record (or "never settles"). :func:`settling_time` therefore accepts
``smooth_s``: the band test is applied to a *centered moving mean* (default) or
median of the record over a window of ``smooth_s`` seconds (reflecting edges;
the band is tested up to half a window before the end of the record, where the
whole window still fits). A centered n-sample mean shrinks white noise by
1/sqrt(n) and does not delay the response. :func:`settling_time_robust` chooses the window from the noise
level sigma: the smallest odd n with ``sigma / sqrt(n) <= band*|step| / margin``
(``margin`` = 5 by default: the last exit is the maximum over many
filtered-noise values, so with 3 or 4 a late spurious exit happens now and
then), capped at 20 % of the post-step record. sigma is estimated from the
record (MAD of first differences / sqrt(2)) when not given. The final level is
estimated on the settled part of the record (provisional: mean of the second
half after the step; then the mean from ``t_step + Ts + window`` to the end,
and the test repeated): the mean of the last 10 % alone has a noise of
sigma/sqrt(0.1 N) that shifts the band and caused late spurious exits when the
noise was 5-6 % of the step (the rig's smallest T2 steps).

The moving mean changes the response it smooths: for a first-order step it
delays the band entry by tau*ln(sinh(x)/x), x = window/(2 tau) (about +8 % of
Ts for noise of 3 % of the step at 1 kHz, tau = 20 ms), and it damps
oscillations whose period is not much longer than the window. Therefore
:func:`settling_time_error` (with ``noise_sigma``) and :func:`step_metrics`
apply the *same* window to the measured and the simulated response: both are
judged by the same functional, and a simulation equal to the noise-free truth
gives STE near 0 (simulated check, first- and second-order steps with
Ts = 60-80 ms, noise 1-3 % of the step at 1 kHz, 300 seeds each: median STE
<= 3 ms, 99 % < 16 ms; for a lightly damped response (zeta = 0.4) whose
oscillation peaks sit near the band edge, jumps of up to half an oscillation
period, ~50 ms, as for any settling time; rig-like T2 data with noise 6 % of the
step: 99 % < 4 ms). To judge a simulated population the same way use
``settling_times(t, Y_sim, t_step=..., smooth_s=w, settled_final=True)`` with
``w = smoothing_window_s(t, y_meas, t_step=..., noise_sigma=...)`` and compare
with ``settling_time_robust(t, y_meas, ...)``: comparing a smoothed measured Ts
with an unsmoothed simulated one is biased (at noise 6 % of the step the window
is ~0.24 s and the smoothed Ts about twice the raw one). A centered median
(``smooth_method='median'``) leaves a clean monotone response unchanged but was clearly worse on noisy data
(late spurious exits, and it flattens overshoots). If the window hits the cap
the noise may still defeat the test (result near the end of the record, or nan).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.ndimage import median_filter, uniform_filter1d

from harness.analysis.core.signals import as_signals, as_time, as_vector, check_same_shape, on_grid, rmse
from harness.data.protocol import sample_period

__all__ = ["StepLevels", "WindowRule", "settling_time", "settling_times", "settling_time_robust", "resolvable_band",
           "settling_time_error", "smoothing_window_s", "smoothing_samples", "estimate_noise_sigma", "step_metrics"]


@dataclass(frozen=True)
class StepLevels:
    """Known levels of a step response [unit of y]: y0 (initial) and y_final (final); None: estimated
    from the record (y0: mean before the step, else the first sample; y_final: see the functions).
    For :func:`settling_times` each may also be one value per response."""
    y0: Any = None
    y_final: Any = None


@dataclass(frozen=True)
class WindowRule:
    """How :func:`smoothing_window_s` sizes the moving mean: ``margin`` standard deviations of the
    filtered noise kept inside the band, at most ``max_fraction`` of the post-step samples."""
    margin: float = 5.0
    max_fraction: float = 0.2


_NO_LEVELS = StepLevels()


# --------------------------------------------------------------------------- smoothing
def _window_samples(t: np.ndarray, smooth_s: float) -> int:
    """Odd number of samples spanning about ``smooth_s`` seconds (>= 1)."""
    n = int(round(smooth_s / sample_period(t)))
    n = max(n, 1)
    return n if n % 2 == 1 else n + 1


def smoothing_samples(t: np.ndarray, smooth_s: float | None) -> int:
    """Odd moving-mean window in samples that the band test uses for a window of ``smooth_s`` [s]
    on the grid t [s]: about smooth_s / median sample period, at most the record (1: no smoothing)."""
    if smooth_s is None or smooth_s <= 0:
        return 1
    N = t.size
    return max(min(_window_samples(t, smooth_s), N if N % 2 == 1 else N - 1), 1)


def _smooth(t: np.ndarray, y: np.ndarray, smooth_s: float | None,
            method: str) -> tuple[np.ndarray, int]:
    """Centered moving mean/median along the last axis over about ``smooth_s`` seconds.

    Returns the smoothed array and the window in samples (1: no smoothing).
    """
    if method not in ("mean", "median"):
        raise ValueError(f"smooth_method: expected 'median' or 'mean', got {method!r}")
    n = smoothing_samples(t, smooth_s)
    if n <= 1:
        return y, 1
    if method == "median":
        size = (1,) * (y.ndim - 1) + (n,)
        return median_filter(y, size=size, mode="reflect"), n
    return uniform_filter1d(y, size=n, axis=-1, mode="reflect"), n


def estimate_noise_sigma(y: Any) -> float:
    """Robust estimate of white measurement noise std [unit of y].

    1.4826 * MAD(diff(y)) / sqrt(2): first differences remove the slow signal,
    the median absolute deviation ignores the few large differences of the
    transient.
    """
    ya = as_vector(y, "y", min_len=3)
    d = np.diff(ya)
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))


# --------------------------------------------------------------------------- settling time
def _step_levels(t, y, t_step, y0, y_final):
    if t_step is None:
        t_step = float(t[0])
    if y_final is None:
        n_tail = max(1, int(math.ceil(0.1 * y.size)))
        y_final = float(np.mean(y[-n_tail:]))
    if y0 is None:
        pre = t < t_step
        y0 = float(np.mean(y[pre])) if np.any(pre) else float(y[0])
    return float(t_step), float(y0), float(y_final)


def _row_levels(t, Y, t_step, y0, y_final):
    """Per-row y0 and y_final (defaults as in :func:`settling_time`) as 1-D arrays."""
    m, N = Y.shape
    if y_final is None:
        n_tail = max(1, int(math.ceil(0.1 * N)))
        yf = Y[:, -n_tail:].mean(axis=1)
    else:
        yf = np.broadcast_to(np.asarray(y_final, dtype=float), (m,)).copy()
    if y0 is None:
        pre = t < t_step
        y0a = Y[:, pre].mean(axis=1) if np.any(pre) else Y[:, 0].copy()
    else:
        y0a = np.broadcast_to(np.asarray(y0, dtype=float), (m,)).copy()
    return y0a, yf


def _settling_core(t, Ys, n_win, t_step, y0, yf, band):
    """Vectorized band test on already smoothed rows ``Ys`` (m, N); NaN rules as documented."""
    m, N = Ys.shape
    out = np.full(m, np.nan)
    tol = band * np.abs(yf - y0)
    last = N - 1 - n_win // 2
    post = np.flatnonzero(t[: last + 1] >= t_step)
    if post.size == 0:
        return out
    p0, L = int(post[0]), post.size
    excess = np.abs(Ys[:, p0:p0 + L] - yf[:, None]) - tol[:, None]   # > 0: outside the band
    outside = excess > 0
    any_out = outside.any(axis=1)
    k = L - 1 - np.argmax(outside[:, ::-1], axis=1)                    # last outside (if any)
    ok = tol > 0
    out[ok & ~any_out] = 0.0
    rows = np.flatnonzero(ok & any_out & (k < L - 1))
    if rows.size:
        kk = k[rows]
        e_i = excess[rows, kk]
        e_j = excess[rows, kk + 1]
        frac = e_i / (e_i - e_j)
        ti, tj = t[p0 + kk], t[p0 + kk + 1]
        out[rows] = np.maximum(ti + frac * (tj - ti) - t_step, 0.0)
    return out


def _settling_many(t, Y, band, levels: StepLevels, t_step, smooth_s, smooth_method, settled_final):
    """Settling times of the rows of Y (validated inputs); see :func:`settling_times`."""
    y0, y_final = levels.y0, levels.y_final
    if not (band > 0 and math.isfinite(band)):
        raise ValueError(f"band: must be a positive finite fraction, got {band!r}")
    t_step = float(t[0]) if t_step is None else float(t_step)
    if not math.isfinite(t_step):
        raise ValueError(f"t_step: must be finite, got {t_step!r}")
    y0a, yf = _row_levels(t, Y, t_step, y0, y_final)
    for name, v in (("y0", y0a), ("y_final", yf)):
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name}: must be finite")
    Ys, n_win = _smooth(t, Y, smooth_s, smooth_method)
    ts = _settling_core(t, Ys, n_win, t_step, y0a, yf, band)
    if not settled_final or y_final is not None:
        return ts
    # final level from the settled part: provisional = mean of the second half after the step
    post = np.flatnonzero(t >= t_step)
    if post.size < 2:
        return ts
    yf1 = Y[:, post[post.size // 2:]].mean(axis=1)
    ts1 = _settling_core(t, Ys, n_win, t_step, y0a, yf1, band)
    n_tail = int(math.ceil(0.1 * t.size))
    start = t_step + np.where(np.isfinite(ts1), ts1, np.inf) + (smooth_s or 0.0)
    mask = t[None, :] >= start[:, None]
    cnt = mask.sum(axis=1)
    use = cnt > n_tail
    if not use.any():
        return ts
    yf2 = yf.copy()
    yf2[use] = (Y[use] * mask[use]).sum(axis=1) / cnt[use]
    ts2 = _settling_core(t, Ys[use], n_win, t_step, y0a[use], yf2[use], band)
    ts = ts.copy()
    ts[use] = ts2
    return ts


def settling_time(
    t: Any,
    y: Any,
    band: float = 0.02,
    y0: float | None = None,
    y_final: float | None = None,
    t_step: float | None = None,
    smooth_s: float | None = None,
    smooth_method: str = "mean",
) -> float:
    """Settling time [s] of a step response.

    The time from the step instant ``t_step`` after which ``y`` stays within
    ``band * |y_final - y0|`` of ``y_final`` until the end of the record.

    Parameters
    ----------
    t : array_like [s]
        Strictly increasing sample times (approximately uniform if ``smooth_s`` is used).
    y : array_like [any unit, e.g. mm or N]
        Response samples.
    band : float
        Relative half-width of the band (0.02 = 2 % settling time).
    y0 : float, optional
        Initial level. Default: mean of the samples before ``t_step``, else ``y[0]``.
    y_final : float, optional
        Final level. Default: mean of the last 10 % of the samples (robust to noise).
    t_step : float, optional [s]
        Step instant. Default ``t[0]``. Only samples at ``t >= t_step`` are tested.
    smooth_s : float, optional [s]
        If given, the band test is applied to a centered moving mean (or median,
        ``smooth_method='median'``) of ``y`` over this window; the test then
        ends half a window before the end of the record (where the whole
        window still fits). Default: no smoothing (clean, e.g. simulated,
        data). See :func:`settling_time_robust` for noisy data.

    Returns
    -------
    float
        Settling time in s (0.0 if the response is inside the band from ``t_step``
        on). The entry into the band is interpolated linearly between samples.
        ``nan`` if the last sample is still outside the band (never settles within
        the record), if the step size ``y_final - y0`` is zero, or if no sample
        lies at or after ``t_step``.
    """
    ta, ya = as_signals(t, y=y)
    return float(_settling_many(ta, ya[None, :], band, StepLevels(y0, y_final), t_step, smooth_s,
                                smooth_method, False)[0])


def settling_times(
    t: Any,
    Y: Any,
    band: float = 0.02,
    levels: StepLevels | None = None,
    t_step: float | None = None,
    smooth_s: float | None = None,
    smooth_method: str = "mean",
    settled_final: bool = False,
) -> np.ndarray:
    """Vectorized :func:`settling_time` for many responses on one time grid.

    ``Y`` has shape (n_responses, n_samples) (a 1-D ``Y`` is one response).
    ``levels`` (:class:`StepLevels`): y0 and y_final each None (per-row defaults as in
    :func:`settling_time`), a scalar, or one value per row. ``settled_final=True`` estimates
    each row's final level on its settled part, as :func:`settling_time_robust` does
    (ignored if ``y_final`` is given). Row k of the result equals
    ``settling_time(t, Y[k], ...)`` (with ``settled_final``: the robust
    two-pass value for the same ``smooth_s``). Use it to judge a simulated
    population exactly like the measured response, e.g.
    ``settling_times(t, Y_sim, t_step=ts, smooth_s=w, settled_final=True)`` with
    ``w = smoothing_window_s(t, y_meas, ...)``.
    """
    ta = as_time(t, "t")
    Ya = np.asarray(Y, dtype=float)
    if Ya.ndim == 1:
        Ya = Ya[None, :]
    if Ya.ndim != 2:
        raise ValueError(f"Y: expected shape (n_responses, n_samples), got {Ya.shape}")
    if Ya.shape[1] != ta.size:
        raise ValueError(f"t and Y differ in length: {ta.size} vs {Ya.shape[1]} samples")
    if Ya.size == 0:
        raise ValueError("Y: empty array")
    if not np.all(np.isfinite(Ya)):
        raise ValueError("Y: non-finite value(s)")
    return _settling_many(ta, Ya, band, levels or _NO_LEVELS, t_step, smooth_s, smooth_method, settled_final)


def _settling_time_settled_final(t, y, band, levels: StepLevels, t_step, smooth_s, smooth_method):
    """Settling time for noisy records with y_final estimated on the settled part.

    Unless ``y_final`` is given: a provisional final level is the mean of the
    second half of the post-step samples; with it the settling time Ts1 is
    found; the final level is then the mean of all samples from
    ``t_step + Ts1 + smooth_s`` on (if that is more than the last 10 %; else,
    or if Ts1 is nan, the default tail mean) and the settling time is
    recomputed with it.
    """
    ta, ya = as_signals(t, y=y)
    return float(_settling_many(ta, ya[None, :], band, levels, t_step, smooth_s, smooth_method, True)[0])


def _noise_step_cap(ta, ya, t_step, noise_sigma, levels: StepLevels, rule: WindowRule) -> tuple[float, float, int]:
    """(noise sigma [unit of y], step |y_final - y0| [unit of y], largest moving-mean window in samples:
    ``rule.max_fraction`` of the post-step samples, at least 1) of a record; sigma estimated from the record
    when ``noise_sigma`` is None, ValueError unless it is finite and >= 0."""
    t_step, y0, y_final = _step_levels(ta, ya, t_step, levels.y0, levels.y_final)
    sigma = estimate_noise_sigma(ya) if noise_sigma is None else float(noise_sigma)
    if not (sigma >= 0 and math.isfinite(sigma)):
        raise ValueError(f"noise_sigma: must be a finite value >= 0, got {noise_sigma!r}")
    n_post = int(np.count_nonzero(ta >= t_step))
    return sigma, abs(y_final - y0), max(1, int(rule.max_fraction * n_post))


def smoothing_window_s(
    t: Any,
    y: Any,
    t_step: float | None = None,
    noise_sigma: float | None = None,
    band: float = 0.02,
    levels: StepLevels | None = None,
    rule: WindowRule = WindowRule(),
    smooth_method: str = "mean",
) -> float:
    """Moving-average window [s] that keeps noise of std ``noise_sigma`` inside the band.

    Smallest odd sample count n with ``k * sigma / sqrt(n) <= band*|step| / rule.margin``
    (k = 1 for the mean; k = sqrt(pi/2) = 1.2533 for ``smooth_method='median'``,
    the std of a median relative to a mean), capped at
    ``rule.max_fraction`` of the post-step samples (assumes roughly uniform
    sampling). Returns 0.0 (no smoothing) for noise-free data. ``noise_sigma``
    [unit of y] defaults to :func:`estimate_noise_sigma` of ``y``. ``levels``: known
    y0 / y_final (:class:`StepLevels`; default: estimated as in :func:`settling_time`).
    """
    ta, ya = as_signals(t, y=y)
    sigma, step, n_cap = _noise_step_cap(ta, ya, t_step, noise_sigma, levels or _NO_LEVELS, rule)
    tol = band * step
    if sigma == 0.0 or tol == 0.0:
        return 0.0
    if smooth_method not in ("mean", "median"):
        raise ValueError(f"smooth_method: expected 'median' or 'mean', got {smooth_method!r}")
    k = 1.0 if smooth_method == "mean" else math.sqrt(math.pi / 2.0)
    n = min(int(math.ceil((k * rule.margin * sigma / tol) ** 2)), n_cap)
    if n % 2 == 0:
        n += 1
    if n <= 1:
        return 0.0
    return n * sample_period(ta)


def resolvable_band(
    t: Any,
    y: Any,
    t_step: float | None = None,
    noise_sigma: float | None = None,
    band: float = 0.02,
    rule: WindowRule = WindowRule(),
) -> float:
    """The narrowest relative band [-] whose settling test the record's noise allows: ``band`` itself unless
    the moving mean of :func:`smoothing_window_s` hits its cap (``rule.max_fraction`` of the post-step
    samples), then ``margin * sigma / (sqrt(n_cap) * |y_final - y0|)`` (the band that ``margin`` standard
    deviations of the capped mean's noise fit in), so the test does not report "never settles" for a
    record whose noise, not its response, leaves a ``band`` test undecidable (very noisy or short records,
    small steps, low sample rates). ``noise_sigma`` [unit of y]: as in :func:`smoothing_window_s` (a value
    that is not finite and >= 0 raises ValueError, as there).
    """
    ta, ya = as_signals(t, y=y)
    sigma, step, n_cap = _noise_step_cap(ta, ya, t_step, noise_sigma, _NO_LEVELS, rule)
    if not (sigma > 0 and step > 0):
        return float(band)
    n_cap += 1 - n_cap % 2                     # odd, as the window
    return float(max(band, rule.margin * sigma / (math.sqrt(n_cap) * step)))


def settling_time_robust(
    t: Any,
    y: Any,
    t_step: float | None = None,
    noise_sigma: float | None = None,
    band: float = 0.02,
    levels: StepLevels | None = None,
    rule: WindowRule = WindowRule(),
    smooth_method: str = "mean",
) -> float:
    """Settling time [s] of a noisy step response.

    :func:`settling_time` on the centered moving mean of ``y`` over the window
    from :func:`smoothing_window_s` (chosen so that noise of std ``noise_sigma``,
    in the unit of ``y``, stays inside the band with ``rule.margin`` standard
    deviations of the filtered noise to spare). ``noise_sigma=None`` estimates
    it from the record. Unless ``levels.y_final`` is given, it is estimated on the
    settled part of the record (provisionally the second half after the step,
    then from ``t_step + Ts + window`` on, and the test repeated), so that its
    own noise does not shift the band.
    For noise-free data this equals :func:`settling_time`.
    The smoothing delays the band entry a little (see the module docstring);
    to compare with a simulation use :func:`settling_time_error` with
    ``noise_sigma``, which smooths both alike.
    """
    levels = levels or _NO_LEVELS
    w = smoothing_window_s(t, y, t_step=t_step, noise_sigma=noise_sigma, band=band, levels=levels, rule=rule,
                           smooth_method=smooth_method)
    return _settling_time_settled_final(t, y, band, levels, t_step, w or None, smooth_method)


def settling_time_error(
    t_meas: Any,
    y_meas: Any,
    t_sim: Any,
    y_sim: Any,
    noise_sigma: float | str | None = None,
    **kw: Any,
) -> float:
    """Settling-time error STE = |Ts_sim - Ts_meas| [s].

    ``kw`` (band, y0, y_final, t_step, smooth_s, smooth_method) are passed to
    :func:`settling_time` for both responses (y0/y_final, if given, apply to
    both; normally leave them to the per-response defaults). With
    ``noise_sigma`` (a std in the unit of ``y``, or ``"auto"`` to estimate it
    from ``y_meas``) the smoothing window is chosen by :func:`smoothing_window_s`
    on the measured record and the same window, and the same two-pass y_final
    estimate as :func:`settling_time_robust`, are applied to both responses
    (``smooth_s`` is then ignored). Returns ``nan`` if either response never settles.
    """
    kw = dict(kw)
    for tn, yn, tv, yv in (("t_meas", "y_meas", t_meas, y_meas), ("t_sim", "y_sim", t_sim, y_sim)):
        check_same_shape(as_time(tv, tn), as_vector(yv, yn), tn, yn)
    if noise_sigma is None:
        ts_m = settling_time(t_meas, y_meas, **kw)
        ts_s = settling_time(t_sim, y_sim, **kw)
        return float(abs(ts_s - ts_m))
    sigma = None if (isinstance(noise_sigma, str) and noise_sigma == "auto") else noise_sigma
    if isinstance(sigma, str):
        raise ValueError(f"noise_sigma: expected a number or 'auto', got {noise_sigma!r}")
    unknown = set(kw) - {"t_step", "band", "y0", "y_final", "smooth_method", "smooth_s"}
    if unknown:
        raise TypeError(f"settling_time_error: unexpected keyword(s) {sorted(unknown)}")
    band = kw.get("band", 0.02)
    method = kw.get("smooth_method", "mean")
    levels = StepLevels(kw.get("y0"), kw.get("y_final"))
    t_step = kw.get("t_step")
    w = smoothing_window_s(t_meas, y_meas, t_step=t_step, noise_sigma=sigma, band=band, levels=levels,
                           smooth_method=method) or None
    ts_m = _settling_time_settled_final(t_meas, y_meas, band, levels, t_step, w, method)
    ts_s = _settling_time_settled_final(t_sim, y_sim, band, levels, t_step, w, method)
    return float(abs(ts_s - ts_m))


def step_metrics(
    t: Any,
    y_meas: Any,
    y_sim: Any,
    t_step: float | None = None,
    noise_sigma: float | str | None = None,
    band: float = 0.02,
    unit: str = "mm",
    t_sim: Any = None,
) -> dict[str, float]:
    """RMSE and settling-time metrics of one step test (T2-T5 in mm, T8 in N).

    ``y_sim`` is on the grid ``t`` unless ``t_sim`` is given (then it is
    interpolated onto ``t``). ``noise_sigma`` (std of the measurement noise in
    ``unit``, or ``"auto"``) selects the robust settling time, with the same
    moving-mean window on both responses; ``None`` tests the raw samples.

    Returns a dict with keys ``rmse_<unit>``, ``ts_meas_s``, ``ts_sim_s``,
    ``ste_s`` (nan if either response never settles) and ``smooth_window_s``
    (0.0: raw samples tested).
    """
    ta, ym = as_signals(t, y_meas=y_meas)
    ys = on_grid(ta, t_sim, y_sim)
    smooth = None
    if noise_sigma is not None:
        sigma = None if noise_sigma == "auto" else float(noise_sigma)
        smooth = smoothing_window_s(ta, ym, t_step=t_step, noise_sigma=sigma, band=band) or None
    if noise_sigma is None:
        ts_m = settling_time(ta, ym, band=band, t_step=t_step)
        ts_s = settling_time(ta, ys, band=band, t_step=t_step)
    else:
        ts_m = _settling_time_settled_final(ta, ym, band, _NO_LEVELS, t_step, smooth, "mean")
        ts_s = _settling_time_settled_final(ta, ys, band, _NO_LEVELS, t_step, smooth, "mean")
    return {
        f"rmse_{unit}": rmse(ym, ys),
        "ts_meas_s": ts_m,
        "ts_sim_s": ts_s,
        "ste_s": float(abs(ts_s - ts_m)),
        "smooth_window_s": float(smooth or 0.0),
    }
