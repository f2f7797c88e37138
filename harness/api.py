"""The public Python API in one place: what a notebook imports (``from harness import api``).

A small, stable surface over the library, one name per thing a researcher does; the objects are those of the
modules that define them (re-exported, not wrapped), so their documentation is in the API reference:

========================  ============================================================  ======================
to                        call                                                          command
========================  ============================================================  ======================
read a dataset            :func:`read_dataset`, :func:`check`                           ``check``
import lab files          :func:`import_lab`                                            ``import``
generate a dataset        :func:`generate` with :class:`DatasetSettings`                ``generate``
simulate the model        :func:`simulate` with :class:`Params`                         --
simulate an FMU           :func:`build` then fmpy's ``simulate_fmu``                    ``build``
identify                  :func:`identify` with :class:`IdentifySettings`               ``identify``
diagnose                  :func:`diagnose`                                              ``diagnose``
control                   :func:`control` with :class:`StudySettings`                   ``control``
uncertainty and design    :func:`uncertainty`, :func:`design` with :class:`DesignTargets`  ``uncertainty``, ``design``
everything                :func:`run_chain` with :class:`ChainSettings`                 ``run DATASET``
========================  ============================================================  ======================

Examples
--------
>>> from harness import api
>>> p = api.Params()
>>> p.R, p.L, p.kB                  # the default coil: 15 Ohm, 120 mH, 0.29 T per ampere
(15.0, 0.12, 0.29)
>>> V = 0.23 / p.kB * p.R           # the voltage whose steady current L/R after the step gives 0.23 T
>>> round(V, 3), round(V / p.R, 4)  # [V], steady current V/R [A]
(11.897, 0.7931)
>>> sorted(api.EFFECTS)[:3]
['coil_heating', 'edge_stiffening', 'filler_saturation']
"""
from __future__ import annotations

from fmu_src.model import simulate
from fmu_src.specs import EFFECTS, Params
from harness.analysis.identification.settings import IdentifySettings
from harness.chain import ChainSettings, run_chain
from harness.control.study import StudySettings
from harness.data.dataset import Dataset, read_dataset
from harness.jobs import BuildSettings, build, check, diagnose, generate, identify, import_lab, load_params_file
from harness.jobs_control import control
from harness.jobs_design import DesignSettings, DesignTargets, UncertaintySettings, design, uncertainty
from harness.pipeline import DatasetSettings, JobSettings, PipelineError

__all__ = [
    "Params", "EFFECTS", "simulate",
    "Dataset", "read_dataset", "check", "import_lab", "generate", "DatasetSettings", "JobSettings",
    "identify", "IdentifySettings", "diagnose", "load_params_file", "build", "BuildSettings",
    "control", "StudySettings", "uncertainty", "UncertaintySettings", "design", "DesignSettings", "DesignTargets",
    "run_chain", "ChainSettings", "PipelineError",
]
