"""Force-kernel tables for the vectorized simulator: one ``fmu_src.field.ForceKernel`` per gap, cached,
stacked so that one array evaluation serves runs with different gaps and coil geometries.

* :func:`kernel` -- ``fmu_src.field.make_kernel(a, D, kB, r0)``, cached per process (the same table the
  FMU's model builds);
* :class:`KernelTable` -- the cubic pieces of several kernels stacked in one array, evaluated per run by
  the kernel's one evaluation function ``fmu_src.field.kernel_value`` (every run of the simulator).

Units: SI (m, T/A, N, A).
"""
from __future__ import annotations

import numpy as np

from fmu_src.field import ForceKernel, kernel_value, make_kernel

__all__ = ["kernel", "KernelTable"]

_KERNELS: dict = {}
_MAX_CACHED = 4000


def kernel(a: float, D: float, kB: float, r0: float) -> ForceKernel:
    """``fmu_src.field.make_kernel(a, D, kB, r0)`` cached per process.

    Parameters
    ----------
    a : float
        Coil (loop) radius [m].
    D : float
        Diaphragm diameter [m].
    kB : float
        Field per ampere at the coil face [T/A].
    r0 : float
        Gap [m].
    """
    key = (float(a), float(D), float(kB), float(r0))
    k = _KERNELS.get(key)
    if k is None:
        if len(_KERNELS) > _MAX_CACHED:
            _KERNELS.clear()
        k = make_kernel(*key)
        _KERNELS[key] = k
    return k


def _segments(k: ForceKernel) -> int:
    return int(k.coef.shape[1])


class KernelTable:
    """Spline coefficients of several force kernels stacked in one array (rows c3, c2, c1, c0).

    Parameters
    ----------
    kernels : sequence of ForceKernel
        One kernel per run (the same object may serve several runs; it is stored once), or with ``index``
        the distinct kernels.
    index : (N,) int array or None
        Run -> position in ``kernels`` (then ``kernels`` are the distinct ones).
    """

    def __init__(self, kernels, index=None):
        if index is None:
            uniq, pos = [], {}
            for k in kernels:
                if id(k) not in pos:
                    pos[id(k)] = len(uniq)
                    uniq.append(k)
            index = np.array([pos[id(k)] for k in kernels], dtype=np.intp)
        else:
            uniq = list(kernels)
        ki = np.asarray(index, dtype=np.intp)
        seg = np.array([_segments(k) for k in uniq], dtype=np.intp)
        offs = np.cumsum(np.r_[0, seg])[:-1]
        self.coef = np.ascontiguousarray(np.hstack([k.coef for k in uniq]))   # (4, total segments)
        dr = np.array([k.r_max for k in uniq]) / seg
        self.off = offs[ki].astype(np.intp)
        self.dr = dr[ki]
        self.inv_dr = (1.0 / dr)[ki]
        self.smax = (seg - 1).astype(float)[ki]
        self.G0 = np.array([k.G0 for k in uniq])[ki]
        self.dG0 = np.array([k.dG0 for k in uniq])[ki]

    def __call__(self, r):
        """G(r) [T^2/(A^2.m)] per row at distances r [m] (linear continuation below r = 0)."""
        return kernel_value(r, self.coef, self.off, self.smax, self.dr, self.inv_dr, self.G0, self.dG0)
