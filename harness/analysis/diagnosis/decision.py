"""Decision: compare candidates with the model they extend (BIC on the fit data, chi-square on held-out
tests), select the causes by greedy forward selection, and state the verdict.

A candidate is accepted when its BIC is lower than the reference's by more than ``bic_min`` AND its
held-out chi-square is lower by more than ``heldout_min`` (:func:`compare`). The accepted candidate with
the largest score (held-out chi-square decrease - BIC change) is the cause; while the selected model's
residuals still show structure (some test/signal with z > ``z_struct``), each remaining candidate is added
to it in turn (same rule against the selected model) -> ranked causes (:func:`select`). The verdict is one
function, :func:`verdict` (its docstring is the rule): "none", "unexplained", the cause(s), or the cause(s)
"+ unexplained remainder" when the extended model still leaves structure beyond the noise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from harness.analysis.core import cpu_clock
from harness.analysis.discovery import GreedySelector

from .candidates import CANDIDATES, STARTS_ONLY_WHEN_BETTER, extra_starts, make_params, off_init, shared_defs
from .fitting import FitContext, ModelFit, ModelSpec, fit_candidates


class ShowsIn(NamedTuple):
    """A test and channel ("y" reading | "I" current) whose chi-square a candidate lowers, and by how much."""
    test: str
    channel: str
    delta_chi2: float


@dataclass(frozen=True)
class Comparison:
    """A candidate compared with its reference model.

    ``k`` extra (shared) parameters; ``d_fit`` chi-square decrease on the fit data; ``d_bic`` =
    BIC(candidate) - BIC(reference) on the fit data; ``d_heldout`` chi-square decrease on the held-out
    tests; ``score`` = d_heldout - d_bic; ``shared`` natural values of the shared parameters {key: value};
    ``shows_in`` [ShowsIn] largest decrease first; ``cut_short`` the candidate's fits that stopped on a limit
    (``ModelFit.cut_short``).
    """
    name: str
    effects: tuple
    k: int
    d_fit: float
    d_bic: float
    d_heldout: float
    score: float
    accepted: bool
    reason: str
    shared: dict = field(default_factory=dict)
    shows_in: list = field(default_factory=list)
    cut_short: tuple = ()


@dataclass(frozen=True)
class Round:
    """One round of the selection: the effects of the reference model and the comparisons against it."""
    reference: tuple
    comparisons: tuple


REMAINDER = "unexplained remainder"
DISCOVERED = "discovered"


@dataclass(frozen=True)
class Verdict:
    """The diagnosis's answer (:func:`verdict`).

    ``cause``: the first cause (catalogue name), "discovered" (only discovered terms), "none" or "unexplained";
    ``label``: the whole answer ("none", "unexplained", "filler_saturation", "coil_heating + viscoelastic_creep",
    "coil_heating + unexplained remainder", "discovered:quad_drag", ...); ``causes``: catalogue names,
    strongest first; ``terms``: discovered terms (``fmu_src.terms.TERMS`` names) in the order taken;
    ``remainder``: the (test, channel, z) of the model the verdict rests on (the extended model, or the
    refitted paper model when nothing was accepted) whose structure exceeds the noise, largest first;
    ``reason``: one sentence saying why.
    """
    cause: str
    label: str
    causes: tuple
    remainder: tuple
    reason: str
    terms: tuple = ()
    #: the candidates of the round that ended the selection whose fits the time budget cut while the fit data
    #: supported them (BIC) and the held-out tests did not confirm them (:func:`budget_bound`): (name, iterations of
    #: the cut joint fit) each; the verdict is then not decided by the data but by the budget, and its reason says so
    undecided: tuple = ()

    @property
    def has_remainder(self) -> bool:
        """True when some structure beyond the noise is left unexplained by the named causes and terms."""
        return bool(self.remainder) and bool(self.causes or self.terms)

    @property
    def needs_discovery(self) -> bool:
        """The catalogue stage left structure beyond the noise ("unexplained" or "+ unexplained remainder")."""
        return bool(self.remainder)


def budget_bound(comparisons, bic_min: float) -> tuple:
    """((name, iterations), ...) of the ``comparisons`` [Comparison] not accepted although the fit data supported
    them (BIC lower by more than ``bic_min``) and whose fits the time budget cut (``cut_short`` with stop
    "time_budget"; iterations: the fewest of their cut fits): the held-out tests judged a fit that had not
    converged, so the budget, not the data, decided against them."""
    out = []
    for c in comparisons:
        cut = [q["iterations"] for q in c.cut_short if q.get("stop") == "time_budget"]
        if cut and not c.accepted and math.isfinite(c.d_bic) and c.d_bic < -bic_min:
            out.append((c.name, int(min(cut))))
    return tuple(out)


def with_undecided(v: Verdict, undecided: tuple) -> Verdict:
    """``v`` with the candidates the budget left undecided (:func:`budget_bound`), named in its reason."""
    if not undecided:
        return v
    names = ", ".join(f"{n} (cut after {k} iteration{'s' if k != 1 else ''})" for n, k in undecided)
    return replace(v, undecided=tuple(undecided),
                   reason=f"{v.reason}; not decided within the fit budget (fit_budget_s): {names}: the fit data "
                          f"supported {'it' if len(undecided) == 1 else 'them'} (BIC), but the time budget cut "
                          f"{'its fit' if len(undecided) == 1 else 'their fits'} before convergence and the held-out "
                          f"tests judged the unconverged fit (fits_cut_short); a larger fit_budget_s may decide")


def _where(q) -> str:
    return f"{q[0]} {'current' if q[1] == 'I' else 'reading'}"


def _structured(structure: dict, z_struct: float) -> tuple:
    return tuple(sorted(((t, ch, float(z)) for (t, ch), z in structure.items() if z > z_struct),
                        key=lambda q: -q[2]))


def term_label(name: str) -> str:
    """How a discovered term stands in the verdict: "discovered:<name>"."""
    return f"{DISCOVERED}:{name}"


def verdict(causes, refit_structure: dict, final_structure: dict, z_struct: float, terms=()) -> Verdict:
    """The decision rule's verdict.

    Parameters
    ----------
    causes : sequence of str
        The accepted causes in the order the greedy forward selection took them (empty: none accepted).
    refit_structure, final_structure : dict
        {(test, channel): z} of the refitted paper model and of the final (extended) model, with
        z = (chi2 - n)/sqrt(2 n) per test and channel summed over the samples (about N(0, 1) for noise; held-out
        tests net of the parameters' prediction allowance;
        ``ModelFit.structure``).
    z_struct : float
        Structure threshold (``DiagnoseSettings.z_struct``).
    terms : sequence of str
        The discovered terms (names of ``fmu_src.terms.TERMS``) in the order the discovery took them.

    Returns
    -------
    Verdict
        - nothing accepted and every refit z <= z_struct: **none** (the paper's model explains the data);
        - nothing accepted and some refit z > z_struct: **unexplained** (structure no candidate explains);
        - causes and/or discovered terms and every final z <= z_struct: the causes and the terms
          ("A", "A + B", "discovered:t", "A + discovered:t"; catalogue causes first, strongest first);
        - causes and/or terms and some final z > z_struct: the same **+ unexplained remainder**: what was
          named improves the fit (it passed BIC and held-out chi-square) but structure beyond the noise is
          left; ``remainder`` lists where.
        ``cause`` is the first catalogue cause, else "discovered" when only terms were accepted.
    """
    causes = tuple(causes)
    named_all = causes + tuple(term_label(t) for t in terms)
    if not named_all:
        rem = _structured(refit_structure, z_struct)
        if not rem:
            return Verdict("none", "none", (), (), f"no candidate accepted and every residual z <= {z_struct:g}: "
                                                   "the paper's model explains the data within the noise")
        return Verdict("unexplained", "unexplained", (), rem,
                       f"no candidate accepted, but the paper model's residuals show structure beyond the noise "
                       f"(largest z {rem[0][2]:.3g} in {_where(rem[0])}, threshold {z_struct:g})")
    rem = _structured(final_structure, z_struct)
    named = " + ".join(named_all)
    cause = causes[0] if causes else DISCOVERED
    if not rem:
        return Verdict(cause, named, causes, (), f"accepted {named}; the extended model leaves every residual "
                                                 f"z <= {z_struct:g}", tuple(terms))
    return Verdict(cause, f"{named} + {REMAINDER}", causes, rem,
                   f"accepted {named}, but the extended model still leaves structure beyond the noise "
                   f"(largest z {rem[0][2]:.3g} in {_where(rem[0])}, threshold {z_struct:g}) that no further "
                   f"candidate explains", tuple(terms))


@dataclass(frozen=True, eq=False)
class Selection:
    """Outcome of :func:`select`: the rounds, the accepted comparisons in order (``chosen``), the final
    model (``final``: the reference itself when nothing was accepted) and the :class:`Verdict`."""
    rounds: tuple
    chosen: tuple
    final: ModelFit
    verdict: Verdict
    #: the discovery stage (``harness.analysis.discovery.selector.Path``: rounds of term comparisons, the terms
    #: chosen, why it stopped) when the catalogue stage left structure and discovery ran, else None
    discovery: object = None
    #: the model of the catalogue stage (before any discovered term): the final one when nothing was discovered
    catalogue_final: ModelFit | None = None
    #: the catalogue stage's verdict (what the diagnosis said before discovery)
    catalogue_verdict: Verdict | None = None

    @property
    def cause(self) -> str:
        """The first cause, "discovered", "none" or "unexplained" (``verdict.cause``)."""
        return self.verdict.cause

    @property
    def terms(self) -> tuple:
        """The comparisons of the discovered terms, in the order taken (empty without discovery)."""
        return tuple(self.discovery.chosen) if self.discovery is not None else ()

    @property
    def first_round(self) -> tuple:
        """The comparisons of every candidate against the refitted paper model."""
        return self.rounds[0].comparisons


def _screened(cand: ModelFit, k: int, n_fit: int, name: str) -> Comparison:
    sc = cand.screened
    shared = {d.key: d.natural(cand.shared[d.key]) for d in shared_defs(cand.effects)}
    return Comparison(name=name, effects=cand.effects, k=k, d_fit=float("nan"),
                      d_bic=k * math.log(max(n_fit, 2)) - sc.delta_chi2_shared_samples,
                      d_heldout=float("nan"), score=float("-inf"), accepted=False,
                      reason=(f"screened out after {sc.iterations} iterations: on the shared-fit samples "
                              f"the chi-square fell by {sc.delta_chi2_shared_samples:.4g}, less than the BIC "
                              f"penalty {sc.bic_penalty:.4g} of its {k} parameter(s)"),
                      shared=shared, shows_in=[], cut_short=cand.cut_short)


def compare(ref: ModelFit, cand: ModelFit, settings, n_fit: int, name: str) -> Comparison:
    """Compare candidate ``cand`` with reference ``ref`` (BIC with ``n_fit`` fit residuals; held-out chi-square)
    under the thresholds of ``settings`` (``DiagnoseSettings``)."""
    k = len(shared_defs(cand.effects)) - len(shared_defs(ref.effects))
    if cand.screened:
        return _screened(cand, k, n_fit, name)
    d_fit = ref.chi2("fit") - cand.chi2("fit")
    d_bic = -d_fit + k * math.log(max(n_fit, 2))
    d_ho = ref.chi2("heldout") - cand.chi2("heldout")
    ok_bic = d_bic < -settings.bic_min
    ok_ho = d_ho > settings.heldout_min
    if ok_bic and ok_ho:
        reason = (f"BIC falls by {-d_bic:.4g} (> {settings.bic_min:g}) on the fit data and the held-out "
                  f"chi-square by {d_ho:.4g} (> {settings.heldout_min:g})")
    elif not ok_bic:
        reason = (f"no support on the fit data: BIC changes by {d_bic:+.4g} (needs < -{settings.bic_min:g})")
    else:
        reason = (f"the fit improves (BIC {d_bic:+.4g}) but the held-out tests do not confirm it "
                  f"(held-out chi-square falls by {d_ho:.4g}, needs > {settings.heldout_min:g})")
    shared = {d.key: d.natural(cand.shared[d.key]) for d in shared_defs(cand.effects)}
    drop = {}
    for a, b in ((ref.fit_chi2, cand.fit_chi2), (ref.heldout or {}, cand.heldout or {})):
        for i in a:
            for key, (c, _) in a[i].items():
                if i in b and key in b[i]:
                    drop[key] = drop.get(key, 0.0) + c - b[i][key][0]
    shows = sorted((ShowsIn(t, ch, float(v)) for (t, ch), v in drop.items() if v > settings.heldout_min),
                   key=lambda q: -q[2])
    return Comparison(name=name, effects=cand.effects, k=k, d_fit=d_fit, d_bic=d_bic, d_heldout=d_ho,
                      score=d_ho - d_bic, accepted=ok_bic and ok_ho, reason=reason, shared=shared, shows_in=shows,
                      cut_short=cand.cut_short)


def runoff(ctx: FitContext, refit: ModelFit, comps: list, fits: list, n_fit: int) -> int | None:
    """The runoff of a round the budget decided (:func:`budget_bound`: nothing accepted, candidates the fit data
    supported but cut before convergence): the one with the largest BIC support goes on alone from where it was
    cut, within ``settings.runoff_budget_s`` more CPU time, and is compared with ``refit`` again. One fit instead of
    every candidate in lock-step: its iterations cost a fraction of the round's. ``comps`` and ``fits`` (same order)
    get its new comparison and fit in place; returns its index if now accepted, else None.

    Deep profile, session 20: a coil heating 100 noise floors strong at 7457 Hz, four samples, was named or left
    "unexplained" depending on whether the budget cut its joint fit after 2 or fewer iterations."""
    st = ctx.settings
    und = dict(budget_bound(comps, st.bic_min))
    if not und or st.runoff_budget_s <= 0:
        return None
    q = min((k for k, c in enumerate(comps) if c.name in und), key=lambda k: comps[k].d_bic)
    mf = fits[q]
    deadline_s = ctx.deadline_s
    ctx.deadline_s = max(deadline_s, cpu_clock.now()) + st.runoff_budget_s
    try:
        cont = ctx.evaluate(ctx.fit_many([ModelSpec(mf.effects, mf.base, dict(mf.shared))]))[0]
    finally:
        ctx.deadline_s = deadline_s          # the round's budget stays spent: no further round starts on the runoff's
    c = compare(refit, cont, st, n_fit, comps[q].name)
    c = replace(c, reason=f"runoff (its fit alone, up to {st.runoff_budget_s:g} CPU-s beyond the budget, after the "
                          f"budget had cut it after {und[comps[q].name]} iteration(s)): {c.reason}")
    comps[q], fits[q] = c, cont          # cut_short: the runoff's own (undecided again only if it was cut too)
    return q if c.accepted else None


def _best_accepted(comps) -> int | None:
    acc = sorted([q for q, c in enumerate(comps) if c.accepted], key=lambda q: -comps[q].score)
    return acc[0] if acc else None


def best_extra_start(ctx: FitContext, effect: str, refit: ModelFit) -> list:
    """[(base, shared_init)]: of the candidate's further starts (``candidates.extra_starts``, within the bounds),
    the one with the lowest chi-square on the fit tests (one evaluation each; one more fit, not one per start);
    empty when it has none, or, for an effect of ``candidates.STARTS_ONLY_WHEN_BETTER``, when none fits the fit
    tests better than the refit itself."""
    starts = [({i: ctx.clip_base(i, b) for i, b in base.items()}, sh)
              for base, sh in extra_starts(effect, ctx.samples, refit.base, refit.shared)]
    gate = effect in STARTS_ONLY_WHEN_BETTER
    if len(starts) <= 1 and not gate:
        return starts
    chi2 = []
    for base, sh in starts:
        parts = ctx.fit_chi2_of({i: make_params(ctx.samples[i], b, sh) for i, b in base.items()})
        chi2.append(sum(c for i in parts for c, _ in parts[i].values()))
    if not starts or (gate and min(chi2) >= refit.chi2("fit")):
        return []
    return [starts[int(np.argmin(chi2))]]


def select(ctx: FitContext, refit: ModelFit, lap=None) -> Selection:
    """Fit every candidate against the refitted paper model ``refit``, then greedy forward selection.

    ``lap(name)`` (optional) is called after the candidate round ("candidates") and after the greedy
    rounds ("greedy") to time them.
    """
    st = ctx.settings
    n_fit = refit.n("fit")
    # every candidate starts at the refit's optimum: its base parameters and its nuisance ones (the derived coil
    # radius), with the effect off; an effect that changes what the base parameters mean has further starts
    specs, owner = [], []
    for c in CANDIDATES:
        for base, sh in [(refit.base, dict(off_init((c,)), **refit.shared))] + best_extra_start(ctx, c, refit):
            specs.append(ModelSpec((c,), base, sh))
            owner.append(c)
    best = {}
    for c, mf in zip(owner, fit_candidates(ctx, specs, st.workers, reference=refit)):
        if c not in best or _better(mf, best[c]):
            best[c] = mf
    fits = [best[c] for c in CANDIDATES]
    comps = [compare(refit, mf, st, n_fit, c) for c, mf in zip(CANDIDATES, fits)]
    if lap:
        lap("candidates")
    q = _best_accepted(comps)
    if q is None:
        q = runoff(ctx, refit, comps, fits, n_fit)
    rounds = [Round(reference=(), comparisons=tuple(comps))]
    current, chosen = refit, []
    if q is not None:
        current = fits[q]
        chosen.append(comps[q])
        # greedy forward selection while the selected model still leaves structure
        while len(chosen) < st.max_effects and max(current.structure().values()) > st.z_struct:
            others = [c for c in CANDIDATES if c not in current.effects]
            if not others:
                break
            specs = [ModelSpec(current.effects + (c,), current.base, dict(off_init((c,)), **current.shared))
                     for c in others]
            if not ctx.can_afford(specs):
                break               # no round whose fits the budget left cannot take one step (FitContext.can_afford)
            f2 = fit_candidates(ctx, specs, st.workers, reference=current)
            c2 = [compare(current, mf, st, n_fit, c) for c, mf in zip(others, f2)]
            rounds.append(Round(reference=tuple(current.effects), comparisons=tuple(c2)))
            q = _best_accepted(c2)
            if q is None:
                break
            current = f2[q]
            chosen.append(c2[q])
        if lap:
            lap("greedy")
    v = verdict([c.name for c in chosen], refit.structure(), current.structure(), st.z_struct)
    v = with_undecided(v, budget_bound(rounds[-1].comparisons, st.bic_min) if v.needs_discovery else ())
    if not (st.discover and v.needs_discovery):
        return Selection(rounds=tuple(rounds), chosen=tuple(chosen), final=current, verdict=v, catalogue_final=current,
                         catalogue_verdict=v)
    path = discover(ctx, current, n_fit)
    if lap:
        lap("discovery")
    v2 = verdict([c.name for c in chosen], refit.structure(), path.final.structure(), st.z_struct,
                 terms=[c.name for c in path.chosen])
    last = path.rounds[-1].comparisons if path.rounds else rounds[-1].comparisons
    v2 = with_undecided(v2, budget_bound(last, st.bic_min) if v2.needs_discovery else ())
    return Selection(rounds=tuple(rounds), chosen=tuple(chosen), final=path.final, verdict=v2, discovery=path,
                     catalogue_final=current, catalogue_verdict=v)


def _better(a: ModelFit, b: ModelFit) -> bool:
    """Fit ``a`` of a term is better than fit ``b`` of it (another start): not screened out where b was, else a
    lower chi-square on the fit tests (the data the fits may use)."""
    if bool(a.screened) != bool(b.screened):
        return not a.screened
    if a.screened:
        return a.screened.delta_chi2_shared_samples > b.screened.delta_chi2_shared_samples
    return a.chi2("fit") < b.chi2("fit")


def discover(ctx: FitContext, start: ModelFit, n_fit: int):
    """The discovery stage: greedy forward selection (``harness.analysis.discovery.GreedySelector``, at most
    ``settings.max_terms``) over the terms of ``fmu_src.terms.TERMS`` added to the catalogue stage's model
    ``start``, each fitted like a catalogue candidate (shared: its coefficient ratio and lag time constant; every
    sample's base parameters re-fitted; screened, in ``workers`` processes) and accepted by the same rule
    (:func:`compare`). Returns the selector's ``Path``."""
    st = ctx.settings
    lib = ctx.library

    def round_specs(ref, names):
        specs, owner = [], []
        for t in names:
            for start in lib.starts(t, ref.shared):        # lag terms: a fast and a slow time-constant start
                specs.append(ModelSpec(ref.effects + (t,), ref.base, {**off_init((t,), lib), **start, **ref.shared}))
                owner.append(t)
        return specs, owner

    def fit(ref, names):
        specs, owner = round_specs(ref, names)
        best = {}
        for t, mf in zip(owner, fit_candidates(ctx, specs, st.workers, reference=ref)):
            if t not in best or _better(mf, best[t]):
                best[t] = mf
        return [best[t] for t in names]

    def cmp(ref, mf, name):
        return compare(ref, mf, st, n_fit, name)

    def structured(mf):
        z = mf.structure()
        return bool(z) and max(z.values()) > st.z_struct

    def exhausted(ref, names):
        return not ctx.can_afford(round_specs(ref, names)[0])

    return GreedySelector(st.max_terms).run(start, lib.names, fit, cmp, structured, exhausted=exhausted)
