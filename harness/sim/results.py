"""Results of the vectorized simulator.

* :class:`BatchResult` -- displacement of a whole population of (C, m) candidates on their tests'
  sample grids in a compact form (a time-major block plus a fill value per candidate from where it
  settled), with the reductions the identification's objectives need;
* :class:`SimResult` -- current, sensor reading and contact flag of a batch of runs with effects.

Units: SI (s, A, m, N).
"""
from __future__ import annotations

from functools import cached_property
from dataclasses import dataclass

import numpy as np

__all__ = ["BatchResult", "SimResult"]


@dataclass(frozen=True)
class SimResult:
    """Outputs of :func:`harness.sim.simulator.simulate` on its output grid.

    Attributes
    ----------
    t : (n_out,) local times [s] from the input onset (the same for every run: it depends only on the
        sample period and the schedule, never on the parameters).
    I : (N, n_out) coil current [A].
    x : (N, n_out) displacement reading x_sensor [m] (x itself without sensor_lag).
    F : (N, n_out) force reading F_sensor [N] (the magnetic force without sensor_lag; for a free run the
        force on the moving diaphragm).
    contact : (N, n_out) bool, the diaphragm rests on the coil face.
    blocked : (N,) bool, blocked runs.
    """

    t: np.ndarray
    I: np.ndarray
    x: np.ndarray
    F: np.ndarray
    contact: np.ndarray
    blocked: np.ndarray

    @cached_property
    def y(self) -> np.ndarray:
        """(N, n_out) the reading of each run's test: F_sensor [N] blocked, x_sensor [m] free (computed once:
        callers index it row by row)."""
        return np.where(self.blocked[:, None], self.F, self.x)

# ----------------------------------------------------------------------------- result
@dataclass
class BatchResult:
    """Displacement x [m] of every candidate on its test's sample grid.

    Candidate j is at rest (x = 0) at samples k < ``k_begin``; ``H[r, j]`` is x at sample
    ``k_begin + r`` (time-major block, ``R = H.shape[0]`` rows); from ``k_fill[j]`` on
    (``n_t[j]`` if it never settled) x equals ``x_fill[j]`` (also inside the block).
    Samples at or after ``k_begin + R`` are all fill values.
    """
    n_t: np.ndarray            # samples per candidate's test
    k_begin: int
    H: np.ndarray              # (R, n) time-major block
    k_fill: np.ndarray
    x_fill: np.ndarray
    settled: np.ndarray        # bool
    substeps: np.ndarray       # RK4 sub-steps per sample interval
    candidate_steps: int = 0   # sample intervals integrated, summed over candidates (cost measure)

    @property
    def n(self) -> int:
        return int(self.k_fill.size)

    def columns(self, lo: int, hi: int) -> "BatchResult":
        """Candidates lo..hi-1 as their own result (a view of the block, rows trimmed)."""
        kf = self.k_fill[lo:hi]
        R = int(min(self.H.shape[0], max(0, int(kf.max(initial=self.k_begin)) - self.k_begin)))
        return BatchResult(n_t=self.n_t[lo:hi], k_begin=self.k_begin, H=self.H[:R, lo:hi], k_fill=kf,
                           x_fill=self.x_fill[lo:hi], settled=self.settled[lo:hi],
                           substeps=self.substeps[lo:hi])

    def dense(self, k_lo: int, k_hi: int, idx=None) -> np.ndarray:
        """x [m] over samples [k_lo, k_hi) as a time-major array (k_hi - k_lo, len(idx))."""
        idx = np.arange(self.n) if idx is None else np.asarray(idx, dtype=np.intp)
        R = self.H.shape[0]
        b0, b1 = self.k_begin, self.k_begin + R
        parts = []
        if k_lo < b0:
            parts.append(np.zeros((min(b0, k_hi) - k_lo, idx.size)))
        a, b = max(k_lo, b0), min(k_hi, b1)
        if b > a:
            parts.append(self.H[a - b0:b - b0][:, idx] if idx.size != self.n else self.H[a - b0:b - b0])
        if k_hi > b1:
            parts.append(np.broadcast_to(self.x_fill[idx], (k_hi - max(k_lo, b1), idx.size)))
        if not parts:
            return np.zeros((0, idx.size))
        return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=0)

    def full(self, idx=None) -> np.ndarray:
        """x [m] as a dense candidate-major array (len(idx), max n_t)."""
        nt = int(self.n_t.max()) if self.n else 0
        return np.ascontiguousarray(self.dense(0, nt, idx).T)

    def range_sum(self, a) -> np.ndarray:
        """Sum of x [m] over samples k >= a[j] (to the end of the record) per candidate j."""
        a = np.broadcast_to(np.asarray(a, dtype=np.intp), (self.n,))
        R = self.H.shape[0]
        b0, b1 = self.k_begin, self.k_begin + R
        lo = np.clip(a, b0, b1)
        s = np.zeros(self.n)
        if R:
            amin = int(lo.min())
            blk = self.H[amin - b0:]
            if np.all(lo == amin):
                s += blk.sum(axis=0)
            else:
                rows = np.arange(amin, b1)[:, None]
                s += np.where(rows >= lo[None, :], blk, 0.0).sum(axis=0)
        tail0 = np.maximum(a, b1)
        s += np.where(self.n_t > tail0, (self.n_t - tail0) * np.nan_to_num(self.x_fill), 0.0)
        return s

    def tail_mean(self, n_tail: int) -> np.ndarray:
        """Mean of the last n_tail samples per candidate [m]."""
        return self.range_sum(self.n_t - n_tail) / n_tail

    def mean_before(self, k: int) -> np.ndarray:
        """Mean of the samples before index k per candidate [m]."""
        if k <= 0:
            return np.full(self.n, np.nan)
        return (self.range_sum(0) - self.range_sum(k)) / k

    def sum_sq_error(self, y) -> np.ndarray:
        """Sum over all samples of (x - y)^2 [m^2] per candidate; y [m] on the (common) grid."""
        y = np.asarray(y, dtype=float)
        nt = y.size
        R = self.H.shape[0]
        b0 = self.k_begin
        b1 = min(b0 + R, nt)
        tot = np.full(self.n, float(np.sum(y[:b0] ** 2)))
        if b1 > b0:
            d = self.H[:b1 - b0] - y[b0:b1, None]
            tot += np.einsum("ij,ij->j", d, d)
        if nt > b1:
            yt = y[b1:]
            xf = np.nan_to_num(self.x_fill)
            tot += (nt - b1) * xf * xf - 2.0 * xf * float(yt.sum()) + float(np.dot(yt, yt))
        return tot

    def values_at(self, k, idx=None) -> np.ndarray:
        """x [m] at sample k[q] of candidate idx[q] (default idx = all candidates)."""
        k = np.asarray(k, dtype=np.intp)
        idx = np.arange(self.n) if idx is None else np.asarray(idx, dtype=np.intp)
        R = self.H.shape[0]
        out = np.zeros(k.shape)
        inb = (k >= self.k_begin) & (k < self.k_begin + R)
        out[inb] = self.H[k[inb] - self.k_begin, idx[inb]]
        after = k >= self.k_begin + R
        out[after] = self.x_fill[idx[after]]
        return out

    def last_outside(self, center, tol, k_min: int = 0) -> np.ndarray:
        """Largest sample index k >= k_min with |x_k - center| > tol per candidate, -1 if none."""
        center = np.asarray(center, dtype=float)
        tol = np.asarray(tol, dtype=float)
        out = np.full(self.n, -1, dtype=np.intp)
        R = self.H.shape[0]
        b0, b1 = self.k_begin, self.k_begin + R
        fo = (self.n_t > b1) & (np.abs(np.nan_to_num(self.x_fill) - center) > tol)
        out = np.where(fo, self.n_t - 1, out)
        lo = max(k_min, b0)
        if b1 > lo:
            M = np.abs(self.H[lo - b0:] - center) > tol
            anyo = M.any(axis=0)
            last = lo + (M.shape[0] - 1 - np.argmax(M[::-1], axis=0))
            out = np.where((out < 0) & anyo, last, out)
        if b0 - 1 >= k_min:
            ro = np.abs(center) > tol
            out = np.where(ro & (out < 0), b0 - 1, out)
        return out

