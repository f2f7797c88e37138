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

    # -- FMU states tied to their instance -----------------------------------------------------------------------
    # FMI 2.0: an FMUstate belongs to the instance that made it; it moves to another one only serialized. The
    # status shim keeps its own state objects and refuses another instance's pointer itself; pythonfmu's stock
    # binary (``build_fmu.py --no-status-shim``, the win64 binary) hands the slave's state object to the host as
    # the fmi2FMUstate pointer and back to whichever instance it is given to. So the state objects are tagged:
    # made by fmi2GetFMUstate, a state belongs to its instance; made by fmi2DeSerializeFMUstate (pythonfmu calls
    # the class, not the instance, there), to the first instance that restores it. ``_foreign_state`` is the
    # check of ``_set_fmu_state``.

    def _own_state(self, payload: bytes) -> "FMUState":
        """``payload`` (the slave's state bytes) as a state of this instance."""
        state = FMUState(payload)
        state.owner, state.owner_name = self._state_owner(), self.instance_name
        return state

    def _state_owner(self):
        token = self.__dict__.get("_state_token")
        if token is None:
            token = self.__dict__["_state_token"] = object()
        return token

    def _foreign_state(self, state, call: str = "fmi2SetFMUstate") -> bool:
        """True, after reporting an error naming both instances, when ``state`` belongs to another instance; a
        deserialized state no instance has restored yet becomes this instance's."""
        owner = getattr(state, "owner", None)
        if owner is None:
            if isinstance(state, FMUState):
                state.owner, state.owner_name = self._state_owner(), self.instance_name
            return False
        if owner is self._state_owner():
            return False
        msg = (f"{call}: the FMUstate belongs to the instance '{state.owner_name}', not to this one "
               f"('{self.instance_name}'): an FMU state is only valid in the instance that made it (move it with "
               f"fmi2SerializeFMUstate and fmi2DeSerializeFMUstate)")
        if self._report_error(msg):
            raise ValueError(msg)
        return True

    @staticmethod
    def _fmu_state_to_bytes(state):
        return bytes(state)

    @staticmethod
    def _fmu_state_from_bytes(state):
        return FMUState(state)


class FMUState(bytes):
    """A slave's state bytes with the instance it belongs to (``owner``: its token, None until an instance restores
    a deserialized state; ``owner_name``: its instance name): see ``StatusShimErrors._foreign_state``."""
    owner = None
    owner_name = None
