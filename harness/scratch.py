"""One scratch folder per command, for the FMUs fmpy extracts: removed however the command ends.

fmpy extracts an FMU into a new temporary folder and removes it when ``simulate_fmu`` returns; a folder extracted
once per process (``harness.sim.fmurun``) was removed by an ``atexit`` handler. Neither ran where it had to: a
pool worker ends with ``os._exit`` (multiprocessing never runs its exit handlers), and so does a command after
Ctrl-C (``harness.entry``). Every worker of every run left its extracted FMU behind in the system's temporary
folder (1515 of them on the development machine).

Here the first process that needs scratch space makes ``<tmp>/mpc-actuator-<pid>-<random>`` and names it in the
environment (``MPC_ACTUATOR_SCRATCH``): its workers, forked or spawned (Dask), inherit the name and extract
under it; the owner removes the whole folder when it ends, normally (``atexit``) or after an interrupt
(:func:`remove`, called by ``harness.entry`` before ``os._exit``). A folder whose owner was killed (SIGKILL, a
power cut) is removed by the next command that makes one (its pid is not running any more).
"""
from __future__ import annotations

import atexit
import contextlib
import os
import re
import shutil
import tempfile
from pathlib import Path

__all__ = ["ENV", "root", "new_dir", "remove"]

ENV = "MPC_ACTUATOR_SCRATCH"
_PREFIX = "mpc-actuator-"
_OWNED: list = []          # [(pid, Path)] of the folder this process made (a forked worker inherits the list:
_REGISTERED: list = []     # the pid tells it is not the owner)


def _pid_running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:     # another user's process
        return True
    return True


def _remove_stale(parent: Path) -> None:
    """Remove ``mpc-actuator-<pid>-*`` folders of ``parent`` whose process is gone (killed before it could)."""
    with contextlib.suppress(OSError):
        for d in parent.iterdir():
            m = re.fullmatch(re.escape(_PREFIX) + r"(\d+)-\w+", d.name)
            if m and d.is_dir() and not _pid_running(int(m.group(1))):
                shutil.rmtree(d, ignore_errors=True)


def root() -> Path:
    """This command's scratch folder: the one named in the environment (made by the command's main process,
    inherited by its workers), or a new one owned by this process."""
    named = os.environ.get(ENV)
    if named and Path(named).is_dir():
        return Path(named)
    if _OWNED and _OWNED[0][1].is_dir():
        return _OWNED[0][1]
    parent = Path(tempfile.gettempdir())
    _remove_stale(parent)
    made = Path(tempfile.mkdtemp(prefix=f"{_PREFIX}{os.getpid()}-", dir=parent))
    _OWNED[:] = [(os.getpid(), made)]
    os.environ[ENV] = str(made)
    if not _REGISTERED:
        atexit.register(remove)
        _REGISTERED.append(True)
    return made


def new_dir(prefix: str = "fmu-") -> Path:
    """A new empty folder under :func:`root`."""
    return Path(tempfile.mkdtemp(prefix=prefix, dir=root()))


def remove() -> None:
    """Remove the scratch folder if this process made it (workers leave it to their owner)."""
    if _OWNED and _OWNED[0][0] == os.getpid():
        shutil.rmtree(_OWNED[0][1], ignore_errors=True)
        if os.environ.get(ENV) == str(_OWNED[0][1]):
            del os.environ[ENV]
        _OWNED.clear()
