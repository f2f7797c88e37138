"""Output folders of the jobs: created on demand, never written into a user's folder or a dataset.

A job writes into a folder it made itself: the folder holds the marker file :data:`MARKER`. A
non-empty folder is reused only when the caller allows overwriting *and* the marker is there, so
nothing of the user's is ever overwritten; an output folder never lies inside the input dataset.
"""
from __future__ import annotations

from pathlib import Path

from harness.data.dataset import Dataset, read_dataset

__all__ = ["MARKER", "OutputPathError", "output_folder", "guard_not_inside", "dataset_and_output"]

MARKER = ".mpc-actuator-output"


class OutputPathError(ValueError):
    """An output folder or file that must not be written; the message starts with its path."""


def output_folder(path: str | Path, overwrite: bool) -> Path:
    """Create (or reuse) an output folder and mark it as made by this tool.

    Parameters
    ----------
    path : str or Path
        The folder; created with its parents if missing.
    overwrite : bool
        Allow writing into a non-empty folder, which must then hold :data:`MARKER`.

    Returns
    -------
    Path
        The folder, holding the marker file.

    Raises
    ------
    OutputPathError
        ``path`` is a file, or is not empty and either ``overwrite`` is false or the folder was
        not made by this tool.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise OutputPathError(f"{out} exists and is not a folder")
    if out.exists() and any(out.iterdir()):
        if not overwrite:
            raise OutputPathError(f"{out} is not empty; choose another folder or pass --overwrite")
        if not (out / MARKER).exists():
            raise OutputPathError(f"{out} is not empty and was not made by mpc-actuator "
                                    f"(no {MARKER} file); refusing to write into it")
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).write_text("output folder of mpc-actuator; --overwrite may replace files here\n")
    return out


def guard_not_inside(out: str | Path, dataset: str | Path) -> None:
    """Refuse an output folder that is the dataset folder or lies inside it.

    Raises
    ------
    OutputPathError
        ``out`` resolves to ``dataset`` or to a folder below it.
    """
    o, d = Path(out).resolve(), Path(dataset).resolve()
    if o == d or d in o.parents:
        raise OutputPathError(f"{out} is inside the input dataset {dataset}; outputs never go into input data")


def dataset_and_output(dataset: str | Path, out: str | Path, overwrite: bool) -> tuple[Dataset, Path]:
    """Read a dataset and create the output folder of a job on it, which must lie outside it.

    Parameters
    ----------
    dataset : str or Path
        Dataset folder (format ``mpc-actuator-data/1``).
    out : str or Path
        Output folder (see :func:`output_folder`).
    overwrite : bool
        Allow reusing a non-empty output folder made by this tool.

    Returns
    -------
    tuple of (Dataset, Path)
        The dataset and the created output folder.

    Raises
    ------
    OutputPathError
        ``out`` lies inside ``dataset`` (checked first) or may not be written into.
    harness.data.dataset.DataFormatError
        The dataset cannot be read; the output folder is then not created.
    """
    guard_not_inside(out, dataset)
    ds = read_dataset(dataset)
    return ds, output_folder(out, overwrite)
