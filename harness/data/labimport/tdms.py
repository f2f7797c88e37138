"""NI TDMS files via npTDMS (``nptdms``).

Channels are named ``"Group/Channel"`` (or by the channel name alone when it is unique, or within
the mapping's ``tdms.group``). A channel's unit is its ``unit_string`` property (or a unit in its
name); a waveform channel (``wf_increment`` property) carries its own time base
``wf_start_offset + i * wf_increment`` [s].
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.data.labimport.errors import LabImportError
from harness.data.labimport.table import Channel, Table
from harness.data.labimport.units import split_unit

__all__ = ["read_tdms"]


def read_tdms(path, group: str | None = None) -> Table:
    """Read the channels of a TDMS file (opened read-only) into a :class:`Table`.

    Parameters
    ----------
    path : path-like
        The ``.tdms`` file.
    group : str, optional
        Only this group's channels, named by channel name alone.

    Returns
    -------
    Table
        Channels ``"Group/Channel"`` (``"Channel"`` with ``group``) with their ``unit_string``
        and, for waveforms, ``time_s``.

    Examples
    --------
    >>> read_tdms("sweep.tdms").names()                                 # doctest: +SKIP
    ['Measured/Time', 'Measured/Current', 'Measured/Displacement']
    """
    try:
        from nptdms import TdmsFile
    except ImportError:   # pragma: no cover - nptdms is a dependency
        raise LabImportError("reading TDMS needs the package nptdms (pip install nptdms)", file=path) from None
    file = Path(path)
    try:
        tf = TdmsFile.read(str(file))
    except (OSError, ValueError, KeyError) as e:
        raise LabImportError(f"not a readable TDMS file: {e}", file=file) from None
    groups = tf.groups()
    if group is not None:
        names = [g.name for g in groups]
        if group not in names:
            raise LabImportError(f"no group {group!r} (groups: {', '.join(map(repr, names))})", file=file,
                                 key="tdms.group")
        groups = [tf[group]]
    chans = []
    for g in groups:
        for ch in g.channels():
            props = ch.properties
            try:
                values = np.asarray(ch[:], dtype=float)
            except (TypeError, ValueError):
                continue     # strings or timestamps: not a signal
            unit = props.get("unit_string") or split_unit(ch.name)[1]
            t = None
            if "wf_increment" in props:
                t = float(props.get("wf_start_offset", 0.0)) + float(props["wf_increment"]) * np.arange(values.size)
            name = ch.name if group is not None else f"{g.name}/{ch.name}"
            chans.append(Channel(name=name, values=values, unit=unit or None, time_s=t))
    if not chans:
        raise LabImportError("no numeric channels in the file", file=file)
    return Table(file=file, channels=chans, notes={"format": "tdms"})
