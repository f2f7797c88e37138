"""In-memory records of a dataset: :class:`TimeSeries`, :class:`GapSweep`, :class:`Sample`, :class:`Dataset`."""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from harness.data.format import DataFormatError, UnknownSampleError

__all__ = ["TimeSeries", "GapSweep", "Sample", "Dataset"]


def _arr(x):
    if x is None:
        return None
    a = np.asarray(x, dtype=float)
    if a.ndim != 1:
        raise ValueError(f"expected a 1-D array, got shape {a.shape}")
    return a


def _values_equal(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        if a is None or b is None:
            return False
        return bool(np.array_equal(np.asarray(a), np.asarray(b)))
    return a == b


class _ArrayEq:
    """Field-wise equality that compares numpy arrays by value (fields with compare=False skipped)."""

    def __eq__(self, other):
        if type(other) is not type(self):
            return NotImplemented
        return all(_values_equal(getattr(self, f.name), getattr(other, f.name))
                   for f in fields(self) if f.compare)

    __hash__ = None


@dataclass(eq=False)
class TimeSeries(_ArrayEq):
    """A time-series test (T2-T6: displacement; T8: blocked force)."""
    test: str
    file: Path | None = field(compare=False)
    time_s: np.ndarray
    voltage_V: np.ndarray
    current_A: np.ndarray
    displacement_mm: np.ndarray | None
    force_N: np.ndarray | None
    field_T: float
    gap_mm: float
    frequency_hz: float | None = None

    def __post_init__(self):
        self.file = None if self.file is None else Path(self.file)
        for name in ("time_s", "voltage_V", "current_A", "displacement_mm", "force_N"):
            setattr(self, name, _arr(getattr(self, name)))


@dataclass(eq=False)
class GapSweep(_ArrayEq):
    """A gap sweep of steady-state values, one row per gap (T1: displacement; T7: blocked force)."""
    test: str
    file: Path | None = field(compare=False)
    gap_mm: np.ndarray
    current_A: np.ndarray
    displacement_mm: np.ndarray | None
    force_N: np.ndarray | None
    field_T: float

    def __post_init__(self):
        self.file = None if self.file is None else Path(self.file)
        for name in ("gap_mm", "current_A", "displacement_mm", "force_N"):
            setattr(self, name, _arr(getattr(self, name)))


@dataclass
class Sample:
    id: str
    wt_pct: float
    diameter_mm: float
    thickness_mm: float
    tests: dict = field(default_factory=dict)   # dict[str, TimeSeries | GapSweep], in T1..T8 order

    def test(self, name: str) -> "TimeSeries | GapSweep":
        """The test ``name``; DataFormatError naming the tests this sample has otherwise."""
        try:
            return self.tests[name]
        except KeyError:
            raise DataFormatError(f"sample {self.id!r} has no test {name!r} "
                                  f"(it has {', '.join(self.tests) or 'no tests'})") from None


@dataclass
class Dataset:
    """A dataset: its folder ``root``, data kind, description, the manifest's ``rig`` object and samples.

    ``read_from`` is the resolved folder :func:`~harness.data.dataset.read_dataset` read it from
    (None for a dataset made in memory): :func:`~harness.data.writer.write_dataset` never writes over it.

    Parameters
    ----------
    root : Path or None
        The dataset's folder (None: made in memory).
    synthetic : bool
        The data come from the virtual rig (not measured).
    description : str
        The manifest's description.
    rig : dict
        The manifest's ``rig`` object (coil radius [mm], field per ampere [T/A], sensor noise, ...).
    samples : list of Sample
        The samples with their tests.
    read_from : Path or None
        The resolved folder it was read from (None: made in memory).
    """
    root: Path | None = field(compare=False)
    synthetic: bool
    description: str
    rig: dict
    samples: list
    read_from: Path | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        self.root = None if self.root is None else Path(self.root)

    @property
    def sample_ids(self) -> list[str]:
        return [s.id for s in self.samples]

    def sample(self, id: str) -> Sample:
        """The sample with this id; UnknownSampleError (a DataFormatError and KeyError) otherwise.

        Parameters
        ----------
        id : str
            The sample's id (e.g. "W20-D45").
        """
        for s in self.samples:
            if s.id == id:
                return s
        raise UnknownSampleError(f"no sample {id!r} in dataset {self.root} "
                                 f"(known ids: {', '.join(self.sample_ids) or 'none'})")

    @property
    def field_per_amp_T_per_A(self) -> float | None:
        v = (self.rig or {}).get("field_per_amp_T_per_A")
        return None if v is None else float(v)

    @property
    def coil_radius_mm(self) -> float | None:
        v = (self.rig or {}).get("coil_radius_mm")
        return None if v is None else float(v)


