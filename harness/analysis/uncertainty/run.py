"""Parameter uncertainty and prediction bands of a whole dataset (``mpc-actuator uncertainty``).

For every identified sample (a parameter file, e.g. ``identification.json``, and the dataset it was
identified from): the covariance and intervals of R, L, Em, K1, K2, C, m
(:mod:`harness.analysis.identification.parameter_uncertainty`, :mod:`harness.analysis.identification.cm_profile`); then Monte-Carlo
prediction bands on every test of every sample (:mod:`harness.analysis.uncertainty.bands`), including the samples
of the dataset that were not identified (the generalized ones, e.g. 15 and 25 wt%), whose draws go
through the generalization surfaces. Both stages run as Dask tasks (:mod:`harness.analysis.core.sweep`): one
task per sample (seconds each). Random numbers: one generator per sample, seeded from (seed, sample
id): the results do not depend on the number of workers.
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from fmu_src.specs import Params
from harness.analysis.uncertainty import bands as bands_mod
from harness.analysis.identification import generalize
from harness.analysis.identification.identify import analyse_sample, estimate_cm
from harness.analysis.identification.settings import IdentifySettings
from harness.analysis.core.sweep import ClusterSettings, cluster_client, run_tasks
from harness.analysis.identification.parameter_uncertainty import (ParameterUncertainty, UncertaintyError, analytic_bootstrap,
                                          analytic_covariance, combine)
from harness.data import protocol

__all__ = ["UncertaintySettings", "UncertaintyResult", "sample_rng", "sample_uncertainty", "dataset_uncertainty"]


@dataclass(frozen=True)
class UncertaintySettings:
    """Settings of the parameter uncertainty and the prediction bands.

    Parameters
    ----------
    n_boot : int
        Bootstrap draws of the analytic part (>= 100).
    n_draws : int
        Monte-Carlo draws per sample for the bands (>= 8).
    seed : int
        Random seed.
    grid : int
        Points per axis of the (C, m) profile grid (>= 11).
    settle_rtol, rk_tol : float
        Tolerances of the (C, m) profile's simulations.
    bands : bool
        Compute the prediction bands.
    """
    n_boot: int = 2000
    n_draws: int = 64
    seed: int = 0
    grid: int = 31
    settle_rtol: float = 1e-8
    rk_tol: float = 1e-5
    bands: bool = True

    def __post_init__(self):
        if not (self.n_boot >= 100 and self.n_draws >= 8 and self.grid >= 11):
            raise UncertaintyError(f"need n_boot >= 100, n_draws >= 8, grid >= 11, got {self!r}")


@dataclass
class UncertaintyResult:
    """uncertainties: {id: ParameterUncertainty} (identified samples); unseen: {id: (median Params, (n, 7)
    draws)} (samples predicted from the surfaces); bands: {id: {test: Band}}; skipped: {id: reason}."""
    uncertainties: dict
    unseen: dict
    bands: dict
    skipped: dict
    settings: UncertaintySettings


def sample_rng(seed: int, sid: str, stage: str) -> np.random.Generator:
    """The generator of one sample and stage, from (seed, crc32(sample id), crc32(stage))."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), zlib.crc32(sid.encode()),
                                                         zlib.crc32(stage.encode())]))


def sample_uncertainty(sample, rig, params: Params, settings: UncertaintySettings = UncertaintySettings()
                       ) -> ParameterUncertainty:
    """Covariance and 95 % intervals of one identified sample's R, L, Em, K1, K2, C, m.

    sample: a dataset Sample with T3, T5, T8; rig: the manifest's rig; params: the identified model
    (its values are the centre of everything; the steady means and their uncertainties are recomputed
    from the data by the analytic identification).
    """
    an = analyse_sample(sample, rig, IdentifySettings())
    gaps = [float(sample.tests[n].gap_mm) / 1000.0 for n in protocol.IDENTIFICATION_TESTS]
    cov5 = analytic_covariance(an.result, gaps)
    boot = analytic_bootstrap(an.result, gaps, settings.n_boot, sample_rng(settings.seed, sample.id, "bootstrap"))
    tight = IdentifySettings(settle_rtol=settings.settle_rtol, rk_tol=settings.rk_tol)
    # the objectives of the identified analytic parameters (perturbed ones for the propagation into C, m), the
    # step simulated as identify's least-squares estimate does (the coil's current)
    est = estimate_cm(an, rig, tight, params, cov5, params.C, params.m, n_grid=settings.grid)
    if not est.ok:
        raise UncertaintyError(f"sample {sample.id}: C and m: {est.least_squares['error']}")
    prof = est.profile
    # bootstrap draws around the identified values (the map's values at the data's means may differ
    # slightly when the identification came from another version of the analytic step); the joint covariance
    # (cm_joint) carries the analytic parameters' uncertainty into C and m, with their cross-covariances
    return combine(sample.id, sample.wt_pct, sample.diameter_mm, params, (cov5, boot),
                   (prof.cov, prof.intervals, {"C": prof.C_hat, "m": prof.m_hat}), cov7=est.cov7)


def _unc_task(args):
    sample, rig, params, settings = args
    return sample_uncertainty(sample, rig, params, settings)


def _band_task(args):
    sample, rig, base, rows = args
    return bands_mod.sample_bands(sample, base, rows, rig)


def dataset_uncertainty(dataset, params: dict, settings: UncertaintySettings = UncertaintySettings(),
                        cluster: ClusterSettings = ClusterSettings()) -> UncertaintyResult:
    """Uncertainty of every sample of ``params`` ({id: Params}) found in ``dataset`` with T3, T5 and T8, and
    (``settings.bands``) prediction bands on every test of every sample of the dataset (module docstring).

    Raises :class:`UncertaintyError` when no sample of the parameter file is in the dataset.
    """
    rig = dataset.rig
    have = {s.id: s for s in dataset.samples}
    ident = [sid for sid in params if sid in have and all(t in have[sid].tests for t in protocol.IDENTIFICATION_TESTS)]
    skipped = {sid: "not in the dataset or lacking T3, T5 or T8" for sid in params if sid not in ident}
    if not ident:
        raise UncertaintyError(f"none of the parameter file's samples ({', '.join(params) or 'none'}) is in the "
                               f"dataset with T3, T5 and T8")
    with cluster_client(cluster) as client:
        uncs = run_tasks(_unc_task, [(have[s], rig, params[s], settings) for s in ident], cluster,
                         desc="parameter uncertainty (samples)", client=client)
        return _bands(dataset, dict(zip(ident, uncs)), skipped, settings, (cluster, client))


def _bands(dataset, uncertainties: dict, skipped: dict, settings: UncertaintySettings, where) -> UncertaintyResult:
    rig = dataset.rig
    have = {s.id: s for s in dataset.samples}
    unseen, bands = {}, {}
    others = [(s.id, s.wt_pct, s.diameter_mm) for s in dataset.samples if s.id not in uncertainties]
    if others and len(uncertainties) >= 3:
        rngs = {sid: sample_rng(settings.seed, sid, "surfaces") for sid in uncertainties}
        fits = generalize.fit_surfaces([(u.wt_pct, u.diameter_mm, u.params) for u in uncertainties.values()])
        inside = []
        for tid, w, d in others:
            try:
                generalize.predict(fits, w, d)
                inside.append((tid, w, d))
            except generalize.GeneralizationError as e:
                skipped[tid] = f"not predicted: {e}"
        if inside:
            unseen = bands_mod.unseen_draws(uncertainties, inside, settings.n_draws, rngs)
    if settings.bands:
        jobs, order = [], []
        for sid, u in uncertainties.items():
            jobs.append((have[sid], rig, u.params, u.draws(settings.n_draws, sample_rng(settings.seed, sid, "bands"))))
            order.append(sid)
        for sid, (base, rows) in unseen.items():
            jobs.append((have[sid], rig, base, rows))
            order.append(sid)
        res = run_tasks(_band_task, jobs, where[0], desc="prediction bands (samples)", client=where[1])
        bands = dict(zip(order, res))
    return UncertaintyResult(uncertainties=uncertainties, unseen=unseen, bands=bands, skipped=skipped,
                             settings=settings)
