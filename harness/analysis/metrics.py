"""Error metrics used to identify and validate the model (paper sections 3 and 6).

All functions are pure numpy/scipy and unit-agnostic: they return results in
the units of their inputs (times in s, displacements in mm, forces in N, ...).
The names of the dictionary keys returned by :func:`step_metrics` and
:func:`sine_metrics` carry units, matching the column names of
:mod:`harness.report.tables`.

Metrics
-------
* RMSE between measured and simulated samples (:func:`rmse`), and over the
  gaps that a measured and a simulated sweep have in common (:func:`sweep_rmse`,
  tests T1/T7).
* 2 % settling time of a step response (:func:`settling_time`; vectorized over
  many responses, e.g. an optimizer's population: :func:`settling_times`) and
  the settling-time error STE = |Ts_sim - Ts_meas| (:func:`settling_time_error`),
  tests T2-T5.
* Amplitude ratio and phase shift of a sinusoidal response (:func:`sine_amplitude_phase`,
  :func:`amplitude_ratio_phase_shift`), test T6.

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
from typing import Any

import numpy as np
from scipy.ndimage import median_filter, uniform_filter1d

__all__ = [
    "rmse",
    "settling_time",
    "settling_time_robust",
    "settling_times",
    "settling_time_error",
    "smoothing_window_s",
    "estimate_noise_sigma",
    "sine_amplitude_phase",
    "amplitude_ratio_phase_shift",
    "sweep_rmse",
    "step_metrics",
    "sine_metrics",
]

GAP_MATCH_TOL_MM = 1e-9  # gaps closer than this [mm] are the same gap in sweep_rmse


# --------------------------------------------------------------------------- input checks
def _vector(x: Any, name: str, *, min_len: int = 1) -> np.ndarray:
    """Return x as a finite 1-D float array or raise ValueError naming ``name``."""
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: cannot convert to a float array ({exc})") from None
    if a.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D array, got shape {a.shape}")
    if a.size < min_len:
        if a.size == 0:
            raise ValueError(f"{name}: empty array")
        raise ValueError(f"{name}: need at least {min_len} samples, got {a.size}")
    if not np.all(np.isfinite(a)):
        bad = int(np.flatnonzero(~np.isfinite(a))[0])
        raise ValueError(f"{name}: non-finite value {a[bad]!r} at index {bad}")
    return a


def _same_shape(a: np.ndarray, b: np.ndarray, name_a: str, name_b: str) -> None:
    if a.shape != b.shape:
        raise ValueError(f"{name_a} and {name_b} differ in shape: {a.shape} vs {b.shape}")


def _time(t: Any, name: str = "t", *, min_len: int = 2) -> np.ndarray:
    ta = _vector(t, name, min_len=min_len)
    if np.any(np.diff(ta) <= 0):
        raise ValueError(f"{name}: sample times must be strictly increasing")
    return ta


def _signals(t: Any, *, min_len: int = 2, **ys: Any) -> tuple[np.ndarray, ...]:
    """(t, y, ...) checked: t strictly increasing with at least ``min_len`` samples, each
    named y (``y_meas=...``) a finite 1-D array of t's shape; errors name the argument."""
    ta = _time(t, "t", min_len=min_len)
    arrays = [_vector(y, name) for name, y in ys.items()]
    for name, a in zip(ys, arrays):
        _same_shape(ta, a, "t", name)
    return (ta, *arrays)


def _frequency(frequency_hz: float) -> None:
    if not (frequency_hz > 0 and math.isfinite(frequency_hz)):
        raise ValueError(f"frequency_hz: must be positive and finite, got {frequency_hz!r}")


# --------------------------------------------------------------------------- RMSE
def rmse(measured: Any, simulated: Any) -> float:
    """Root-mean-square error sqrt(mean((simulated - measured)^2)).

    Parameters
    ----------
    measured, simulated : array_like, same shape (1-D)
        Samples at the same instants, in the same unit (e.g. mm or N).

    Returns
    -------
    float
        RMSE in the unit of the inputs.

    Raises
    ------
    ValueError
        If an array is empty or holds NaN/inf (the message names the argument),
        or if the shapes differ.
    """
    m = _vector(measured, "measured")
    s = _vector(simulated, "simulated")
    _same_shape(m, s, "measured", "simulated")
    return float(np.sqrt(np.mean((s - m) ** 2)))


# --------------------------------------------------------------------------- smoothing
def _median_dt(t: np.ndarray) -> float:
    return float(np.median(np.diff(t)))


def _window_samples(t: np.ndarray, smooth_s: float) -> int:
    """Odd number of samples spanning about ``smooth_s`` seconds (>= 1)."""
    n = int(round(smooth_s / _median_dt(t)))
    n = max(n, 1)
    return n if n % 2 == 1 else n + 1


def _smooth(t: np.ndarray, y: np.ndarray, smooth_s: float | None,
            method: str) -> tuple[np.ndarray, int]:
    """Centered moving mean/median along the last axis over about ``smooth_s`` seconds.

    Returns the smoothed array and the window in samples (1: no smoothing).
    """
    if method not in ("mean", "median"):
        raise ValueError(f"smooth_method: expected 'median' or 'mean', got {method!r}")
    if smooth_s is None or smooth_s <= 0:
        return y, 1
    N = y.shape[-1]
    n = min(_window_samples(t, smooth_s), N if N % 2 == 1 else N - 1)
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
    ya = _vector(y, "y", min_len=3)
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


def _settling_many(t, Y, band, y0, y_final, t_step, smooth_s, smooth_method, settled_final):
    """Settling times of the rows of Y (validated inputs); see :func:`settling_times`."""
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
    ta, ya = _signals(t, y=y)
    return float(_settling_many(ta, ya[None, :], band, y0, y_final, t_step, smooth_s,
                                smooth_method, False)[0])


def settling_times(
    t: Any,
    Y: Any,
    band: float = 0.02,
    y0: Any = None,
    y_final: Any = None,
    t_step: float | None = None,
    smooth_s: float | None = None,
    smooth_method: str = "mean",
    settled_final: bool = False,
) -> np.ndarray:
    """Vectorized :func:`settling_time` for many responses on one time grid.

    ``Y`` has shape (n_responses, n_samples) (a 1-D ``Y`` is one response).
    ``y0``/``y_final``: None (per-row defaults as in :func:`settling_time`), a
    scalar, or one value per row. ``settled_final=True`` estimates each row's
    final level on its settled part, as :func:`settling_time_robust` does
    (ignored if ``y_final`` is given). Row k of the result equals
    ``settling_time(t, Y[k], ...)`` (with ``settled_final``: the robust
    two-pass value for the same ``smooth_s``). Use it to judge a simulated
    population exactly like the measured response, e.g.
    ``settling_times(t, Y_sim, t_step=ts, smooth_s=w, settled_final=True)`` with
    ``w = smoothing_window_s(t, y_meas, ...)``.
    """
    ta = _time(t, "t")
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
    return _settling_many(ta, Ya, band, y0, y_final, t_step, smooth_s, smooth_method,
                          settled_final)


def _settling_time_settled_final(t, y, band, y0, y_final, t_step, smooth_s, smooth_method):
    """Settling time for noisy records with y_final estimated on the settled part.

    Unless ``y_final`` is given: a provisional final level is the mean of the
    second half of the post-step samples; with it the settling time Ts1 is
    found; the final level is then the mean of all samples from
    ``t_step + Ts1 + smooth_s`` on (if that is more than the last 10 %; else,
    or if Ts1 is nan, the default tail mean) and the settling time is
    recomputed with it.
    """
    ta, ya = _signals(t, y=y)
    return float(_settling_many(ta, ya[None, :], band, y0, y_final, t_step, smooth_s,
                                smooth_method, True)[0])


def smoothing_window_s(
    t: Any,
    y: Any,
    t_step: float | None = None,
    noise_sigma: float | None = None,
    band: float = 0.02,
    y0: float | None = None,
    y_final: float | None = None,
    margin: float = 5.0,
    max_fraction: float = 0.2,
    smooth_method: str = "mean",
) -> float:
    """Moving-average window [s] that keeps noise of std ``noise_sigma`` inside the band.

    Smallest odd sample count n with ``k * sigma / sqrt(n) <= band*|step| / margin``
    (k = 1 for the mean; k = sqrt(pi/2) = 1.2533 for ``smooth_method='median'``,
    the std of a median relative to a mean), capped at
    ``max_fraction`` of the post-step samples (assumes roughly uniform
    sampling). Returns 0.0 (no smoothing) for noise-free data. ``noise_sigma``
    [unit of y] defaults to :func:`estimate_noise_sigma` of ``y``.
    """
    ta, ya = _signals(t, y=y)
    t_step, y0, y_final = _step_levels(ta, ya, t_step, y0, y_final)
    sigma = estimate_noise_sigma(ya) if noise_sigma is None else float(noise_sigma)
    if not (sigma >= 0 and math.isfinite(sigma)):
        raise ValueError(f"noise_sigma: must be a finite value >= 0, got {noise_sigma!r}")
    tol = band * abs(y_final - y0)
    if sigma == 0.0 or tol == 0.0:
        return 0.0
    if smooth_method not in ("mean", "median"):
        raise ValueError(f"smooth_method: expected 'median' or 'mean', got {smooth_method!r}")
    k = 1.0 if smooth_method == "mean" else math.sqrt(math.pi / 2.0)
    n = int(math.ceil((k * margin * sigma / tol) ** 2))
    n_post = int(np.count_nonzero(ta >= t_step))
    n = min(n, max(1, int(max_fraction * n_post)))
    if n % 2 == 0:
        n += 1
    if n <= 1:
        return 0.0
    return n * _median_dt(ta)


def settling_time_robust(
    t: Any,
    y: Any,
    t_step: float | None = None,
    noise_sigma: float | None = None,
    band: float = 0.02,
    y0: float | None = None,
    y_final: float | None = None,
    margin: float = 5.0,
    smooth_method: str = "mean",
) -> float:
    """Settling time [s] of a noisy step response.

    :func:`settling_time` on the centered moving mean of ``y`` over the window
    from :func:`smoothing_window_s` (chosen so that noise of std ``noise_sigma``,
    in the unit of ``y``, stays inside the band with ``margin`` standard
    deviations of the filtered noise to spare). ``noise_sigma=None`` estimates
    it from the record. Unless ``y_final`` is given, it is estimated on the
    settled part of the record (provisionally the second half after the step,
    then from ``t_step + Ts + window`` on, and the test repeated), so that its
    own noise does not shift the band.
    For noise-free data this equals :func:`settling_time`.
    The smoothing delays the band entry a little (see the module docstring);
    to compare with a simulation use :func:`settling_time_error` with
    ``noise_sigma``, which smooths both alike.
    """
    w = smoothing_window_s(t, y, t_step=t_step, noise_sigma=noise_sigma, band=band,
                           y0=y0, y_final=y_final, margin=margin, smooth_method=smooth_method)
    return _settling_time_settled_final(t, y, band, y0, y_final, t_step, w or None, smooth_method)


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
        _same_shape(_time(tv, tn), _vector(yv, yn), tn, yn)
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
    args = dict(t_step=kw.get("t_step"), band=band, y0=kw.get("y0"), y_final=kw.get("y_final"))
    w = smoothing_window_s(t_meas, y_meas, noise_sigma=sigma, smooth_method=method, **args) or None
    ts_m = _settling_time_settled_final(t_meas, y_meas, band, args["y0"], args["y_final"],
                                        args["t_step"], w, method)
    ts_s = _settling_time_settled_final(t_sim, y_sim, band, args["y0"], args["y_final"],
                                        args["t_step"], w, method)
    return float(abs(ts_s - ts_m))


# --------------------------------------------------------------------------- sinusoids
def _wrap(phi: float) -> float:
    """Wrap an angle [rad] to (-pi, pi]."""
    w = math.remainder(phi, 2.0 * math.pi)  # in [-pi, pi]
    return math.pi if w <= -math.pi else w


def sine_amplitude_phase(
    t: Any, y: Any, frequency_hz: float, drift: bool = False, harmonics: int = 1
) -> tuple[float, float]:
    """Least-squares fit ``y ~ c + A sin(2 pi f t + phi) [+ d (t - t_mid)]``.

    Parameters
    ----------
    t : array_like [s]
        Sample times (absolute: the phase refers to t = 0).
    y : array_like [any unit]
        Samples.
    frequency_hz : float [Hz]
        Known frequency f.
    drift : bool
        Also fit a linear drift term.
    harmonics : int
        Also fit sin/cos terms at 2f .. harmonics*f (only the fundamental is
        returned). Over whole periods without drift the harmonics do not affect
        the fundamental; with ``drift=True`` they must be modelled, or harmonic
        content (a response to a raised-cosine drive has a strong 2f term, the
        force going with I^2) leaks through the drift term into A and phi.

    Returns
    -------
    (A, phi)
        Amplitude A >= 0 [unit of y] and phase phi [rad] wrapped to (-pi, pi].
    """
    ta, ya = _signals(t, min_len=3, y=y)
    _frequency(frequency_hz)
    if int(harmonics) != harmonics or harmonics < 1:
        raise ValueError(f"harmonics: must be an integer >= 1, got {harmonics!r}")
    w = 2.0 * math.pi * frequency_hz
    cols = [np.sin(w * ta), np.cos(w * ta), np.ones_like(ta)]
    for k in range(2, int(harmonics) + 1):
        cols += [np.sin(k * w * ta), np.cos(k * w * ta)]
    if drift:
        cols.append(ta - 0.5 * (ta[0] + ta[-1]))
    X = np.column_stack(cols)
    if X.shape[0] < X.shape[1]:
        raise ValueError(f"t: {X.shape[0]} samples cannot fit {X.shape[1]} coefficients")
    coef, *_ = np.linalg.lstsq(X, ya, rcond=None)
    a, b = float(coef[0]), float(coef[1])  # a = A cos(phi), b = A sin(phi)
    return float(math.hypot(a, b)), _wrap(math.atan2(b, a))


def _last_periods(t: np.ndarray, frequency_hz: float, periods: int | None) -> np.ndarray:
    """Boolean mask of the last whole periods of the record."""
    T = 1.0 / frequency_hz
    dt = _median_dt(t)
    duration = t[-1] - t[0] + dt          # each sample stands for dt of record
    available = int(math.floor(duration / T + 1e-9))
    if periods is None:
        periods = max(available - 1, 1)   # skip the first period (transient)
    if periods < 1:
        raise ValueError(f"periods: must be >= 1, got {periods}")
    if periods > available:
        raise ValueError(
            f"periods: record of {duration:.6g} s holds {available} whole period(s) of "
            f"{frequency_hz:g} Hz, {periods} requested")
    t_start = t[-1] + dt - periods * T
    return t >= t_start - 1e-9 * T


def amplitude_ratio_phase_shift(
    t: Any,
    y_meas: Any,
    y_sim: Any,
    frequency_hz: float,
    periods: int | None = None,
    drift: bool = False,
    harmonics: int = 3,
) -> tuple[float, float]:
    """Amplitude ratio and phase shift of a simulated vs a measured sinusoidal response.

    Both responses are fitted at the fundamental ``frequency_hz`` (see
    :func:`sine_amplitude_phase`; by default with harmonics up to 3f and no
    drift term) over the last ``periods`` whole periods of the record (default:
    all whole periods but the first, to skip the transient).

    Returns
    -------
    (ratio, shift)
        ``A_sim / A_meas`` [-] and ``phi_sim - phi_meas`` [rad] wrapped to
        (-pi, pi]. A positive shift means the simulation leads; the paper's
        T6 values (about -0.2 rad) mean the simulation lags.
    """
    ta, ym, ys = _signals(t, min_len=3, y_meas=y_meas, y_sim=y_sim)
    _frequency(frequency_hz)
    sel = _last_periods(ta, frequency_hz, periods)
    a_m, p_m = sine_amplitude_phase(ta[sel], ym[sel], frequency_hz, drift=drift, harmonics=harmonics)
    a_s, p_s = sine_amplitude_phase(ta[sel], ys[sel], frequency_hz, drift=drift, harmonics=harmonics)
    if a_m == 0.0:
        raise ValueError("y_meas: fitted amplitude is zero, amplitude ratio undefined")
    return a_s / a_m, _wrap(p_s - p_m)


# --------------------------------------------------------------------------- sweeps
def sweep_rmse(gap_meas: Any, y_meas: Any, gap_sim: Any, y_sim: Any) -> float:
    """RMSE over the gaps present in both a measured and a simulated sweep (T1, T7).

    Gaps [mm] match when they differ by at most 1e-9 mm. Every measured point
    whose gap is in the simulated sweep counts (measured points at other gaps
    are ignored). Result in the unit of ``y`` (mm for T1, N for T7).

    Raises ValueError if no gap is common, or the simulated gaps are not unique.
    """
    gm = _vector(gap_meas, "gap_meas")
    ym = _vector(y_meas, "y_meas")
    gs = _vector(gap_sim, "gap_sim")
    ys = _vector(y_sim, "y_sim")
    _same_shape(gm, ym, "gap_meas", "y_meas")
    _same_shape(gs, ys, "gap_sim", "y_sim")
    order = np.argsort(gs, kind="stable")
    gs_sorted, ys_sorted = gs[order], ys[order]
    if np.any(np.diff(gs_sorted) <= GAP_MATCH_TOL_MM):
        raise ValueError("gap_sim: gaps must be unique (closer than 1e-9 mm found)")
    idx = np.searchsorted(gs_sorted, gm)
    matched_m, matched_s = [], []
    for k, g in enumerate(gm):
        for cand in (idx[k] - 1, idx[k]):
            if 0 <= cand < gs_sorted.size and abs(gs_sorted[cand] - g) <= GAP_MATCH_TOL_MM:
                matched_m.append(ym[k])
                matched_s.append(ys_sorted[cand])
                break
    if not matched_m:
        raise ValueError("gap_meas and gap_sim have no gap in common (tolerance 1e-9 mm)")
    return rmse(np.array(matched_m), np.array(matched_s))


# --------------------------------------------------------------------------- convenience
def _on_grid(t: np.ndarray, t_sim: Any, y_sim: Any) -> np.ndarray:
    """Simulated samples on the measured time grid (linear interpolation if needed)."""
    ys = _vector(y_sim, "y_sim")
    if t_sim is None:
        _same_shape(t, ys, "t", "y_sim")
        return ys
    tsa = _time(t_sim, "t_sim")
    _same_shape(tsa, ys, "t_sim", "y_sim")
    if tsa[0] > t[0] + 1e-12 or tsa[-1] < t[-1] - 1e-12:
        raise ValueError("t_sim: must cover the measured time range")
    return np.interp(t, tsa, ys)


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
    ta, ym = _signals(t, y_meas=y_meas)
    ys = _on_grid(ta, t_sim, y_sim)
    smooth = None
    if noise_sigma is not None:
        sigma = None if noise_sigma == "auto" else float(noise_sigma)
        smooth = smoothing_window_s(ta, ym, t_step=t_step, noise_sigma=sigma, band=band) or None
    if noise_sigma is None:
        ts_m = settling_time(ta, ym, band=band, t_step=t_step)
        ts_s = settling_time(ta, ys, band=band, t_step=t_step)
    else:
        ts_m = _settling_time_settled_final(ta, ym, band, None, None, t_step, smooth, "mean")
        ts_s = _settling_time_settled_final(ta, ys, band, None, None, t_step, smooth, "mean")
    return {
        f"rmse_{unit}": rmse(ym, ys),
        "ts_meas_s": ts_m,
        "ts_sim_s": ts_s,
        "ste_s": float(abs(ts_s - ts_m)),
        "smooth_window_s": float(smooth or 0.0),
    }


def sine_metrics(
    t: Any,
    y_meas: Any,
    y_sim: Any,
    frequency_hz: float,
    periods: int | None = None,
    unit: str = "mm",
) -> dict[str, float]:
    """Fixed-frequency test (T6) metrics over the last whole periods.

    Returns ``amplitude_ratio`` [-] (A_sim/A_meas), ``phase_shift_rad``
    (phi_sim - phi_meas, positive = simulation leads) and ``rmse_<unit>`` over
    the same periods.
    """
    ta, ym, ys = _signals(t, min_len=3, y_meas=y_meas, y_sim=y_sim)
    ratio, shift = amplitude_ratio_phase_shift(ta, ym, ys, frequency_hz, periods=periods)
    sel = _last_periods(ta, frequency_hz, periods)
    return {
        "amplitude_ratio": float(ratio),
        "phase_shift_rad": float(shift),
        f"rmse_{unit}": rmse(ym[sel], ys[sel]),
    }
