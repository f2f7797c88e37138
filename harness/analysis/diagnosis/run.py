"""The diagnosis's procedure, step by step (:func:`diagnose`)."""
from __future__ import annotations

import time
from dataclasses import replace

from harness.analysis.core import cpu_clock
from harness.analysis.core.lsq import one_blas_thread

from .allowance import prediction_allowance
from .candidates import base_vector, refit_start
from .decision import select
from .evidence import features
from .baseline import paper_baseline
from .fitting import FitContext, ModelFit, ModelSpec
from .jobs import full_traces
from .prepare import prepare
from .result import Diagnosis, Outcome, assemble
from .settings import DiagnoseSettings


class _Laps:
    """Wall time of the steps {name: s} (printed as they end with ``progress``)."""

    def __init__(self, progress: bool):
        self.t0 = self.last = time.perf_counter()
        self.timing = {}
        self.progress = progress

    def __call__(self, name: str):
        now = time.perf_counter()
        self.timing[name] = round(now - self.last, 3)
        self.last = now
        if self.progress:
            print(f"[diagnose] {name}: {self.timing[name]:.1f} s", flush=True)


def diagnose(dataset, settings: DiagnoseSettings | None = None, progress: bool = False) -> Diagnosis:
    """Diagnose which catalogued effect (if any) the paper's model misses in ``dataset``.

    Runs blind: it reads the measured tests and the rig description (coil radius, field per
    ampere, sensor noise), never ``rig.effects`` or ``rig.true_parameters``. See the package
    docstring (``harness.analysis.diagnosis``) for the procedure and the decision rule.

    Parameters
    ----------
    dataset : harness.data.dataset.Dataset
        The measured dataset (SI and unit-suffixed columns as in the dataset format).
    settings : DiagnoseSettings, optional
        Fit and held-out tests, thresholds, workers (defaults: ``DiagnoseSettings()``).
    progress : bool
        Print the wall time [s] of each step as it ends.

    Returns
    -------
    Diagnosis
    """
    # BLAS on one thread: the diagnosis spreads its parallel work over processes (``workers``), and the fits'
    # budget counts CPU time (harness.analysis.core.cpu_clock), which idle-spinning BLAS threads would inflate
    with one_blas_thread():
        return _diagnose(dataset, settings, progress)


def _structure(mf, ctx) -> bool:
    """Some (test, channel) of ``mf`` shows structure (z above the settings' threshold)."""
    return any(z > ctx.settings.z_struct for z in mf.structure().values())


#: the reference refit carrying a nuisance parameter converges to tight tolerances (``fitting.TIGHT_LM``) only when
#: its chi-square per fit residual is at most this: where the paper model already fits to within the noise, the
#: nuisance direction's last percent moves the held-out predictions by noise floors; where it misfits by more,
#: the effect to be found decides, and tight tolerances only spend the fit budget (deep profile, session 20: a
#: coil heating 100 noise floors strong at 7457 Hz, whose tight refit took the whole budget and left every
#: candidate at its start: "unexplained")
TIGHT_MAX_CHI2_PER_RESIDUAL = 4.0


def reference_refit(ctx: FitContext, starts: dict) -> ModelFit:
    """The paper model refitted from ``starts`` (the reference the candidates extend): to the default tolerances,
    then, when it carries a nuisance parameter (a derived coil radius) and fits to within
    :data:`TIGHT_MAX_CHI2_PER_RESIDUAL` per residual, on from there to tight ones (``fitting.TIGHT_LM``)."""
    refit = ctx.fit_many([ModelSpec((), starts, None)])[0]
    if not ctx.nuisance or refit.chi2("fit") > TIGHT_MAX_CHI2_PER_RESIDUAL * max(refit.n("fit"), 1):
        return refit
    ctx.tight = True
    try:
        tight = ctx.fit_many([ModelSpec((), refit.base, dict(refit.shared))])[0]
    finally:
        ctx.tight = False
    return tight                 # (a default-tolerance stop is no cut: the tight fit went on from it)


def _diagnose(dataset, settings: DiagnoseSettings | None, progress: bool) -> Diagnosis:
    st = settings or DiagnoseSettings()
    lap = _Laps(progress)
    prep = prepare(dataset, st)
    samples = prep.samples
    n = len(samples)
    deadline_s = cpu_clock.now() + st.fit_budget_s      # every fit of this diagnosis within st.fit_budget_s of CPU
    paper, notes = paper_baseline(samples, st, deadline_s)
    lap("paper_identification")
    conv = prep.conventions
    derived = conv is not None and conv.coil_radius_source != "manifest" and conv.sd_coil_radius_mm
    ctx = FitContext(samples, st, deadline_s,
                     coil_rel_sd=float(conv.sd_coil_radius_mm) / float(conv.coil_radius_mm) if derived else 0.0)
    paper_mf = ModelFit(effects=(), shared={}, base={i: base_vector(p) for i, p in paper.items()},
                        params=dict(paper), fit_chi2=ctx.fit_chi2_of(paper), noise_rel_sd=ctx.noise_rel_sd)
    starts = {}
    for i, p in paper.items():
        q, note = refit_start(p)
        starts[i] = base_vector(q)
        if note:
            notes[i] = list(notes[i]) + [note]
    ctx.set_bounds(starts)
    refit = reference_refit(ctx, starts)
    paper_mf, refit = ctx.evaluate([paper_mf, refit])
    if _structure(refit, ctx):
        # structure: is it more than the fitted parameters' and the step instants' own uncertainty predicts there?
        ctx.allowance = prediction_allowance(ctx, refit)
        paper_mf, refit = (replace(m, allowance=ctx.allowance) for m in (paper_mf, refit))
    lap("baseline_refit")
    selection = select(ctx, refit, lap)
    final = selection.final
    unc = ctx.shared_uncertainty(final) if final.effects else {}
    lap("uncertainty")
    # simulations of every test for the figures, tables, features and gains
    all_names = sorted({nm for sd in samples for nm in sd.tests})
    models = [("paper", paper_mf), ("refit", refit)] + ([("final", final)] if final is not refit else [])
    cat = selection.catalogue_final
    if selection.terms and cat is not None and cat is not refit:
        models.append(("catalogue", cat))          # the catalogue stage's model: residuals before discovery
    sims = ctx.simulate([mf for _, mf in models], all_names)
    traces = {m: {i: full_traces(samples[i], s[i]) for i in range(n)} for (m, _), s in zip(models, sims)}
    if final is refit:
        traces["final"] = traces["refit"]
    if selection.terms and "catalogue" not in traces:
        traces["catalogue"] = traces["refit"]
    feats = features(samples, traces["paper"])
    lap("evidence")
    return assemble(Outcome(prepared=prep, settings=st, shared_idx=tuple(ctx.shared_idx), paper=paper_mf,
                            refit=refit, selection=selection, uncertainty=unc, traces=traces, features=feats,
                            notes=notes, timing=lap.timing, t0=lap.t0))
