"""What the pythonfmu slaves share (the actuator's and the controller's): recoverable errors reported through
the status shim, and the FMU state as bytes.

Error convention (shared with the C status shim, fmu_shim/fmi2_status_shim.c): a recoverable error is logged
at error status by :meth:`StatusShimErrors._report_error`. With the status shim (this platform listed in the
FMU's ``resources/status_shim.json``, written by build_fmu.py) the message alone makes the FMI call return
fmi2Error, so the caller returns normally and pythonfmu's instance stays usable (pythonfmu breaks its instance
when a Python exception passes through it). Without the shim only an exception stops the call (fmi2Fatal).
"""
import json
import os
import platform
import sys

from pythonfmu.enums import Fmi2Causality, Fmi2Status, Fmi2Variability


class StatusShimErrors:
    """Mixin for a pythonfmu ``Fmi2Slave``: error reporting through the status shim, FMU-state bytes as they are.

    Uses the slave's ``log``, ``instance_name`` and ``resources``.
    """

    _shim = None   # whether this platform's binary is the status shim; found on first use
    _initialized = False   # True from fmi2ExitInitializationMode on (the slave sets it): fixed parameters frozen

    def _refuse_frozen(self, vrs, call: str) -> bool:
        """True, after reporting an error naming the variable, when one of ``vrs`` is a parameter of variability
        fixed and initialization is over: FMI 2.0 lets a master set such a parameter only before and in
        initialization mode (tunable ones, and inputs, at any time). Nothing of the call is then set."""
        if not self._initialized:
            return False
        for vr in vrs:
            var = self.vars.get(vr)
            if var is not None and var.causality == Fmi2Causality.parameter \
                    and var.variability == Fmi2Variability.fixed:
                msg = (f"{call}: parameter {var.name} has variability fixed: FMI 2.0 allows setting it only before "
                       f"and in initialization mode (fmi2Reset, then set it before fmi2ExitInitializationMode); "
                       f"nothing was set")
                if self._report_error(msg):
                    raise ValueError(msg)
                return True
        return False

    def set_real(self, vrs, values):
        if not self._refuse_frozen(vrs, "fmi2SetReal"):
            super().set_real(vrs, values)

    def set_integer(self, vrs, values):
        if not self._refuse_frozen(vrs, "fmi2SetInteger"):
            super().set_integer(vrs, values)

    def set_boolean(self, vrs, values):
        if not self._refuse_frozen(vrs, "fmi2SetBoolean"):
            super().set_boolean(vrs, values)

    def set_string(self, vrs, values):
        if not self._refuse_frozen(vrs, "fmi2SetString"):
            super().set_string(vrs, values)

    def _report_error(self, message) -> bool:
        """Log ``message`` at Fmi2Status.error; True if the caller must then raise (no status shim here).
        Never log at error status except through this method."""
        self.log(f"{self.instance_name}: {message}", Fmi2Status.error)
        return not self._shim_reports_errors()

    def _shim_reports_errors(self) -> bool:
        """True if this platform's binary in the FMU is the status shim (see build_fmu.py)."""
        if self._shim is None:
            plat = "linux64" if sys.platform.startswith("linux") and platform.machine().lower() in (
                "x86_64", "amd64") else sys.platform
            path = os.path.join(self.resources or "", "status_shim.json") if self.resources else None
            platforms = []
            if path and os.path.isfile(path):
                with open(path) as f:
                    platforms = json.load(f).get("platforms", [])
            self._shim = plat in platforms
        return self._shim

    @staticmethod
    def _fmu_state_to_bytes(state):
        return state

    @staticmethod
    def _fmu_state_from_bytes(state):
        return bytes(state)
