"""The prepared dataset of the identification: what it reads of the rig, derived once and then only read.

:func:`prepare` infers the rig's conventions from a dataset once
(:func:`harness.analysis.identification.conventions.infer_conventions`: noise floors, step instants, coil)
and reads from them, once, everything the later steps of the identification need:

* the loop radius a [mm] of the electromagnet (and its standard uncertainty when derived from T7), the
  field per ampere kB [T/A] when the manifest states it;
* the white-noise std of every measured column (the manifest's sensor model, else the data's estimate);
* the step instant of every pure step of every sample (the RL fit of the current's rise), which the
  objectives' held step voltage reads instead of fitting it again.

The result, :class:`PreparedData`, is frozen (its mappings read-only): the analytic steps, the
objectives and the least-squares estimate read it; none looks a value up again in the manifest. :meth:`PreparedData.from_rig` gives the same object for a bare manifest ``rig`` (the public
``identify_sample(sample, rig)``), without step instants: those are then fitted once per sample.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

from harness.analysis.identification.conventions import NOISE_COLUMNS, Conventions, infer_conventions
from harness.data import protocol

__all__ = ["PreparedData", "ReadOnlyDict", "prepare", "as_prepared"]


def _rig_get(rig, key):
    if rig is None:
        return None
    if hasattr(rig, "rig") and isinstance(getattr(rig, "rig"), dict):   # a Dataset
        rig = rig.rig
    v = rig.get(key) if isinstance(rig, dict) else None
    return None if v is None else float(v)


class ReadOnlyDict(dict):
    """A dict that refuses every change (``TypeError``); picklable, so it reaches worker processes."""

    def _refuse(self, *args, **kwargs):
        raise TypeError("the prepared data are read-only")

    __setitem__ = __delitem__ = clear = pop = popitem = setdefault = update = __ior__ = _refuse

    def __reduce__(self):
        return type(self), (dict(self),)


def _frozen(d: dict) -> Mapping:
    return ReadOnlyDict({k: (_frozen(v) if isinstance(v, dict) else v) for k, v in d.items()})


@dataclass(frozen=True)
class PreparedData:
    """What the identification reads of a dataset's rig (units in the names; None: not stated/derived).

    coil_radius_mm, sd_coil_radius_mm: the loop radius a and its standard uncertainty (derived from T7 when
    the manifest has none); field_per_amp_T_per_A: kB from the manifest (None: derived per sample from T5);
    noise_sigma: {column: white-noise std [unit of column]} (no quantization; ``harness.data.protocol.
    noise_floor(..., quantization=False)`` of the rig completed by the conventions); steps: {sample id:
    {test: StepInstant}} of every pure step (None: not derived, e.g. from a bare rig); conventions: the
    :class:`~harness.analysis.identification.conventions.Conventions` it was read from (None from a bare rig).
    """
    coil_radius_mm: float | None
    sd_coil_radius_mm: float | None
    field_per_amp_T_per_A: float | None
    noise_sigma: Mapping = field(default_factory=ReadOnlyDict)
    steps: Mapping | None = None
    conventions: Conventions | None = None

    @classmethod
    def from_rig(cls, rig, conventions: Conventions | None = None) -> "PreparedData":
        """From a manifest's ``rig`` dict (or a Dataset holding it), as stated; with ``conventions`` (inferred
        from the same dataset) the rig is first completed with them and their step instants kept."""
        if hasattr(rig, "rig") and isinstance(getattr(rig, "rig"), dict):
            rig = rig.rig
        if conventions is not None:
            rig = conventions.effective_rig(rig)
        return cls(coil_radius_mm=_rig_get(rig, "coil_radius_mm"),
                   sd_coil_radius_mm=_rig_get(rig, "sd_coil_radius_mm"),
                   field_per_amp_T_per_A=_rig_get(rig, "field_per_amp_T_per_A"),
                   noise_sigma=ReadOnlyDict({c: protocol.noise_floor(rig, c, quantization=False)
                                             for c in NOISE_COLUMNS}),
                   steps=None if conventions is None else _frozen(conventions.steps),
                   conventions=conventions)

    def step_instants(self, sample_id: str) -> Mapping | None:
        """{test: StepInstant} of one sample (empty: no pure step could be fitted), None when not derived."""
        if self.steps is None:
            return None
        return self.steps.get(sample_id, ReadOnlyDict())


def prepare(dataset, conventions: Conventions | None = None) -> PreparedData:
    """The prepared data of ``dataset`` (``harness.data.dataset.Dataset``): its conventions inferred once
    (or the ``conventions`` already inferred from it), then read. Raises
    :class:`~harness.analysis.identification.conventions.ConventionError` when the coil radius can be
    neither read nor derived."""
    conv = infer_conventions(dataset) if conventions is None else conventions
    return PreparedData.from_rig(dataset.rig, conv)


def as_prepared(rig) -> PreparedData:
    """``rig`` itself when it is already a :class:`PreparedData`, else :meth:`PreparedData.from_rig` of it."""
    return rig if isinstance(rig, PreparedData) else PreparedData.from_rig(rig)
