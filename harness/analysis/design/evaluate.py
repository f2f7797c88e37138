"""Evaluation kernel of the design search: a block of designs sharing the diaphragm diameter D and the
gap r0 (so one force kernel G serves the block), each with its own parameters (Em, K1, K2, C, m from
the generalization surfaces at its filler fraction) and voltage.

Per design (SI units):

* current I = V/R [A] and coil power P = V^2/R [W] at steady state;
* blocked force F_b = Em I^2 G(r0) [N] (diaphragm held at x = 0);
* static operating point: the smallest root of h(x) = Em I^2 G(r0 - x) - (K1 x^3 + K2 x) on (0, r0)
  (h(0) > 0: the first crossing from rest is the stable equilibrium the diaphragm settles to; none:
  the force exceeds the spring everywhere, the diaphragm is pulled in), by a vectorized scan of 64
  points and bisection to 1e-12 m;
* short step response: the voltage step from rest through the vectorized simulator
  (:func:`harness.sim.simulator.simulate`, the FMU's physics and contact semantics) for ``t_step_s``;
  stroke = displacement at its end [m], contact = the diaphragm reached the coil face, 2 % settling
  time [s] = time after which the displacement stays within 2 % of its final value, the last exit from
  the band interpolated linearly between the output samples (so that it is continuous in the parameters,
  as the linearised probability of :mod:`harness.analysis.design.advice` needs; inf if it has not
  settled by the end: the end value then differs from the static point by more than the band);
* static pull-in current [A] (:func:`pull_in_current`): above it the force exceeds the spring at every
  x (its margin to the current is what the linearised probability uses for pull-in);
* small-signal bandwidth [Hz] from the voltage to the displacement at the static point: the -3 dB
  frequency of H(s) = (2 Em I G(r0 - x) / (R + L s)) / (m s^2 + C s + k_t), k_t = 3 K1 x^2 + K2 +
  Em I^2 G'(r0 - x) (spring minus the magnetic force's gradient), on a log grid of 400 frequencies
  0.01-1000 Hz refined linearly (0 when pulled in or k_t <= 0).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from harness.sim.kernels import kernel
from harness.sim.settings import Schedule
from harness.sim.simulator import PARAM_FIELDS, Runs, simulate

__all__ = ["Block", "METRICS", "static_point", "pull_in_current", "bandwidth", "evaluate_block"]

METRICS = ("current_A", "power_W", "blocked_force_N", "static_stroke_m", "stroke_m", "settling_s", "contact",
           "bandwidth_Hz", "pull_in_current_A")
_FIT = ("Em", "K1", "K2", "C", "m")


@dataclass(frozen=True)
class Block:
    """Designs sharing D and r0.

    a_m, kB_T_per_A, R_Ohm, L_H: the coil; D_m, gap_m: diameter and gap [m]; V_V: (n,) voltages [V];
    params: {"Em", "K1", "K2", "C", "m": (n,) SI arrays}; t_step_s: step-response duration [s];
    dt_s: its output period [s]; band: settling band (0.02 = 2 %).
    """
    a_m: float
    kB_T_per_A: float
    R_Ohm: float
    L_H: float
    D_m: float
    gap_m: float
    V_V: np.ndarray
    params: dict
    t_step_s: float = 0.5
    dt_s: float = 1e-3
    band: float = 0.02


def static_point(G, r0: float, EmI2: np.ndarray, K1: np.ndarray, K2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x [m], pulled_in) of the smallest root of Em I^2 G(r0 - x) = K1 x^3 + K2 x on (0, r0) (module docstring).

    G: a ``fmu_src.field.ForceKernel``; EmI2 = Em I^2 [N.m/A^2 * A^2]; K1, K2: (n,) arrays.
    """
    n = EmI2.size
    xs = np.linspace(0.0, r0, 65)
    Gx = G.eval(r0 - xs)                                           # (65,)
    h = EmI2[:, None] * Gx[None, :] - (K1[:, None] * xs ** 3 + K2[:, None] * xs)
    neg = h[:, 1:] <= 0.0
    has = neg.any(axis=1)
    k = np.where(has, np.argmax(neg, axis=1), 63)
    lo, hi = xs[k], xs[k + 1]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        hm = EmI2 * G.eval(r0 - mid) - (K1 * mid ** 3 + K2 * mid)
        pos = hm > 0
        lo = np.where(pos, mid, lo)
        hi = np.where(pos, hi, mid)
        if np.max(hi - lo) < 1e-12:
            break
    x = np.where(has, 0.5 * (lo + hi), r0)
    return x, ~has & (n > 0)


def pull_in_current(G, r0: float, Em: np.ndarray, K1: np.ndarray, K2: np.ndarray, n: int = 512) -> np.ndarray:
    """Static pull-in current [A]: the largest I with a static equilibrium on (0, r0], I^2 = max_x (K1 x^3 +
    K2 x) / (Em G(r0 - x)) over n points of (0, r0] (a maximum over a fixed grid: continuous in the
    parameters, its derivative the partial one at the maximising point)."""
    xs = np.linspace(0.0, r0, n + 1)[1:]
    Gx = G.eval(r0 - xs)
    ratio = (K1[:, None] * xs ** 3 + K2[:, None] * xs) / (Em[:, None] * Gx[None, :])
    return np.sqrt(np.max(ratio, axis=1))


def bandwidth(G, r0: float, x, I, p: dict, R: float, L: float) -> np.ndarray:
    """-3 dB bandwidth [Hz] of the small-signal voltage -> displacement response at (x [m], I [A]) (module
    docstring); p: {"Em", "K1", "K2", "C", "m": (n,) arrays}."""
    r = r0 - x
    kt = 3 * p["K1"] * x ** 2 + p["K2"] + p["Em"] * I ** 2 * G.derivative(r)
    f = np.logspace(-2, 3, 400)
    w = 2 * np.pi * f
    s = 1j * w[None, :]
    mech = p["m"][:, None] * s ** 2 + p["C"][:, None] * s + kt[:, None]
    H = np.abs(1.0 / ((R + L * s) * mech))
    H0 = np.abs(1.0 / (R * kt))[:, None]
    below = H < H0 / np.sqrt(2.0)
    has = below.any(axis=1) & (kt > 0)
    k = np.argmax(below, axis=1)
    k0 = np.maximum(k - 1, 0)
    rows = np.arange(x.size)
    h0, h1 = H[rows, k0] / H0[:, 0], H[rows, k] / H0[:, 0]
    frac = np.where(h1 != h0, (h0 - 1 / np.sqrt(2.0)) / np.where(h1 != h0, h0 - h1, 1.0), 0.0)
    fb = f[k0] + np.clip(frac, 0, 1) * (f[k] - f[k0])
    return np.where(has, fb, 0.0)


def evaluate_block(b: Block) -> dict:
    """{metric: (n,) array} for the designs of block b (``METRICS``; module docstring)."""
    V = np.asarray(b.V_V, dtype=float)
    n = V.size
    p = {k: np.asarray(b.params[k], dtype=float) for k in _FIT}
    I = V / b.R_Ohm
    G = kernel(b.a_m, b.D_m, b.kB_T_per_A, b.gap_m)
    EmI2 = p["Em"] * I * I
    x_st, pulled = static_point(G, b.gap_m, EmI2, p["K1"], p["K2"])
    par = {k: np.zeros(n) for k in PARAM_FIELDS}
    par.update({"a": np.full(n, b.a_m), "r0": np.full(n, b.gap_m), "D": np.full(n, b.D_m),
                "kB": np.full(n, b.kB_T_per_A), "R": np.full(n, b.R_Ohm), "L": np.full(n, b.L_H)})
    par.update(p)
    res = simulate(Runs(params=par, blocked=np.zeros(n, bool), V=V, dt=b.dt_s),
                   Schedule(t_end=b.t_step_s, fine_s=None))
    x = res.x
    x_end = x[:, -1]
    tol = b.band * np.abs(x_end)
    outside = np.abs(x - x_end[:, None]) > tol[:, None]
    last = x.shape[1] - 1 - np.argmax(outside[:, ::-1], axis=1)
    any_out = outside.any(axis=1)
    nxt = np.minimum(last + 1, x.shape[1] - 1)
    rows = np.arange(n)
    e0 = np.abs(x[rows, last] - x_end) - tol                       # > 0: outside the band at the last exit
    e1 = np.abs(x[rows, nxt] - x_end) - tol                        # <= 0: inside at the next sample
    frac = np.clip(np.where(e0 > e1, e0 / np.where(e0 > e1, e0 - e1, 1.0), 1.0), 0.0, 1.0)
    t_exit = res.t[last] + frac * (res.t[nxt] - res.t[last])       # the band's last exit, interpolated
    t_settle = np.where(any_out, t_exit, 0.0)
    contact = res.contact.any(axis=1)
    unsettled = (np.abs(x_end - x_st) > tol) & ~contact
    t_settle = np.where(unsettled, np.inf, t_settle)
    bw = np.where(pulled, 0.0, bandwidth(G, b.gap_m, x_st, I, p, b.R_Ohm, b.L_H))
    return {"current_A": I, "power_W": V * I, "blocked_force_N": EmI2 * G.eval(np.full(n, b.gap_m)),
            "static_stroke_m": x_st, "stroke_m": x_end, "settling_s": t_settle, "contact": contact | pulled,
            "bandwidth_Hz": bw, "pull_in_current_A": pull_in_current(G, b.gap_m, p["Em"], p["K1"], p["K2"])}
