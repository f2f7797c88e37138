"""Vectorized simulator of the actuator with every effect: hundreds of runs (samples x tests x gaps x
parameter sets) integrated at once by classic RK4 in a compiled loop (:mod:`harness.sim.core`), the
physics from ``fmu_src.effects`` (the functions the FMU's compiled integrator is made of), the contact
semantics of the FMU's integrator.

    runs = Runs(params={name: (N,) array for name in PARAM_FIELDS}, blocked=..., V=..., dt=1e-3)
    res = simulate(runs, Schedule(t_end=2.8, fine_s=0.5))     # SimResult: t, I, x, F (sensors), contact

Inputs: a constant voltage per run switched on at local time 0 (step tests and sweep points), or a
voltage per sample, held over each sample interval (zero-order hold, ``hold="zoh"``, as a co-simulation
master does) or linear between samples (``hold="linear"``). Every run starts at rest at local time 0.

Steps: RK4 with step dt/n_sub, n_sub (a power of two) per run from its stiffest mode; the coarse steps of the
quasi-static remainder likewise per run (a run's result does not depend on the other runs of its batch).
With a constant input: runs without slow states (coil heating, creep) whose outputs have stopped changing
(by less than tol_y [m or N] and tol_I [A] over 50 ms) are frozen; after ``fine_s`` the remaining runs
step by coarse_out*dt/per with per = 1, 2, 4, ... (RK4 stability for the decayed fast modes, accuracy for
the slow states). The output grid depends only on dt and the schedule, never on the parameters (residual
vectors keep their length during a fit). Sample periods may differ between runs (datasets of other rigs:
200 Hz to 10 kHz): :func:`simulate_by_period` integrates one batch per period.

Units: SI (s, V, A, m, N).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import core, physics
from .physics import PARAM_FIELDS, TERM_FIELDS
from .results import SimResult
from .settings import Schedule, SimInputError

__all__ = ["PARAM_FIELDS", "Runs", "simulate", "simulate_by_period"]


@dataclass(frozen=True)
class Runs:
    """N runs of the effect model.

    Attributes
    ----------
    params : dict
        {name: (N,) array} for every name of ``PARAM_FIELDS`` (SI; effect parameters 0 = off; the term set's
        ``TERM_FIELDS`` may be left out: 0, off).
    blocked : (N,) bool
        Blocked mode (x = v = 0; the reading is the force).
    V : (N,) or (N, n) or (N, n + 1) array
        Voltage [V]: constant from local time 0, or per sample (see ``hold``).
    dt : float or (N,) array
        Sample period [s] (output spacing of the fine part).
    hold : str
        "zoh": V[:, k] held over [k dt, (k+1) dt) (V has n columns for n intervals); "linear": linear
        between the samples V[:, k] at k dt (n + 1 columns).
    tol_y : (N,) array or None
        Settle tolerance of the reading [m or N] (default 1e-10 m free, 1e-7 N blocked).
    """

    params: dict
    blocked: np.ndarray
    V: np.ndarray
    dt: float | np.ndarray = 1e-3
    hold: str = "zoh"
    tol_y: np.ndarray | None = None

    def __post_init__(self):
        if any(k not in self.params for k in TERM_FIELDS):
            # the generic term set's parameters (fmu_src.terms) default to 0: off
            n0 = np.asarray(self.blocked).size
            object.__setattr__(self, "params", {**{k: np.zeros(n0) for k in TERM_FIELDS}, **self.params})
        missing = [k for k in PARAM_FIELDS if k not in self.params]
        if missing:
            raise SimInputError(f"Runs.params lacks {missing}")
        if self.hold not in ("zoh", "linear"):
            raise SimInputError(f"hold must be 'zoh' or 'linear', got {self.hold!r}")
        n = np.asarray(self.blocked).size
        V = np.asarray(self.V)
        if V.shape[:1] != (n,) or V.ndim > 2 or (self.hold == "linear" and V.ndim == 2 and V.shape[1] < 2):
            raise SimInputError(f"V must have shape (N,) or (N, n) with N = {n}, got {V.shape}")
        dt = np.asarray(self.dt, dtype=float)
        if not (np.all(np.isfinite(dt)) and np.all(dt > 0)):
            raise SimInputError(f"sample period dt [s] must be > 0, got {self.dt!r}")

    @property
    def n(self) -> int:
        return int(np.asarray(self.blocked).size)

    def subset(self, idx) -> "Runs":
        """The runs idx (index array) as their own Runs."""
        dt = self.dt if np.ndim(self.dt) == 0 else np.asarray(self.dt)[idx]
        tol = None if self.tol_y is None else np.broadcast_to(self.tol_y, (self.n,))[idx]
        return Runs(params={k: np.asarray(v, dtype=float)[idx] for k, v in self.params.items()},
                    blocked=np.asarray(self.blocked)[idx], V=np.asarray(self.V)[idx], dt=dt, hold=self.hold,
                    tol_y=tol)


def simulate_by_period(runs: Runs, schedule: Schedule = Schedule()) -> list:
    """:func:`simulate` per sample period: [(run indices (array), SimResult)], one entry per distinct dt."""
    dts = np.broadcast_to(np.asarray(runs.dt, dtype=float), (runs.n,))
    out = []
    for d in np.unique(dts):
        idx = np.flatnonzero(dts == d)
        sub = runs.subset(idx)
        out.append((idx, simulate(Runs(params=sub.params, blocked=sub.blocked, V=sub.V, dt=float(d),
                                       hold=sub.hold, tol_y=sub.tol_y), schedule)))
    return out


def simulate(runs: Runs, schedule: Schedule = Schedule()) -> SimResult:
    """Integrate the runs (one sample period: see :func:`simulate_by_period` for several).

    Parameters
    ----------
    runs : Runs
        Parameters, modes and inputs of the N runs.
    schedule : Schedule
        Duration and step schedule of constant-input runs (ignored with per-sample inputs: their grid
        is the input's).

    Returns
    -------
    SimResult
        t [s] (local, from the input onset), I [A], x (x_sensor [m]), F (F_sensor [N]), contact;
        y: the reading of each run's test (F blocked, x free).
    """
    dts = np.unique(np.asarray(runs.dt, dtype=float))
    if dts.size != 1:
        raise SimInputError("simulate needs one sample period; use simulate_by_period")
    with np.errstate(all="ignore"):
        return _simulate(runs, float(dts[0]), schedule)


def _simulate(runs: Runs, dt: float, schedule: Schedule) -> SimResult:
    c = physics.constants(runs)
    return _Integration(c, dt, physics.substeps(c, dt), schedule).run()


class _Integration:
    """One batch: the step schedule and the outputs; the stepping itself (and the freezing of settled runs)
    in the compiled core (:func:`harness.sim.core.run_part`). Every run's steps are its own (fine: n_sub; coarse:
    from its own rates), so a run's result does not depend on the other runs of its batch; runs are grouped by
    n_sub only for the output times, those of the group with the fewest sub-steps among the runs whose sub-steps
    are fixed (runs with a lag of its own rate, ``harness.sim.core.C_OWNK`` > 0 in their parameter block, whose
    sub-steps follow their speed, give the output times only in a batch of such runs; so the output times of the
    other runs do not depend on whether such runs share their batch)."""

    def __init__(self, c: dict, dt: float, n_sub: np.ndarray, schedule: Schedule):
        self.c, self.dt, self.n_sub, self.sch = c, dt, n_sub, schedule
        V = c["V"]
        self.const_v = V.ndim == 1
        if self.const_v:
            n_all = int(round(schedule.t_end / dt))
            fine = schedule.fine_s if schedule.fine_s is not None else schedule.t_end
            n_fine = min(n_all, int(round(fine / dt)))
            n_coarse = (n_all - n_fine) // schedule.coarse_out
            tail = n_all - n_fine - n_coarse * schedule.coarse_out
            self.sched = [("fine", n_fine), ("coarse", n_coarse), ("tail", tail)]
            n_out = 1 + n_fine + n_coarse + tail
        else:
            n_int = V.shape[1] - (1 if c["hold"] == "linear" else 0)
            self.sched = [("fine", n_int)]
            n_out = 1 + n_int
        self.t_out = np.zeros(n_out)
        self.col = 1
        self.t = 0.0

    def _spacing(self, kind: str) -> int:
        return self.sch.coarse_out if kind == "coarse" else 1

    def _steps(self, kind: str, active: np.ndarray) -> tuple:
        """(step [s], steps per output) per run in a part of the schedule (active: the runs still stepping)."""
        if kind == "fine":
            return self.dt / self.n_sub, self.n_sub.astype(float)
        # quasi-static remainder: the fast modes have decayed; RK4 stays stable for them while
        # max(omega, C/m) * h <= 2.4 (its stability region reaches 2.6-2.8) and follows the slow
        # states (heating, creep) closely
        every = self._spacing(kind)
        rate = physics.coarse_rate(self.c)
        per = np.ones(active.size)
        while True:
            more = (per < 256) & ~(every * self.dt / per * rate <= 1.0)
            if not more.any():
                break
            per[more] *= 2
        return every * self.dt / per, per

    def _times(self, kind: str, n: int):
        """Output times of the next n outputs of a part and the settle checks after them (constant input,
        fine part: every 50 outputs after 0.1 s)."""
        sp = self._spacing(kind)
        t = np.empty(n)
        check = np.zeros(n, dtype=bool)
        for k in range(n):
            self.t += self.dt * sp
            t[k] = self.t
            check[k] = self.const_v and kind == "fine" and (self.col + k + 1) % 50 == 1 and self.t > 0.1
        return t, check

    def run(self) -> SimResult:
        c = self.c
        P = physics.param_blocks(c)
        S = core.new_state(P)
        N = P.shape[0]
        out = np.zeros((4, N, self.t_out.size))
        last = np.zeros(N, dtype=np.intp)
        V = np.ascontiguousarray(c["V"].reshape(N, -1))
        mode = 0 if self.const_v else (2 if c["hold"] == "linear" else 1)
        own = P[:, core.C_OWNK] > 0     # sub-steps that follow the speed reached
        fixed = self.n_sub if own.all() else np.where(own, -1, self.n_sub)
        # the output times are those of the group with the fewest fixed sub-steps
        ks = np.unique(fixed[fixed >= 0])
        first = np.flatnonzero(fixed == ks[0]) if ks.size else np.arange(fixed.size)
        i_act = core.STATE_COLUMNS.index("active")
        tau = c[physics.EXACT_TAU]
        for kind, n_int in self.sched:
            if n_int <= 0:
                continue
            active = S[:, i_act] != 0.0
            if not active.any():
                self._times_only(kind, n_int)
                continue
            col0 = self.col
            P[:, core.C_H], P[:, core.C_PER] = self._steps(kind, active)
            P[:, core.C_LAGE] = np.where(tau > 0, np.exp(-P[:, core.C_H] / np.where(tau > 0, tau, 1.0)), 0.0)
            first_on = active[first].any()
            if first_on:
                t, check = self._times(kind, n_int)
            else:
                self._times_only(kind, n_int)
                check = np.zeros(n_int, dtype=bool)
            core.run_part(P, c["kt"].coef, S, V, out, np.array([n_int, col0, mode, self.sch.tol_I]), check, last)
            if not first_on:
                continue
            n_done = int(last[first].max()) - col0 + 1
            if n_done < n_int:
                # the first group froze before the end of the part: its remaining output times as its
                # stepping loop gave them (one multiplication, not a running sum)
                self.t, self.col = t[n_done - 1], col0 + n_done
                self._times_only(kind, n_int - n_done)
                t = np.concatenate([t[:n_done], self.t_out[col0 + n_done:self.col]])
            self.t_out[col0:col0 + n_int] = t
            self.col = col0 + n_int
        # frozen runs keep their last outputs
        col = self.col
        for r in np.flatnonzero(last < col - 1):
            lr = last[r]
            out[:, r, lr + 1:col] = out[:, r, lr:lr + 1]
        return SimResult(t=self.t_out[:col], blocked=c["blocked"].copy(), I=out[0, :, :col], x=out[1, :, :col],
                         F=out[2, :, :col], contact=out[3, :, :col] != 0.0)

    def _times_only(self, kind: str, n: int) -> None:
        """Output times of n outputs of a part (every run of the first group frozen)."""
        if n <= 0:
            return
        sp = self._spacing(kind)
        self.t_out[self.col:self.col + n] = self.t + self.dt * sp * np.arange(1, n + 1)
        self.t += self.dt * sp * n
        self.col += n
