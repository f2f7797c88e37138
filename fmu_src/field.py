"""Field of the electromagnet as a single current loop, and the force kernel.

Paper Eq. 2 in SI form, with the effective turn count N expressed through the
field per ampere at the coil face, kB = mu0*N/(2a) [T/A]:

    B(r, theta) = (mu0*N*I*a^2/4) * cos(theta) * (2a^2 + 2r^2 + a*r*sin(theta))
                                   / (a^2 + r^2 + 2a*r*sin(theta))^(5/2)
                = kB*I * (a^3/2) * cos(theta) * (...) / (...)^(5/2)

r = r0 - x is the distance from the coil face to the diaphragm. On the axis
(theta = 0) it reduces to the exact loop field mu0*N*I*a^2 / (2 (a^2 + r^2)^(3/2)).

Paper Eq. 3, attraction positive:

    F = -Em * integral_0^atan(D/(2r)) B * dB/dr dtheta = Em * I^2 * G(r)

with the current-free kernel G(r) [T^2/(A^2.m)] depending only on r, a, D and kB.
``ForceKernel`` tabulates G once as a cubic spline so that the integrators need
no quadrature per step.
"""
from __future__ import annotations


import numpy as np
from numba.extending import register_jitable
from scipy.interpolate import CubicSpline

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(64)


def field_per_amp(r, theta, a: float, kB: float):
    """B/I [T/A] at distance r [m] from the coil face and angle theta [rad] (Eq. 2)."""
    r = np.asarray(r, dtype=float)
    s = np.sin(theta)
    num = 2 * a * a + 2 * r * r + a * r * s
    q = a * a + r * r + 2 * a * r * s
    return kB * 0.5 * a**3 * np.cos(theta) * num / q**2.5


def dfield_dr_per_amp(r, theta, a: float, kB: float):
    """d(B/I)/dr [T/(A.m)] at fixed theta (analytic derivative of Eq. 2)."""
    r = np.asarray(r, dtype=float)
    s = np.sin(theta)
    num = 2 * a * a + 2 * r * r + a * r * s
    q = a * a + r * r + 2 * a * r * s
    dnum = 4 * r + a * s
    dq = 2 * r + 2 * a * s
    return kB * 0.5 * a**3 * np.cos(theta) * (dnum * q**-2.5 - 2.5 * num * dq * q**-3.5)


@register_jitable
def axial_field(I, r, a: float, kB: float):
    """Field on the coil axis [T] at distance r [m] for current I [A]: kB*I*a^3/(a^2+r^2)^(3/2).

    Plain arithmetic: floats or numpy arrays, and callable from numba-compiled code (the FMU's outputs)."""
    return kB * I * a**3 / (a * a + r * r) ** 1.5


def theta_max(r, D: float):
    """Upper integration limit atan(D/(2r)) [rad]; pi/2 at r = 0."""
    return np.arctan2(0.5 * D, np.asarray(r, dtype=float))


def force_kernel(r, a: float, D: float, kB: float) -> np.ndarray:
    """G(r) [T^2/(A^2.m)] = -integral_0^atan(D/2r) b*db/dr dtheta with b = B/I, by 64-point Gauss-Legendre.

    Accepts a scalar or an array of r >= 0 [m]; F = Em * I^2 * G(r).
    """
    r = np.atleast_1d(np.asarray(r, dtype=float))
    tm = theta_max(r, D)[:, None]
    th = 0.5 * tm * (_GL_NODES[None, :] + 1.0)
    integrand = field_per_amp(r[:, None], th, a, kB) * dfield_dr_per_amp(r[:, None], th, a, kB)
    return -0.5 * tm[:, 0] * (integrand @ _GL_WEIGHTS)


@register_jitable
def kernel_value(r, coef, off, smax, dr, inv_dr, G0, dG0):
    """G(r) [T^2/(A^2.m)] of a tabulated kernel: the ONE evaluation of ``ForceKernel``'s cubic pieces.

    Plain arithmetic on a float r or a numpy array r (then off, smax, dr, inv_dr, G0, dG0 may be arrays
    of the same shape, one kernel per element: ``harness.analysis.diagnose``'s stacked tables); numba-compiled
    code (the FMU's integrator, ``fmu_src.integrator``) calls this same function. coef: (4, segments)
    rows c3, c2, c1, c0 of the pieces (scipy ``CubicSpline.c``), piece k on [k*dr, (k+1)*dr] in
    columns off + k; smax = index of the last piece (as a float). r < 0 (reached only inside
    integrator stages at contact): linear continuation G0 + dG0*r. Beyond the table the last piece is
    continued (``ForceKernel`` computes that range by quadrature instead). A NaN r gives NaN (index clipped).
    """
    s = np.minimum(np.maximum(r, 0.0) * inv_dr, smax)
    i = np.minimum(np.maximum(np.intp(s), 0), np.intp(smax)) + off
    u = r - (i - off) * dr
    g = ((coef[0, i] * u + coef[1, i]) * u + coef[2, i]) * u + coef[3, i]
    return g + (r < 0.0) * (G0 + dG0 * r - g)


class ForceKernel:
    """G(r) tabulated once on r in [0, r_max] as a cubic spline (scalar and vector evaluation).

    The table is its coefficient array ``coef`` (4, segments) on equally spaced breakpoints (``dr``);
    ``kernel_value`` evaluates it (floats, arrays, and inside numba-compiled code). Below r = 0 (only
    reached inside integrator stages at contact) G is continued linearly; above r_max ``__call__``
    and ``eval`` compute it by quadrature.
    """

    def __init__(self, a: float, D: float, kB: float, r_max: float, n: int = 1201):
        self.a, self.D, self.kB = float(a), float(D), float(kB)
        self.r_max = float(r_max)
        r = np.linspace(0.0, self.r_max, n)
        self.spline = CubicSpline(r, force_kernel(r, a, D, kB))   # scipy's spline the table is made of
        self.coef = np.ascontiguousarray(self.spline.c, dtype=np.float64)   # (4, n-1): c3, c2, c1, c0
        self.dr = float(r[1] - r[0])      # breakpoint spacing [m]
        self.inv_dr = 1.0 / self.dr       # [1/m]
        self.nseg = n - 1                 # number of cubic pieces
        self.smax = float(n - 2)          # index of the last piece (a float, as kernel_value takes it)
        self.G0 = float(self.spline(0.0))
        self.dG0 = float(self.spline(0.0, 1))
        # transition aliases of the former private names (harness.sim.rk4); remove at integration
        self._c, self._dr, self._nseg = self.coef, self.dr, self.nseg

    def __call__(self, r: float) -> float:
        """G(r) [T^2/(A^2.m)] for a float r [m]."""
        if r > self.r_max:
            return float(force_kernel(r, self.a, self.D, self.kB)[0])
        return float(kernel_value(float(r), self.coef, 0, self.smax, self.dr, self.inv_dr, self.G0, self.dG0))

    def eval(self, r) -> np.ndarray:
        """G(r) [T^2/(A^2.m)] for an array of r [m] (vectorized, used by batched integrations)."""
        r = np.asarray(r, dtype=float)
        out = np.asarray(kernel_value(r, self.coef, 0, self.smax, self.dr, self.inv_dr, self.G0, self.dG0),
                         dtype=float)
        high = r > self.r_max
        if np.any(high):
            out = np.array(out, dtype=float, copy=True)
            out[high] = force_kernel(r[high], self.a, self.D, self.kB)
        return out

    def derivative(self, r) -> np.ndarray:
        """dG/dr [T^2/(A^2.m^2)] (vectorized)."""
        r = np.asarray(r, dtype=float)
        return np.where(r < 0.0, self.dG0, self.spline(np.clip(r, 0.0, self.r_max), 1))


def make_kernel(a: float, D: float, kB: float, r0: float) -> ForceKernel:
    """Kernel table covering every gap a run can reach (x from -r0-20 mm up to r0)."""
    return ForceKernel(a, D, kB, r_max=2.0 * r0 + 0.02)
