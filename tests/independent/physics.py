"""Independent physics of the MPC diaphragm actuator, written from the paper and the README only.

This module deliberately imports nothing of the project's physics (``fmu_src``, ``harness.sim``,
``harness.analysis``): it is a second, independent implementation used to make test data whose
conventions and hidden effects differ from the project's virtual rig.

Equations (SI units; paper section 2 and the README's "The model"):

* coil (Eq. 1): ``d(L(x) I)/dt = V - R(T) I``; with ``L`` constant this is ``L dI/dt = V - R I``;
* field (Eq. 2): ``B(r, theta) = (mu0 N I a^2 / 4) cos(theta) (2a^2 + 2r^2 + a r sin(theta))
  / (a^2 + r^2 + 2 a r sin(theta))^(5/2)`` with ``mu0 N = 2 a kB``;
* force (Eq. 3): ``F = -Em * integral_0^atan(D / 2r) B dB/dr dtheta = Em I^2 G(r)``, attraction
  positive; ``dB/dr`` is differentiated by hand below and the integral is done by our own fixed
  Gauss-Legendre rule (``numpy.polynomial.legendre.leggauss``), checked in the tests against
  ``scipy.integrate.quad``;
* diaphragm (Eqs. 4-5): ``m x'' + C x' + (K1 x^2 + K2) x = F``;
* contact: ``x <= r0``; reaching ``x = r0`` is a perfectly inelastic impact (velocity set to 0); the
  diaphragm rests there while the net force ``F(r=0) - spring(r0)`` is >= 0 and is released when it
  becomes negative;
* blocked mode: ``x = v = 0`` and the transducer reads ``F(r0)``;
* hidden effects of the catalogue's kinds (in forms of their own) and, for issue 22, effects outside it
  (:data:`tests.independent.generator.OUTSIDE_FORMS`): orifice drag and added mass of a pumped fluid, Dahl
  friction in the clamping, a pre-stressed dome (even spring term), silicone softened by the coil's heat
  through a two-node network, eddy currents as a shorted secondary circuit, a laser with a polynomial
  reading, a force transducer with two-exponential creep (``TrueParams``; ``Actuator.rhs``/``readings``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

ALPHA_CU_PER_K = 0.0039          # temperature coefficient of copper resistance [1/K]


# ================================================================ field and force kernel
def field_B_T(r_m: float, theta_rad, a_m: float, kB_T_per_A: float, I_A: float):
    """Eq. 2: flux density [T] at distance ``r_m`` from the coil face, angle ``theta_rad``."""
    s = np.sin(theta_rad)
    pref = 0.5 * kB_T_per_A * I_A * a_m**3          # mu0 N I a^2 / 4 with mu0 N = 2 a kB
    num = 2 * a_m**2 + 2 * r_m**2 + a_m * r_m * s
    den = (a_m**2 + r_m**2 + 2 * a_m * r_m * s) ** 2.5
    return pref * np.cos(theta_rad) * num / den


def field_dBdr_T_per_m(r_m: float, theta_rad, a_m: float, kB_T_per_A: float, I_A: float):
    """dB/dr of Eq. 2 [T/m], differentiated by hand (quotient rule)."""
    s = np.sin(theta_rad)
    pref = 0.5 * kB_T_per_A * I_A * a_m**3
    num = 2 * a_m**2 + 2 * r_m**2 + a_m * r_m * s
    dnum = 4 * r_m + a_m * s
    q = a_m**2 + r_m**2 + 2 * a_m * r_m * s
    dq = 2 * r_m + 2 * a_m * s
    return pref * np.cos(theta_rad) * (dnum * q ** -2.5 - 2.5 * num * dq * q ** -3.5)


def on_axis_loop_field_T(z_m: float, a_m: float, kB_T_per_A: float, I_A: float) -> float:
    """The exact on-axis field of a circular loop, mu0 N I a^2 / (2 (a^2 + z^2)^(3/2)) [T]."""
    mu0N = 2 * a_m * kB_T_per_A
    return mu0N * I_A * a_m**2 / (2 * (a_m**2 + z_m**2) ** 1.5)


_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(96)


def kernel_G(r_m: float, a_m: float, D_m: float, kB_T_per_A: float) -> float:
    """Current-free force kernel G(r) = -integral_0^atan(D/2r) B dB/dr dtheta / I^2 [T^2/(A^2 m)].

    96-point Gauss-Legendre on [0, atan(D / 2r)] (pi/2 at r = 0).
    """
    upper = math.pi / 2 if r_m <= 0 else math.atan(D_m / (2 * r_m))
    th = 0.5 * upper * (_GL_NODES + 1.0)
    f = field_B_T(r_m, th, a_m, kB_T_per_A, 1.0) * field_dBdr_T_per_m(r_m, th, a_m, kB_T_per_A, 1.0)
    return float(-0.5 * upper * np.dot(_GL_WEIGHTS, f))


def kernel_G_array(r_m, a_m: float, D_m: float, kB_T_per_A: float) -> np.ndarray:
    """:func:`kernel_G` on an array of distances [m] (same rule, vectorized over r)."""
    r = np.asarray(r_m, dtype=float)[:, None]
    upper = np.where(r <= 0, math.pi / 2, np.arctan(D_m / (2 * np.where(r <= 0, 1.0, r))))
    th = 0.5 * upper * (_GL_NODES[None, :] + 1.0)
    f = field_B_T(r, th, a_m, kB_T_per_A, 1.0) * field_dBdr_T_per_m(r, th, a_m, kB_T_per_A, 1.0)
    return -0.5 * upper[:, 0] * (f @ _GL_WEIGHTS)


class KernelTable:
    """G(r) tabulated once on a uniform grid and evaluated by cubic Hermite interpolation.

    Values by :func:`kernel_G`, slopes by a central difference of the quadrature (step h/50);
    pure-Python evaluation (fast inside a scalar ODE right-hand side).
    """

    def __init__(self, a_m: float, D_m: float, kB_T_per_A: float, r_max_m: float = 0.04, h_m: float = 5e-5):
        n = int(math.ceil(r_max_m / h_m)) + 1
        self.h = h_m
        self.r_max = (n - 1) * h_m
        r = np.arange(n) * h_m
        d = h_m / 50
        g = kernel_G_array(r, a_m, D_m, kB_T_per_A)
        lo = np.maximum(r - d, 0.0)
        dg = (kernel_G_array(r + d, a_m, D_m, kB_T_per_A) - kernel_G_array(lo, a_m, D_m, kB_T_per_A)) / (r + d - lo)
        self.g = g.tolist()
        self.dg = dg.tolist()

    def array(self, r_m) -> np.ndarray:
        """Vectorized evaluation on an array of distances [m] (r < 0 treated as 0)."""
        r = np.clip(np.asarray(r_m, dtype=float), 0.0, None)
        far = r >= self.r_max
        rc = np.where(far, 0.0, r)
        k = np.minimum((rc / self.h).astype(int), len(self.g) - 2)
        g, dg, h = np.asarray(self.g), np.asarray(self.dg), self.h
        t = (rc - k * h) / h
        t2, t3 = t * t, t * t * t
        val = ((2 * t3 - 3 * t2 + 1) * g[k] + (t3 - 2 * t2 + t) * h * dg[k]
               + (-2 * t3 + 3 * t2) * g[k + 1] + (t3 - t2) * h * dg[k + 1])
        return np.where(far, g[-1] * (self.r_max / np.where(far, r, 1.0)) ** 5, val)

    def __call__(self, r_m: float) -> float:
        if r_m < 0.0:
            r_m = 0.0
        if r_m >= self.r_max:
            return self.g[-1] * (self.r_max / r_m) ** 5      # far field ~ r^-5, never reached by the protocols
        k = int(r_m / self.h)
        h = self.h
        t = (r_m - k * h) / h
        t2, t3 = t * t, t * t * t
        return ((2 * t3 - 3 * t2 + 1) * self.g[k] + (t3 - 2 * t2 + t) * h * self.dg[k]
                + (-2 * t3 + 3 * t2) * self.g[k + 1] + (t3 - t2) * h * self.dg[k + 1])


_KERNEL_CACHE: dict = {}


def kernel_table(a_m: float, D_m: float, kB_T_per_A: float) -> KernelTable:
    """Cached :class:`KernelTable` for (a, D, kB) (the generator's own cache)."""
    key = (round(a_m, 12), round(D_m, 12), round(kB_T_per_A, 12))
    if key not in _KERNEL_CACHE:
        _KERNEL_CACHE[key] = KernelTable(a_m, D_m, kB_T_per_A)
    return _KERNEL_CACHE[key]


# ================================================================ parameters and effects
@dataclass(frozen=True)
class TrueParams:
    """A sample's true parameters (SI units) and its hidden effects (0 = off)."""
    a_m: float
    D_m: float
    kB_T_per_A: float
    R_Ohm: float
    L_H: float
    Em_N_m_per_T2: float
    K1_N_per_m3: float
    K2_N_per_m: float
    C_N_s_per_m: float
    m_kg: float
    # coil heating: thermal network of up to two first-order branches (Foster), dT_i' = (Rth_i P - dT_i)/tau_i
    Rth_K_per_W: tuple = ()
    tau_th_s: tuple = ()
    # saturation of the filler's magnetization: "none", "rational" (1/(1 + ksat B^2)), "tanh", "langevin"
    saturation: str = "none"
    ksat_per_T2: float = 0.0            # rational form
    Bsat_T: float = 0.0                 # tanh / langevin forms
    # creep: generalized Maxwell branches (spring Kc_i in series with a dashpot Kc_i*tau_c_i)
    Kc_N_per_m: tuple = ()
    tau_c_s: tuple = ()
    K5_N_per_m5: float = 0.0            # edge stiffening, spring force + K5 x^5
    lam_1: float = 0.0                  # motional EMF: L(x) = L (1 + lam (a^2/(a^2 + r^2))^(3/2))
    tau_s_s: float = 0.0                # first-order lag of the laser and force readings
    # ---- effects outside the project's catalogue (OUTSIDE_FORMS of the generator); 0 / () = off
    drag_N_s2_per_m2: float = 0.0       # fluid load: orifice drag -kd v|v| of the pumped fluid ...
    added_mass_kg: float = 0.0          # ... and the fluid's added mass (m + m_a accelerates)
    dahl_Fc_N: float = 0.0              # clamp friction, Dahl model: z' = sigma (v - |v| z / Fc), force -z
    dahl_sigma_N_per_m: float = 0.0
    K_even_N_per_m2: float = 0.0        # pre-stressed dome: spring force + K_even x^2 (stiffer toward the coil)
    soft_beta_per_K: float = 0.0        # silicone softening: K1, K2 * (1 - beta dT_d), dT_d the diaphragm's rise,
    soft_Rth_K_per_W: float = 0.0       # heated by the coil's loss P = I^2 R through two nodes:
    soft_tau_s: tuple = ()              # dT_c' = (Rth P - dT_c)/tau_1, dT_d' = (dT_c - dT_d)/tau_2
    eddy_k2: float = 0.0                # eddy currents in the core: a shorted secondary, coupling k^2 = M^2/(L Le),
    eddy_tau_s: float = 0.0             # Le/Re = tau_e; [L M; M Le] d[I, Ie]/dt = [V - R I, -Re Ie] (Le = L)
    laser_g2_per_m: float = 0.0         # laser nonlinearity: reading x + g2 x^2 + g3 x^3
    laser_g3_per_m2: float = 0.0
    cell_creep: tuple = ()              # load-cell creep: reading F + sum c_i (z_i - F), z_i' = (F - z_i)/tau_i
    cell_tau_s: tuple = ()


def saturation_factor(p: TrueParams, B_T: float) -> float:
    """Factor (<= 1) multiplying the unsaturated force Em I^2 G at coil-face field ``B_T`` [T]."""
    if p.saturation == "none":
        return 1.0
    if p.saturation == "rational":
        return 1.0 / (1.0 + p.ksat_per_T2 * B_T * B_T)
    y = abs(B_T) / p.Bsat_T
    if p.saturation == "tanh":            # magnetization Bsat tanh(B/Bsat) instead of B
        return 1.0 if y < 1e-8 else math.tanh(y) / y
    if p.saturation == "langevin":        # magnetization Bsat L(3B/Bsat), L(u) = coth u - 1/u (slope 1/3)
        u = 3.0 * y
        if u < 1e-4:
            return 1.0 - u * u / 15.0
        return 3.0 * (1.0 / math.tanh(u) - 1.0 / u) / u
    raise ValueError(f"unknown saturation form {p.saturation!r}")


def resistance_Ohm(p: TrueParams, dT_K) -> float:
    return p.R_Ohm * (1.0 + ALPHA_CU_PER_K * sum(dT_K))


def inductance_H(p: TrueParams, r_m: float) -> float:
    return p.L_H * (1.0 + p.lam_1 * (p.a_m**2 / (p.a_m**2 + r_m**2)) ** 1.5)


def dinductance_dx_H_per_m(p: TrueParams, r_m: float) -> float:
    """dL/dx = -dL/dr (r = r0 - x) [H/m]."""
    a2 = p.a_m**2
    dLdr = p.L_H * p.lam_1 * 1.5 * (a2 / (a2 + r_m**2)) ** 0.5 * (-a2 * 2 * r_m / (a2 + r_m**2) ** 2)
    return -dLdr


def softening(p: TrueParams, dT_d_K: float) -> float:
    """Factor (<= 1, >= 0.2) of K1 and K2 of a silicone warmed by ``dT_d_K`` [K] (1 without the effect)."""
    return max(1.0 - p.soft_beta_per_K * dT_d_K, 0.2) if p.soft_beta_per_K else 1.0


def spring_force_N(p: TrueParams, x_m: float, creep_y_m, soft: float = 1.0) -> float:
    """Elastic restoring force: Duffing (times the softening factor ``soft``) + pre-stress + edge stiffening +
    Maxwell branches [N]."""
    f = soft * (p.K1_N_per_m3 * x_m**3 + p.K2_N_per_m * x_m) + p.K_even_N_per_m2 * x_m**2 + p.K5_N_per_m5 * x_m**5
    for Kc, y in zip(p.Kc_N_per_m, creep_y_m):
        f += Kc * (x_m - y)
    return f


@dataclass
class Layout:
    """Positions in the ODE state vector: I, x, v, thermal dT_i, creep y_i, sensor (x_s, F_s), then the
    effects outside the catalogue: Dahl friction z [N], silicone heating (dT_c, dT_d) [K], eddy current Ie [A],
    load-cell creep z_i [N]."""
    n_th: int
    n_cr: int
    lag: bool
    fric: bool = False
    soft: bool = False
    eddy: bool = False
    n_cell: int = 0
    i_th: int = field(init=False)
    i_cr: int = field(init=False)
    i_s: int = field(init=False)
    i_fr: int = field(init=False)
    i_soft: int = field(init=False)
    i_ed: int = field(init=False)
    i_cell: int = field(init=False)
    n: int = field(init=False)

    def __post_init__(self):
        self.i_th = 3
        self.i_cr = 3 + self.n_th
        self.i_s = self.i_cr + self.n_cr
        self.i_fr = self.i_s + (2 if self.lag else 0)
        self.i_soft = self.i_fr + (1 if self.fric else 0)
        self.i_ed = self.i_soft + (2 if self.soft else 0)
        self.i_cell = self.i_ed + (1 if self.eddy else 0)
        self.n = self.i_cell + self.n_cell


# ================================================================ simulation
FREE, CONTACT, BLOCKED = "free", "contact", "blocked"
METHOD = "LSODA"


@dataclass(frozen=True)
class Drive:
    """Piecewise-smooth voltage: ``pieces`` is a tuple of (start instant [s], function t -> V [V]),
    sorted by start; before the first start the voltage is 0. Right-continuous at each start."""
    pieces: tuple

    def piece_at(self, t_s: float):
        f = None
        for start, fn in self.pieces:
            if t_s >= start:
                f = fn
        return f

    def voltage_V(self, t_s: float) -> float:
        f = self.piece_at(t_s)
        return 0.0 if f is None else float(f(t_s))


def step_drive(t_step_s: float, V_on_V: float) -> Drive:
    return Drive(((t_step_s, lambda t, V=V_on_V: V),))


def raised_cosine_drive(t_on_s: float, V_peak_V: float, f_Hz: float) -> Drive:
    return Drive(((t_on_s, lambda t: 0.5 * V_peak_V * (1.0 - math.cos(2 * math.pi * f_Hz * (t - t_on_s)))),))


class Actuator:
    """Right-hand sides and events of the actuator in its three modes (one sample, one gap)."""

    def __init__(self, p: TrueParams, r0_m: float, blocked: bool):
        self.p, self.r0, self.blocked = p, float(r0_m), bool(blocked)
        self.G = kernel_table(p.a_m, p.D_m, p.kB_T_per_A)
        self.lay = Layout(len(p.Rth_K_per_W), len(p.Kc_N_per_m), p.tau_s_s > 0, fric=p.dahl_Fc_N > 0,
                          soft=p.soft_beta_per_K > 0, eddy=p.eddy_k2 > 0, n_cell=len(p.cell_creep))
        if p.eddy_k2 > 0 and p.lam_1:
            raise ValueError("eddy currents and motional EMF together are not written")

    def force_N(self, I_A: float, r_m: float) -> float:
        p = self.p
        return p.Em_N_m_per_T2 * I_A * I_A * self.G(r_m) * saturation_factor(p, p.kB_T_per_A * I_A)

    def soft_factor(self, y) -> float:
        """Softening factor of the silicone in state ``y`` (a list)."""
        return softening(self.p, y[self.lay.i_soft + 1]) if self.lay.soft else 1.0

    def net_contact_force_N(self, y) -> float:
        lay = self.lay
        y = y.tolist()
        return self.force_N(y[0], 0.0) - spring_force_N(self.p, self.r0, y[lay.i_cr:lay.i_cr + lay.n_cr],
                                                        self.soft_factor(y))

    def rhs(self, t, y, mode, vfun):
        p, lay = self.p, self.lay
        y = y.tolist()
        I, x, v = y[0], y[1], y[2]
        if mode == BLOCKED:
            x = v = 0.0
        elif mode == CONTACT:
            x, v = self.r0, 0.0
        r = self.r0 - x
        dT = y[lay.i_th:lay.i_th + lay.n_th]
        cy = y[lay.i_cr:lay.i_cr + lay.n_cr]
        R = resistance_Ohm(p, dT) if dT else p.R_Ohm
        F = self.force_N(I, r)
        V = vfun(t)
        dIe = None
        if p.lam_1:
            dI = (V - R * I - I * dinductance_dx_H_per_m(p, r) * v) / inductance_H(p, r)
        elif lay.eddy:           # [L M; M Le] d[I, Ie]/dt = [V - R I, -Re Ie] with Le = L, M = k L, Re = Le/tau_e
            Ie = y[lay.i_ed]
            L, k = p.L_H, math.sqrt(p.eddy_k2)
            e1, e2 = V - R * I, -(L / p.eddy_tau_s) * Ie
            det = L * L * (1.0 - p.eddy_k2)
            dI, dIe = (L * e1 - k * L * e2) / det, (L * e2 - k * L * e1) / det
        else:
            dI = (V - R * I) / p.L_H
        out = [dI, 0.0, 0.0]
        if mode == FREE:
            f = F - p.C_N_s_per_m * v - spring_force_N(p, x, cy, self.soft_factor(y))
            f -= p.drag_N_s2_per_m2 * v * abs(v)
            if lay.fric:
                f -= y[lay.i_fr]
            out[1] = v
            out[2] = f / (p.m_kg + p.added_mass_kg)
        if dT:
            P = I * I * R
            out += [(Rth * P - d) / tau for Rth, tau, d in zip(p.Rth_K_per_W, p.tau_th_s, dT)]
        if cy:
            out += [(x - yc) / tau for tau, yc in zip(p.tau_c_s, cy)]
        if lay.lag:
            out += [(x - y[lay.i_s]) / p.tau_s_s, (F - y[lay.i_s + 1]) / p.tau_s_s]
        if lay.fric:             # Dahl: the bristle force follows the motion and saturates at Fc
            z = y[lay.i_fr]
            out.append(p.dahl_sigma_N_per_m * (v - abs(v) * z / p.dahl_Fc_N) if mode == FREE else 0.0)
        if lay.soft:
            Tc, Td = y[lay.i_soft], y[lay.i_soft + 1]
            out += [(p.soft_Rth_K_per_W * I * I * p.R_Ohm - Tc) / p.soft_tau_s[0], (Tc - Td) / p.soft_tau_s[1]]
        if lay.eddy:
            out.append(dIe)
        if lay.n_cell:
            out += [(F - z) / tau for tau, z in zip(p.cell_tau_s, y[lay.i_cell:lay.i_cell + lay.n_cell])]
        return out

    def readings(self, Y, mode_of_col):
        """I [A], x [m], F [N], x_sensor [m], F_sensor [N] for state columns ``Y`` (n_state x n_t)."""
        lay = self.lay
        I = Y[0]
        x = np.where(np.array([m == FREE for m in mode_of_col]), Y[1],
                     np.where(np.array([m == CONTACT for m in mode_of_col]), self.r0, 0.0))
        r = self.r0 - x
        p = self.p
        sat = np.array([saturation_factor(p, b) for b in (p.kB_T_per_A * I).tolist()])
        F = p.Em_N_m_per_T2 * I * I * self.G.array(r) * sat
        xs, Fs = (Y[lay.i_s], Y[lay.i_s + 1]) if lay.lag else (x, F)
        if p.laser_g2_per_m or p.laser_g3_per_m2:
            xs = xs + p.laser_g2_per_m * xs**2 + p.laser_g3_per_m2 * xs**3
        for j, c in enumerate(p.cell_creep):
            Fs = Fs + c * (Y[lay.i_cell + j] - F)
        return I, x, F, xs, Fs


def simulate(p: TrueParams, r0_m: float, blocked: bool, drive: Drive, t_samples_s, *, rtol: float = 1e-7,
             max_switches: int = 2000):
    """Simulate from rest (I = 0, x = v = 0, cold coil) from t = 0 and sample at ``t_samples_s``.

    Returns a dict of arrays ``I_A``, ``x_m``, ``F_N``, ``x_sensor_m``, ``F_sensor_N`` and the list
    ``events`` of (instant [s], "contact"/"release"). ``scipy.integrate.solve_ivp`` (DOP853) between
    the drive's breakpoints, with terminal events for contact (x = r0, rising) and release (net
    contact force falling through 0).
    """
    from scipy.integrate import solve_ivp

    act = Actuator(p, r0_m, blocked)
    lay = act.lay
    ts = np.asarray(t_samples_s, dtype=float)
    y = np.zeros(lay.n)
    if blocked:
        mode = BLOCKED
    elif r0_m <= 0.0:
        mode = CONTACT
        y[1] = r0_m
    else:
        mode = FREE
    # absolute tolerances far below the sensors' resolution (2 um, 1 mA, 0.1 mN)
    atol = np.full(lay.n, 1e-10)                 # x [m], creep states [m], x_sensor [m]
    atol[0], atol[2] = 1e-8, 1e-8                # I [A], v [m/s]
    atol[lay.i_th:lay.i_th + lay.n_th] = 1e-6    # dT [K]
    if lay.fric:
        atol[lay.i_fr] = 1e-9                    # friction force [N]
    if lay.soft:
        atol[lay.i_soft:lay.i_soft + 2] = 1e-6   # dT_c, dT_d [K]
    if lay.eddy:
        atol[lay.i_ed] = 1e-8                    # Ie [A]
    atol[lay.i_cell:lay.i_cell + lay.n_cell] = 1e-9  # load-cell creep states [N]
    if lay.lag:
        atol[lay.i_s + 1] = 1e-9                 # F_sensor [N]
    breaks = sorted({s for s, _ in drive.pieces if 0.0 < s < ts[-1]})
    bounds = [0.0] + breaks + [float(ts[-1])]
    Y = np.zeros((lay.n, ts.size))
    modes = [FREE] * ts.size
    events = []

    def ev_contact(tt, yy, *args):
        return yy[1] - act.r0
    ev_contact.terminal, ev_contact.direction = True, 1.0

    def ev_release(tt, yy, *args):
        return act.net_contact_force_N(yy)
    ev_release.terminal, ev_release.direction = True, -1.0

    for j in range(len(bounds) - 1):
        a, b = bounds[j], bounds[j + 1]
        piece = drive.piece_at(0.5 * (a + b))
        vfun = (lambda t: 0.0) if piece is None else piece
        last = j == len(bounds) - 2
        t = a
        while t < b:
            evs = [ev_contact] if mode == FREE else [ev_release] if mode == CONTACT else None
            sol = solve_ivp(act.rhs, (t, b), y, method=METHOD, dense_output=True, events=evs,
                            rtol=rtol, atol=atol, args=(mode, vfun))
            if sol.status < 0:
                raise RuntimeError(f"solve_ivp failed: {sol.message}")
            t_end = float(sol.t[-1])
            hit = sol.status == 1
            sel = (ts >= t) & ((ts <= t_end) if (last and not hit) else (ts < t_end))
            idx = np.nonzero(sel)[0]
            if idx.size:
                Y[:, idx] = sol.sol(ts[idx])
                for k in idx:
                    modes[k] = mode
            y = np.array(sol.y[:, -1], dtype=float)
            t = t_end
            if not hit:
                break
            if len(events) >= max_switches:
                raise RuntimeError(f"more than {max_switches} contact/release switches")
            y[1], y[2] = act.r0, 0.0
            if mode == FREE:
                events.append((t, "contact"))
                if act.net_contact_force_N(y) >= 0.0:
                    mode = CONTACT
            else:
                events.append((t, "release"))
                mode = FREE
            if last and t >= b:       # an event exactly at the final sample
                k = ts.size - 1
                Y[:, k], modes[k] = y, mode
    I, x, F, xs, Fs = act.readings(Y, modes)
    return {"I_A": I, "x_m": x, "F_N": F, "x_sensor_m": xs, "F_sensor_N": Fs, "events": events}
