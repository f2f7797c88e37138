"""Model fits of the diagnosis: the refit and the candidates (in parallel processes); the paper baseline's C and m
fit (``baseline.paper_baseline``) uses its evaluator.

Weighted least squares (residuals / noise) with the batched Levenberg-Marquardt of
``harness.analysis.core.lsq``: several problems in lock-step so that one simulation batch serves them all.
A model (a set of effects) is fitted to every sample: the shared effect parameters jointly with the base
parameters of the shared-fit samples (up to ``max_shared_samples`` spread over the diameters), then
every other sample's base parameters with the effect parameters fixed (held-out samples; which is which:
``heldout``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from harness.parallel import process_pool
from harness.analysis.core import cpu_clock
from harness.analysis.core.lsq import BoxProblem, LMSettings, check_length, jacobian, levenberg_marquardt
from harness.analysis.discovery.library import default_library

from .candidates import SLOW_EFFECTS, base_bounds, coil_radius_def, free_mask, make_params, shared_defs
from .heldout import shared_fit_samples
from .prepare import noise_rel_sd
from .jobs import JobOptions, chi2_parts, param_key, residual_parts, run_jobs, shortest_compared_period_s


@dataclass(frozen=True)
class Screening:
    """Why a candidate was screened out: after ``iterations`` its chi-square on the shared-fit samples fell
    by ``delta_chi2_shared_samples``, less than ``bic_penalty`` = k ln n."""
    iterations: int
    delta_chi2_shared_samples: float
    bic_penalty: float


@dataclass(frozen=True, eq=False)
class ModelFit:
    """A model (set of effects) fitted to every sample.

    ``shared`` {key: fitted value}; ``base`` {sample index: log base vector}; ``params`` {sample index:
    Params}; ``fit_chi2``/``heldout`` {sample index: {(test, channel): Chi2}} on the fit / held-out tests;
    ``screened`` set when the candidate was screened out (it is then not evaluated further); ``cut_short``:
    the fits of this model that stopped on a limit (iterations or the time budget) rather than at a minimum,
    each ``{"fit": what was fitted, "stop": "max_iter" | "time_budget", "iterations": n}``; ``noise_rel_sd``:
    {(test, channel): relative standard uncertainty of the noise level the residuals are divided by}
    (:func:`noise_rel_sd`; 0 where absent), which :meth:`structure` allows for; ``allowance``: {(held-out test,
    channel): (mean, variance)} of the chi-square the fitted parameters' own uncertainty adds to a held-out test
    (:func:`harness.analysis.diagnosis.allowance.prediction_allowance`; empty: not computed, none allowed), which :meth:`structure` allows for.
    """
    effects: tuple
    shared: dict
    base: dict
    params: dict
    fit_chi2: dict
    heldout: dict | None = None
    screened: Screening | None = None
    cut_short: tuple = ()
    noise_rel_sd: dict = field(default_factory=dict)
    allowance: dict = field(default_factory=dict)

    def chi2(self, which: str = "fit", samples=None) -> float:
        """Chi-square on the fit ("fit") or held-out ("heldout") tests, over ``samples`` (indices; all: None)."""
        d = self.fit_chi2 if which == "fit" else self.heldout
        return float(sum(c for i, v in d.items() if samples is None or i in samples for c, _ in v.values()))

    def n(self, which: str = "fit") -> int:
        """Number of residuals on the fit or held-out tests."""
        d = self.fit_chi2 if which == "fit" else self.heldout
        return int(sum(k for v in d.values() for _, k in v.values()))

    def structure(self) -> dict:
        """Excess chi-square per (test, channel), summed over samples:
        z = (chi2 - n - mu)/sqrt(2 n + (2 e n)^2 + var).

        e: the relative standard uncertainty of the noise level of that (test, channel) (``noise_rel_sd``): a
        noise level estimated from few readings scales chi2 by (1 + d)^-2, d ~ N(0, e^2), i.e. adds a variance
        of about (2 e n)^2 to chi2's 2 n; a level known exactly (e = 0) leaves the plain z. (mu, var): the
        ``allowance``, the mean and variance of the chi-square that the fitted parameters' own uncertainty adds
        to a held-out test's prediction and the step instants' to a step test (0, 0 where none was computed)."""
        acc = {}
        for d in (self.fit_chi2, self.heldout or {}):
            for i, parts in d.items():
                for k, (c, m) in parts.items():
                    a = acc.setdefault(k, [0.0, 0])
                    a[0] += c
                    a[1] += m
        e, al = self.noise_rel_sd, self.allowance
        return {k: (c - m - al.get(k, (0.0, 0.0))[0])
                / math.sqrt(2.0 * m + (2.0 * e.get(k, 0.0) * m) ** 2 + al.get(k, (0.0, 0.0))[1])
                for k, (c, m) in acc.items() if m > 0}


@dataclass(frozen=True, eq=False)
class ModelSpec:
    """A model to fit: its ``effects``, start log base vectors {sample index: vector} and start values of
    its shared parameters {key: fitted value} (missing keys: the catalogue's start value)."""
    effects: tuple
    start_base: dict
    shared_init: dict | None = None


@dataclass(frozen=True)
class FitProblem:
    box: BoxProblem
    jobs: Callable            # x -> [(sample index, Params)]
    prior: Callable | None = None    # x -> extra residuals of Gaussian priors (a fixed number), or None

    def residuals(self, x, vector) -> np.ndarray:
        """The data residual ``vector`` of the point ``x`` followed by the prior's residuals."""
        return vector if self.prior is None else np.concatenate([vector, self.prior(x)])


def TIGHT_LM(max_iter: int, deadline_s: float | None) -> LMSettings:
    """Stopping rules of a fit that must converge beyond the fit data's own resolution: the reference (paper) model
    when it carries a nuisance parameter (a derived coil radius). Its direction is weakly determined by the fit
    tests (chi-square changes of order 1) but moves the held-out predictions by many noise floors; the default
    rules (a step lowering the cost by less than 2 ends the fit) stopped a 100 Hz and a 787 Hz fit 2 % short in a
    (property-test findings), so this one runs on to 1e-8 relative and 0.05 absolute, at least 40 iterations."""
    return LMSettings(max_iter=max(int(max_iter), 40), ftol=1e-8, atol=0.05, deadline_s=deadline_s)


#: the residual cache of an :class:`Evaluator` is emptied when it holds more than this many floats (about
#: 400 MB): bounded by size, not by entries, so that 10 kHz data (10x longer residual vectors) cannot
#: exhaust the memory
CACHE_MAX_FLOATS = 50_000_000
#: simulations in a batch whose cost per simulation may price a round (``Evaluator.dear_s_per_sim``): a smaller
#: batch's cost per simulation is mostly the batch's own overhead
DEAR_MIN_BATCH = 16


class Evaluator:
    """Residual vectors of many parameter points on the tests ``names``, simulated together (one batch per
    call), cached (at most :data:`CACHE_MAX_FLOATS` floats).

    The residuals' layout is an invariant: each (sample, test, channel) keeps the length it had the first
    time, whatever the parameters and whatever else shares the batch (``layout``); a change is a defect and
    raises ``harness.analysis.core.lsq.ResidualLayoutError`` naming the sample, test and channel.
    """

    def __init__(self, samples, names, settings):
        self.samples = samples
        self.names = list(names)
        self.settings = settings
        self.cache = {}
        self.cache_floats = 0
        self.n_sims = 0
        self.sim_cpu_s = 0.0      # [s] CPU-clock time of those simulations
        #: [s] the dearest CPU cost of one simulation in a batch of at least DEAR_MIN_BATCH (prices a round:
        #: FitContext.round_cost_s)
        self.dear_s_per_sim = 0.0
        self.layout = {}          # (sample index, test, channel) -> number of residuals

    def _check_layout(self, i: int, parts: dict) -> None:
        for (test, ch), z in parts.items():
            n0 = self.layout.setdefault((i, test, ch), z.size)
            check_length(f"sample {self.samples[i].sid}, test {test}, signal {ch}", n0, z.size)

    def parts(self, jobs) -> list:
        """Residual parts {(test, channel): z} for each job (sample index, Params)."""
        keys = [(i,) + param_key(p) for i, p in jobs]
        todo, seen = [], set()
        for k, (i, p) in zip(keys, jobs):
            if k not in self.cache and k not in seen:
                seen.add(k)
                todo.append((k, i, p))
        got = {}
        if todo:
            t0 = cpu_clock.now()
            sims = run_jobs([(self.samples[i], p) for _, i, p in todo], self.names,
                            JobOptions(fine_s=self.settings.fine_s, fit_gaps=True,
                                       max_rate_hz=self.settings.max_rate_hz))
            self.n_sims += len(todo)
            cost_s = cpu_clock.now() - t0
            self.sim_cpu_s += cost_s
            if len(todo) >= DEAR_MIN_BATCH:
                self.dear_s_per_sim = max(self.dear_s_per_sim, cost_s / len(todo))
            for (k, i, p), s in zip(todo, sims):
                got[k] = residual_parts(self.samples[i], s, self.names, self.settings.sweep_robust_c)
                self._check_layout(i, got[k])
        out = [got[k] if k in got else self.cache[k] for k in keys]
        size = sum(z.size for parts in got.values() for z in parts.values())
        if self.cache_floats + size > CACHE_MAX_FLOATS:
            self.cache.clear()
            self.cache_floats = 0
        self.cache.update(got)
        self.cache_floats += size
        return out

    def vectors(self, points) -> list:
        """points: list of job lists; returns the concatenated residual vector of each point."""
        flat = [j for pt in points for j in pt]
        parts = self.parts(flat)
        out, pos = [], 0
        for pt in points:
            vec = [np.concatenate([parts[pos + q][k] for k in sorted(parts[pos + q])]) for q in range(len(pt))]
            out.append(np.concatenate(vec) if vec else np.zeros(0))
            pos += len(pt)
        return out

    def solve(self, problems, max_iter: int, deadline_s: float | None = None, tight: bool = False) -> list:
        """Levenberg-Marquardt on fit problems in lock-step (no iteration starts after the CPU-clock
        (:mod:`harness.analysis.core.cpu_clock`) instant ``deadline_s``); returns ``harness.analysis.core.lsq.LMResult`` each."""
        def residuals(pts):
            vs = self.vectors([problems[i].jobs(x) for i, x in pts])
            return [problems[i].residuals(x, v) for (i, x), v in zip(pts, vs)]

        return levenberg_marquardt([p.box for p in problems], residuals,
                                   TIGHT_LM(max_iter, deadline_s) if tight else
                                   LMSettings(max_iter=max_iter, deadline_s=deadline_s))


@dataclass
class _Spec:
    """A model being fitted (mutable working state of :meth:`FitContext.fit_many`)."""
    effects: tuple
    defs: list
    free: np.ndarray
    sh: dict
    base: dict
    screened: Screening | None = None
    params: dict = field(default_factory=dict)
    cut_short: list = field(default_factory=list)

    def note(self, problem, res) -> None:
        """Record a fit that stopped on a limit (``res.cut_short``)."""
        if res.cut_short:
            self.cut_short.append({"fit": problem.box.label, "stop": res.stop, "iterations": res.iterations})

    @property
    def nf(self) -> int:
        return int(self.free.sum())


class FitContext:
    """The samples, settings, shared-fit samples, base bounds and residual evaluator of the fits."""

    def __init__(self, samples, settings, deadline_s: float | None = None, coil_rel_sd: float = 0.0):
        self.samples = samples
        # a loop radius derived from the data (relative uncertainty coil_rel_sd > 0) is refined with every model
        self.nuisance = [coil_radius_def(coil_rel_sd)] if coil_rel_sd > 0 else []
        self.settings = settings
        self.fit_names = list(settings.fit_tests)
        self.heldout_names = list(settings.heldout_tests)
        self.ev = Evaluator(samples, self.fit_names, settings)
        self.shared_idx = shared_fit_samples(samples, settings)
        self.noise_rel_sd = noise_rel_sd(samples)
        # the discovery terms as the fits resolve these data: lags no faster than a tenth of the shortest period
        # compared (the sample period, or every q-th sample of a rig faster than max_rate_hz)
        self.library = default_library().at_resolution(shortest_compared_period_s(samples, self.fit_names,
                                                                                  settings.max_rate_hz))
        self.tight = False           # fits to TIGHT_LM tolerances (the reference model with nuisance parameters)
        self.bounds = {}
        self.allowance = {}          # held-out prediction allowance given to every ModelFit (prediction_allowance)
        # the CPU-clock instant after which no fit iteration starts (the diagnosis's fit budget; the clock's
        # reading carries into forked worker processes, and back from them: harness.analysis.core.cpu_clock)
        self.deadline_s = cpu_clock.now() + settings.fit_budget_s if deadline_s is None else deadline_s

    def round_cost_s(self, models) -> float:
        """[s] A lower bound on the CPU-clock time (critical path over ``settings.workers`` processes) that fitting
        ``models`` [ModelSpec] in one round takes before any of their fits completes one iteration: each joint fit's
        start point and its first Jacobian (``1 + columns`` simulations of each shared-fit sample); 0 before any
        simulation was measured. The price of a simulation is the dearest measured so far in a batch
        (``Evaluator.dear_s_per_sim``, from every process's fits), else the mean of this process's: the round's models
        extend the one chosen last, whose simulations were among the dearest (session 21: a round of terms added to
        a fitted creep lag cost 0.35 CPU-s a simulation where the mean had been 0.013). The fits of one process run
        in lock-step, so until that bound is paid no fit of the round has taken a step."""
        ev = self.ev
        price_s = ev.dear_s_per_sim or (ev.sim_cpu_s / ev.n_sims if ev.n_sims else 0.0)
        if not price_s:
            return 0.0
        nS = len(self.shared_idx)
        sims = []
        for m in models:
            k = len(self.defs_of(m.effects))
            if k:
                sims.append(nS * (1 + int(free_mask(m.effects).sum()) * nS + k))
        if not sims:
            return 0.0
        groups = max(1, min(int(self.settings.workers), len(sims)))
        per_group = math.ceil(len(sims) / groups) * (sum(sims) / len(sims))
        return per_group * price_s

    def can_afford(self, models) -> bool:
        """The budget left pays for a round fitting ``models`` [ModelSpec] at least one iteration
        (:meth:`round_cost_s` within the joint fits' share of it, :meth:`joint_share`): a round that cannot would
        end with every fit at its start point (cut by the budget after 0 iterations, hence screened out), having
        simulated every start point past the deadline (session 21: a second discovery round of 17 fits at 10 kHz
        began with 17 CPU-s left and took 55 more)."""
        left = self.deadline_s - cpu_clock.now()
        return left > 0 and self.round_cost_s(models) <= left * self.joint_share()

    def joint_share(self) -> float:
        """The share of the budget left that the joint fits of the shared-fit samples get: |S| / n, so that the
        samples fitted after them get theirs (1 when every sample is in the shared fit)."""
        n, nS = len(self.samples), len(self.shared_idx)
        return nS / n if nS < n else 1.0

    def solve(self, problems, max_iter: int, deadline_s: float | None = None) -> list:
        """:meth:`Evaluator.solve` within the diagnosis's time budget (or the earlier CPU-clock instant
        ``deadline_s``); to tight tolerances (:data:`TIGHT_LM`) while ``self.tight`` is set."""
        dl = self.deadline_s if deadline_s is None else min(self.deadline_s, deadline_s)
        return self.ev.solve(problems, max_iter, dl, self.tight)

    def joint_deadline(self, specs) -> float | None:
        """The CPU-clock instant the joint fits of ``specs`` end by: their share (:meth:`joint_share`) of the budget
        left, so that the samples fitted after them get theirs (None: no other sample follows). Else a candidate's
        held-out sample could keep its start and lose the candidate the fit data (deep profile, session 13: BIC
        +2.9e8)."""
        share = self.joint_share()
        if share >= 1.0 or not any(sp.defs for sp in specs):
            return None
        now = cpu_clock.now()
        return now + max(self.deadline_s - now, 0.0) * share

    def set_bounds(self, start: dict):
        """Bounds of every sample's base parameters around the refit's start (log vectors)."""
        self.bounds = {i: base_bounds(b, self.samples[i].D) for i, b in start.items()}

    def clip_base(self, i: int, b) -> np.ndarray:
        """Sample ``i``'s log base vector ``b`` within its bounds (:meth:`set_bounds`)."""
        lo, hi = self.bounds[i]
        return np.clip(np.asarray(b, dtype=float), lo, hi)

    def defs_of(self, effects) -> list:
        """The shared parameters fitted with a model of ``effects``: the effects' and the nuisance ones (the coil
        radius when derived from the data)."""
        return shared_defs(effects, self.library) + self.nuisance

    def shared_problem(self, effects, base: dict, sh: dict) -> tuple:
        """The joint problem of the shared-fit samples: (problem, x) with x = [free base of each, shared]."""
        defs = self.defs_of(effects)
        free = free_mask(effects)
        nf = int(free.sum())
        S = self.shared_idx
        samples = self.samples
        base = {i: np.asarray(b, dtype=float).copy() for i, b in base.items()}
        x0 = np.concatenate([base[i][free] for i in S] + [np.array([sh[d.key] for d in defs])])
        lo = np.concatenate([self.bounds[i][0][free] for i in S] + [np.array([d.lo for d in defs])])
        hi = np.concatenate([self.bounds[i][1][free] for i in S] + [np.array([d.hi for d in defs])])
        fd = np.concatenate([np.full(nf * len(S), 1e-5), np.array([d.fd for d in defs])])

        def jobs(x):
            shv = {d.key: x[nf * len(S) + k] for k, d in enumerate(defs)}
            out = []
            for j, i in enumerate(S):
                b = base[i].copy()
                b[free] = x[j * nf:(j + 1) * nf]
                out.append((i, make_params(samples[i], b, shv)))
            return out

        label = (f"joint fit of {'+'.join(effects) or 'the paper model'} on samples "
                 f"{', '.join(samples[i].sid for i in S)}")
        pri = [(nf * len(S) + k, d.init, d.prior_sd) for k, d in enumerate(defs) if d.prior_sd]
        prior = None
        if pri:
            k_, c_, s_ = (np.array(v, dtype=float) for v in zip(*pri))

            def prior(x):
                return (np.asarray(x, dtype=float)[k_.astype(int)] - c_) / s_
        return FitProblem(BoxProblem(x0, lo, hi, fd, label=label), jobs, prior), x0

    def _take(self, sp: _Spec, x):
        nf, S = sp.nf, self.shared_idx
        for j, i in enumerate(S):
            sp.base[i][sp.free] = x[j * nf:(j + 1) * nf]
        sp.sh = {d.key: float(x[nf * len(S) + k]) for k, d in enumerate(sp.defs)}

    def _fit_shared(self, specs: list, max_iter: int, reference: ModelFit | None):
        """Joint fits of the shared-fit samples (a screening pass first when there is a reference), within their
        share of the budget (:meth:`joint_deadline`)."""
        st = self.settings
        S = self.shared_idx
        dl = self.joint_deadline(specs)
        probs, owners = [], []
        for sp in specs:
            if sp.defs:
                probs.append(self.shared_problem(sp.effects, sp.base, sp.sh)[0])
                owners.append(sp)
        if probs and reference is not None and st.screen_iter:
            ref_S = sum(c for i in S for c, _ in reference.fit_chi2[i].values())
            n_all = reference.n("fit")
            keep_p, keep_o = [], []
            for sp, prob, res in zip(owners, probs, self.solve(probs, st.screen_iter, dl)):
                self._take(sp, res.x)
                if res.stop == "time_budget":
                    sp.note(self.shared_problem(sp.effects, sp.base, sp.sh)[0], res)
                k = len(sp.defs) - len(self.defs_of(reference.effects))
                # the data's chi-square against the reference's (the LM cost also holds the nuisance prior's
                # residuals, which ref_S does not: a refit that moved the derived radius by 30 prior sd screened
                # out every candidate by that prior's chi-square, 919)
                pr = prob.prior(res.x) if prob.prior is not None else np.zeros(0)
                gain = ref_S - (res.cost - float(pr @ pr))
                if gain < k * math.log(max(n_all, 2)):
                    sp.screened = Screening(iterations=st.screen_iter, delta_chi2_shared_samples=gain,
                                            bic_penalty=k * math.log(max(n_all, 2)))
                else:
                    keep_p.append(self.shared_problem(sp.effects, sp.base, sp.sh)[0])
                    keep_o.append(sp)
            probs, owners = keep_p, keep_o
        if probs:
            for sp, prob, res in zip(owners, probs, self.solve(probs, max_iter, dl)):
                self._take(sp, res.x)
                sp.note(prob, res)

    def _fit_others(self, specs: list, max_iter: int):
        """Per-sample fits of the samples outside the shared fit (of all, for a model without shared parameters)."""
        samples, S = self.samples, self.shared_idx
        probs, owners = [], []
        for sp in specs:
            if sp.screened:
                continue
            for i in range(len(samples)):
                if sp.defs and i in S:
                    continue
                free, base, sh = sp.free, sp.base, sp.sh

                def jobs(x, i=i, free=free, base=base, sh=sh):
                    b = base[i].copy()
                    b[free] = x
                    return [(i, make_params(samples[i], b, sh))]

                x0 = base[i][free]
                box = BoxProblem(x0, self.bounds[i][0][free], self.bounds[i][1][free], np.full(x0.size, 1e-5),
                                 label=f"fit of {'+'.join(sp.effects) or 'the paper model'} on sample {samples[i].sid}")
                probs.append(FitProblem(box, jobs))
                owners.append((sp, i))
        if probs:
            for (sp, i), prob, res in zip(owners, probs, self.solve(probs, max_iter)):
                sp.base[i][sp.free] = res.x
                sp.note(prob, res)

    def fit_many(self, models, max_iter: int | None = None, reference: ModelFit | None = None) -> list:
        """Fit models [ModelSpec] in lock-step; returns a ModelFit each.

        Shared effect parameters and the samples' free base parameters are fitted jointly on the
        shared-fit samples; then every other sample's free base parameters with the shared ones fixed.
        With a ``reference`` model (the one the candidates extend, started from its optimum with the
        new effects off), a candidate whose fit on the shared-fit samples has not paid for its extra
        parameters (chi-square decrease < k ln n) after ``settings.screen_iter`` iterations is screened
        out: it cannot reach the BIC threshold (its fit is left there and it is not evaluated further).
        """
        max_iter = max_iter or self.settings.max_iter
        specs = []
        for m in models:
            defs = self.defs_of(m.effects)
            base = {i: np.asarray(b, dtype=float).copy() for i, b in m.start_base.items()}
            free = free_mask(m.effects)
            sh0 = {d.key: (m.shared_init or {}).get(d.key, d.init) for d in defs}
            specs.append(_Spec(effects=tuple(m.effects), defs=defs, free=free, sh=sh0, base=base))
        self._fit_shared(specs, max_iter, reference)
        self._fit_others(specs, max_iter)
        n = len(self.samples)
        allj = []
        for sp in specs:
            sp.params = {i: make_params(self.samples[i], sp.base[i], sp.sh) for i in range(n)}
            allj += [(i, sp.params[i]) for i in range(n)]
        parts = self.ev.parts(allj)
        return [ModelFit(effects=sp.effects, shared=sp.sh, base=sp.base, params=sp.params,
                         fit_chi2={i: chi2_parts(parts[q * n + i]) for i in range(n)}, screened=sp.screened,
                         cut_short=tuple(sp.cut_short), noise_rel_sd=self.noise_rel_sd, allowance=self.allowance)
                for q, sp in enumerate(specs)]

    def fit_chi2_of(self, params: dict) -> dict:
        """{sample index: {(test, channel): Chi2}} of Params {sample index: Params} on the fit tests."""
        n = len(self.samples)
        return {i: chi2_parts(pp) for i, pp in enumerate(self.ev.parts([(i, params[i]) for i in range(n)]))}

    def shared_uncertainty(self, mf: ModelFit) -> dict:
        """Standard uncertainty of the shared parameters (natural units) from the Jacobian of the shared fit.

        cov = s^2 (J^T J)^-1 over every jointly fitted parameter (the shared-fit samples' base
        parameters included), s^2 = max(1, chi2/dof).
        """
        defs = self.defs_of(mf.effects)
        if not defs:
            return {}
        prob, x = self.shared_problem(mf.effects, mf.base, mf.shared)
        J, r = jacobian(prob.box, x, lambda xs: [prob.residuals(xp, v) for xp, v in
                                                 zip(xs, self.ev.vectors([prob.jobs(xp) for xp in xs]))])
        dof = max(1, r.size - x.size)
        s2 = max(1.0, float(r @ r) / dof)
        cov = s2 * np.linalg.pinv(J.T @ J)
        k0 = x.size - len(defs)
        out = {}
        for k, d in enumerate(defs):
            sd = math.sqrt(max(float(cov[k0 + k, k0 + k]), 0.0))
            out[d.key] = math.exp(mf.shared[d.key]) * sd if d.log else sd
        return out

    def simulate(self, mfs, names) -> list:
        """Simulations of models on the tests ``names`` on the measured grids (one batch for all):
        per model {sample index: {test: SeriesSim | SweepSim}}."""
        names = list(names)
        n = len(self.samples)
        sims = run_jobs([(self.samples[i], mf.params[i]) for mf in mfs for i in range(n)], names,
                        JobOptions(full=True, max_rate_hz=self.settings.max_rate_hz))
        return [{i: sims[q * n + i] for i in range(n)} for q in range(len(mfs))]

    def evaluate(self, mfs) -> list:
        """The models with their held-out chi-square (lock-step: one simulation batch for all of them)."""
        out = []
        for mf, sims in zip(mfs, self.simulate(mfs, self.heldout_names)):
            held = {i: chi2_parts(residual_parts(self.samples[i], s, self.heldout_names,
                                                 self.settings.sweep_robust_c)) for i, s in sims.items()}
            out.append(replace(mf, heldout=held, allowance=self.allowance))
        return out


# ============================================================================ parallel candidate fits
_WORKER_CTX = None


def fit_and_evaluate(ctx: FitContext, models, reference=None) -> list:
    """Fit models [ModelSpec] in lock-step in this process and evaluate the held-out tests of those that were not
    screened out; a ModelFit each (what each worker of :func:`fit_candidates` runs)."""
    mfs = ctx.fit_many(models, reference=reference)
    live = [q for q, mf in enumerate(mfs) if not mf.screened]
    if live:
        for q, mf in zip(live, ctx.evaluate([mfs[q] for q in live])):
            mfs[q] = mf
    return mfs


def _worker_fit(args):
    models, reference = args
    mfs = fit_and_evaluate(_WORKER_CTX, models, reference)
    # the worker's CPU-clock reading goes back with its fits (the parent's clock advances to the latest), and so
    # does its dearest simulation cost (it prices the next round: FitContext.round_cost_s)
    return mfs, cpu_clock.now(), _WORKER_CTX.ev.dear_s_per_sim


def fit_candidates(ctx: FitContext, models, workers: int, reference: ModelFit | None = None) -> list:
    """Fit and evaluate models [ModelSpec], spread over ``workers`` processes (fork); a ModelFit each."""
    global _WORKER_CTX
    if workers <= 1 or len(models) <= 1:
        return fit_and_evaluate(ctx, models, reference)
    # lock-step groups of about equal cost: models with slow states cost more
    slow = [q for q, m in enumerate(models) if set(m.effects) & SLOW_EFFECTS]
    fast = [q for q in range(len(models)) if q not in slow]
    groups = [[] for _ in range(workers)]
    load = [0.0] * workers
    for q in slow + fast:
        g = int(np.argmin(load))
        groups[g].append(q)
        load[g] += 2.0 if q in slow else 1.0
    groups = [g for g in groups if g]
    _WORKER_CTX = ctx
    try:
        with process_pool(len(groups)) as pool:
            futs = [pool.submit(_worker_fit, ([models[q] for q in g], reference)) for g in groups]
            res = []
            for f in futs:
                mfs, reading_s, dear_s = f.result()
                cpu_clock.advance_to(reading_s)
                ctx.ev.dear_s_per_sim = max(ctx.ev.dear_s_per_sim, dear_s)
                res.append(mfs)
    finally:
        _WORKER_CTX = None
    out = [None] * len(models)
    for g, r in zip(groups, res):
        for q, mf in zip(g, r):
            out[q] = mf
    return out
