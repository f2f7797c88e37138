"""The ``uncertainty`` and ``design`` jobs (``mpc-actuator uncertainty``, ``mpc-actuator design``, issue 15): the
parameter uncertainty of an identified dataset with Monte-Carlo prediction bands, and the inverse design built on
it, each written into an output folder as a transaction (:mod:`harness.outputs`). The settings they take are
re-exported here (``UncertaintySettings``, ``DesignSettings``, ``DesignTargets``, ``ClusterSettings``)."""
from __future__ import annotations

from pathlib import Path

from harness.analysis.core.sweep import ClusterSettings
from harness.analysis.design.advice import OBJECTIVES as DESIGN_OBJECTIVES
from harness.analysis.design.run import DesignSettings, default_space, design as run_design
from harness.analysis.design.space import Targets as DesignTargets
from harness.analysis.identification.parameter_uncertainty import read_uncertainty
from harness.analysis.uncertainty.run import UncertaintySettings, dataset_uncertainty
from harness.jobs import load_params_file
from harness.outputs import (OutputPathError, check_output_target, dataset_and_output, final_paths, guard_not_inside,
                             output_transaction)
from harness.report.uncertainty_report import write_design_outputs, write_uncertainty_outputs

__all__ = ["uncertainty", "design", "ClusterSettings", "UncertaintySettings", "DesignSettings", "DesignTargets",
           "DESIGN_OBJECTIVES"]


def uncertainty(dataset: str | Path, out: str | Path, params_file: str | Path,
                settings: UncertaintySettings | None = None, cluster: ClusterSettings | None = None,
                overwrite: bool = False) -> tuple:
    """Parameter uncertainty of every identified sample and Monte-Carlo prediction bands on every test.

    :func:`harness.analysis.uncertainty.run.dataset_uncertainty`, written to ``out`` outside the dataset by
    :func:`harness.report.uncertainty_report.write_uncertainty_outputs` (``uncertainty.json``, interval tables,
    band figures); the folder is written as a transaction.

    Parameters
    ----------
    dataset : str or Path
        The dataset folder.
    out : str or Path
        Output folder (outside the dataset).
    params_file : str or Path
        The identification's ``identification.json`` (:func:`harness.jobs.load_params_file`): the samples whose
        uncertainty is computed.
    settings : UncertaintySettings or None
        Bootstrap and Monte-Carlo draws, seed, profile grid, bands (None: the defaults, 2000 bootstrap draws and
        64 draws per sample).
    cluster : ClusterSettings or None
        Where the tasks run: local worker processes or a Dask scheduler, progress bar (None: two local
        workers).
    overwrite : bool
        Replace an earlier output of this tool in ``out``.

    Returns
    -------
    tuple
        (:class:`harness.analysis.uncertainty.run.UncertaintyResult`, list of the written paths).

    Raises
    ------
    harness.jobs.ParamsFileError
        ``params_file`` is unreadable or invalid.
    harness.outputs.OutputPathError
        ``out`` may not be written (inside the dataset, a folder this tool did not make, ...).
    """
    ds, target = dataset_and_output(dataset, out, overwrite)
    params = load_params_file(params_file)
    with output_transaction(target, overwrite, inputs=(dataset,)) as tmp:
        res = dataset_uncertainty(ds, params, settings or UncertaintySettings(), cluster or ClusterSettings())
        written = write_uncertainty_outputs(res, tmp)
    return res, final_paths(written, tmp, target)


def design(uncertainty_file: str | Path, out: str | Path, targets: DesignTargets, space_spec: dict | None = None,
           settings: DesignSettings | None = None, cluster: ClusterSettings | None = None,
           overwrite: bool = False) -> tuple:
    """Inverse design from an ``uncertainty.json``: the feasible region and the candidates' probabilities.

    :func:`harness.analysis.design.run.design` on the training samples of ``uncertainty_file`` (made by
    :func:`uncertainty`), written to ``out`` by :func:`harness.report.uncertainty_report.write_design_outputs`
    (``design.json``, ``design.md``, figures) as a transaction.

    Parameters
    ----------
    uncertainty_file : str or Path
        ``uncertainty.json`` written by :func:`uncertainty`.
    out : str or Path
        Output folder (it must not hold ``uncertainty_file``).
    targets : DesignTargets
        The spec a design must meet (stroke [mm], blocked force [N], settling time [ms], current [A], power [W],
        bandwidth [Hz]).
    space_spec : dict or None
        The design grid (:func:`harness.analysis.design.run.default_space`): {"wt_pct", "diameter_mm", "gap_mm",
        "voltage_V": [lo, hi] or [value], "points": points per ranged axis (default 12)}; None or a missing
        axis: the identified samples' wt% and diameter ranges, gap 3-12 mm, voltage 1-12 V.
    settings : DesignSettings or None
        Draws, seed, number of candidates, objective, minimum probability (None: the defaults).
    cluster : ClusterSettings or None
        Where the tasks run (None: two local workers).
    overwrite : bool
        Replace an earlier output of this tool in ``out``.

    Returns
    -------
    tuple
        (:class:`harness.analysis.design.run.DesignResult`, list of the written paths).

    Raises
    ------
    harness.outputs.OutputPathError
        ``out`` may not be written, or it holds ``uncertainty_file``.
    """
    target = check_output_target(out, overwrite)
    training = read_uncertainty(uncertainty_file)
    spec = dict(space_spec or {})
    space = default_space(training, spec, int(spec.pop("points", 12)))
    try:
        guard_not_inside(uncertainty_file, target)
    except OutputPathError:
        raise OutputPathError(f"{target} holds the input file {uncertainty_file}; choose another output folder") from None
    with output_transaction(target, overwrite) as tmp:
        res = run_design(training, targets, space, settings or DesignSettings(), cluster or ClusterSettings())
        written = write_design_outputs(res, tmp)
    return res, final_paths(written, tmp, target)
