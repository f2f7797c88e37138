"""MATLAB ``.mat`` files (v4, v5/v6/v7 via ``scipy.io.loadmat``).

A column is a variable (a vector) or a column of a matrix (``{"name": "data", "index": 2}``,
1-based). A unit comes from the mapping or the variable name's suffix (``current_mA``). v7.3
files are HDF5 containers that scipy cannot read: they are refused with a clear message (the
project does not depend on h5py); re-save them with ``save(..., '-v7')``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.data.labimport.errors import LabImportError
from harness.data.labimport.table import Channel, Table
from harness.data.labimport.units import split_unit

__all__ = ["read_mat", "HDF5_SIGNATURE"]

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _is_v73(file: Path) -> bool:
    with open(file, "rb") as fh:
        head = fh.read(520)
    return head[:128].startswith(b"MATLAB 7.3") or head[512:520] == HDF5_SIGNATURE or head[:8] == HDF5_SIGNATURE


def read_mat(path) -> Table:
    """Read the numeric variables of a MAT file (opened read-only) into a :class:`Table`.

    Parameters
    ----------
    path : path-like
        The ``.mat`` file (v4 to v7; not v7.3).

    Returns
    -------
    Table
        One channel per real numeric vector (named as the variable), and per column of a real
        2-D matrix (``"name:k"``, k 1-based; a 1 x n or n x 1 matrix is a vector).

    Examples
    --------
    >>> read_mat("run.mat").names()                                     # doctest: +SKIP
    ['time_s', 'current_mA', 'data:1', 'data:2']
    """
    from scipy.io import loadmat

    file = Path(path)
    if not file.is_file():
        raise LabImportError("file not found", file=file)
    if _is_v73(file):
        raise LabImportError("MATLAB v7.3 (HDF5) files are not supported: scipy.io cannot read them and h5py is "
                             "not a dependency of this project; re-save in MATLAB with save(FILE, '-v7')", file=file)
    try:
        with open(file, "rb") as fh:
            d = loadmat(fh, squeeze_me=False)
    except NotImplementedError as e:      # scipy's own v7.3 refusal
        raise LabImportError(f"MATLAB v7.3 (HDF5) files are not supported ({e}); re-save with '-v7'",
                             file=file) from None
    except (ValueError, TypeError, OSError) as e:
        raise LabImportError(f"not a readable MAT file: {e}", file=file) from None
    chans = []
    for name, v in d.items():
        if name.startswith("__") or not isinstance(v, np.ndarray) or v.dtype.kind not in "iuf":
            continue
        a = np.asarray(v, dtype=float)
        if a.ndim == 2 and 1 in a.shape or a.ndim == 1:
            chans.append(Channel(name=name, values=a.reshape(-1), unit=split_unit(name)[1]))
        elif a.ndim == 2:
            for k in range(a.shape[1]):
                chans.append(Channel(name=f"{name}:{k + 1}", values=a[:, k], unit=None, column=k + 1))
    if not chans:
        raise LabImportError("no real numeric variables in the file", file=file)
    return Table(file=file, channels=chans, notes={"format": "mat"})
