"""Residuals of quantized readings (harness.analysis.core.quantized) against Monte Carlo draws of the rounding
(numpy's normal draws, np.rint): the exact standardization has mean 0 and mean square 1 wherever the true value
lies between two steps, where the noise floor sqrt(sigma^2 + q^2/12) is off by up to 13 % in variance; the
converter's step is found in the readings."""
import math

import numpy as np
from hypothesis import given, settings, strategies as st

from harness.analysis.core import quantized

N = 120_000


@settings(max_examples=12, deadline=None, derandomize=True)
@given(ratio=st.floats(quantized.SIGMA_OVER_Q_MIN, quantized.SIGMA_OVER_Q_MAX - 0.01),
       frac=st.floats(0.0, 1.0), level=st.integers(-500, 500), q=st.sampled_from([1e-3, 2e-6, 1e-4, 0.5]))
def test_exact_standardization_has_unit_mean_square_at_any_position(ratio, frac, level, q):
    sigma = ratio * q
    x = np.full(N, (level + frac) * q)
    rng = np.random.default_rng(abs(level) * 7919 + int(frac * 1e6))
    y = np.rint((x + rng.normal(0.0, sigma, N)) / q) * q
    mu, sd = quantized.moments(x, quantized.Quantization(sigma=sigma, q=q))
    z = (y - mu) / sd
    se = float(np.std(z ** 2)) / math.sqrt(N)     # the mean square's standard error (few levels: heavy tails)
    assert abs(float(np.mean(z ** 2)) - 1.0) < 5 * se
    assert abs(float(np.mean(z))) < 5 / math.sqrt(N)


def test_the_floor_alone_is_off_where_the_exact_moments_are_not():
    """sigma = 0.4 q: at 0.27 of a step the floor's chi-square is 1.3 % high, half a step 11 % high (and at a
    level 13 % low): thousands of readings make that a structure z of several sd; the exact one stays at 1."""
    q, sigma = 1e-3, 4e-4
    floor = math.sqrt(sigma ** 2 + q ** 2 / 12)
    rng = np.random.default_rng(5)
    for frac, floor_ms in ((0.27, 1.013), (0.5, 1.13), (0.0, 0.87)):
        x = np.full(N, (145 + frac) * q)
        y = np.rint((x + rng.normal(0.0, sigma, N)) / q) * q
        plain = float(np.mean(((y - x) / floor) ** 2))
        mu, sd = quantized.moments(x, quantized.Quantization(sigma, q))
        exact = float(np.mean(((y - mu) / sd) ** 2))
        assert abs(plain - floor_ms) < 0.015, (frac, plain)
        assert abs(exact - 1.0) < 0.015, (frac, exact)


def test_detect_finds_the_step_only_where_the_rounding_shapes_the_noise():
    rng = np.random.default_rng(2)
    x = 0.145 + 0.01 * np.sin(np.linspace(0, 3, 5000))
    for sigma, q, found in ((4e-4, 1e-3, True), (2e-3, 1e-3, False), (1e-4, 1e-3, True)):
        y = np.rint((x + rng.normal(0, sigma, x.size)) / q) * q
        y = np.round(y, 6)                       # as written to a CSV file with six decimals
        got = quantized.detect(y, math.sqrt(sigma ** 2 + q ** 2 / 12))
        assert (got is not None) == found, (sigma, got)
        if found:
            assert got.q == q and got.sigma == max(sigma, quantized.SIGMA_OVER_Q_MIN * q)
    # no grid (noise not rounded), too few levels, an unusable floor
    assert quantized.detect(x + rng.normal(0, 4e-4, x.size), 5e-4) is None
    assert quantized.detect(np.array([1.0, 2.0, 1.0, 2.0]), 0.3) is None
    assert quantized.detect(np.array([1.0, 2.0, 3.0]), float("nan")) is None


def test_weights_from_the_readings_give_unit_mean_square_on_plateaus_and_do_not_follow_the_model():
    """The diagnosis's per-reading (offset, scale), computed from the readings' own moving mean: on a record of
    three plateaus (0.27, 0.5 and 0 of a step above a level; sigma = 0.4 q) the residuals against the true
    values have mean square 1 on each plateau; they are the same whatever a model predicts (data only)."""
    q, sigma = 1e-3, 4e-4
    n = 60_000
    x = np.repeat(np.array([145.27, 151.5, 160.0]) * q, n)
    y = np.rint((x + np.random.default_rng(9).normal(0.0, sigma, x.size)) / q) * q
    off, sc = quantized.reading_weights(y, quantized.Quantization(sigma, q))
    z = (y - x - off) / sc
    for k in range(3):
        part = z[k * n + 200:(k + 1) * n - 200]          # away from the edges, where the window mixes levels
        se = float(np.std(part ** 2)) / math.sqrt(part.size)
        assert abs(float(np.mean(part ** 2)) - 1.0) < 5 * se, (k, float(np.mean(part ** 2)))
    off2, sc2 = quantized.reading_weights(y.copy(), quantized.Quantization(sigma, q))
    assert np.array_equal(off, off2) and np.array_equal(sc, sc2)
