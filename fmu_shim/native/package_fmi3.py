"""Build mpc_actuator_native_fmi3.fmu: the native model as an FMI 3.0 co-simulation FMU
(``python build_fmu.py --native --fmi 3``).

The same generated C code as the FMI 2.0 native FMU (``package.py``): ``mpc_native.c`` and ``mpc_native_gen.h``
unchanged, wrapped by ``mpc_native_fmi3.c`` (each FMI 3.0 call runs its FMI 2.0 counterpart of mpc_native.c).

* modelDescription.xml: the pythonfmu3 slave's own (``fmu_src.mpc_actuator_fmi3.MpcActuatorFmi3(...).to_xml()``,
  with the baked start values if any) completed by ``build_fmu.complete_model_description_fmi3`` exactly as for
  mpc_actuator_fmi3.fmu: the same variables, value references, units and start values; only the CoSimulation
  element (modelIdentifier ``mpc_actuator_native_fmi3``, needsExecutionTool false, FMU state) and the
  instantiation token (a hash of the sources) differ;
* sources/: the C sources, ``mpc_native_vars.h`` generated from this modelDescription (FMI 3.0's value
  references), the FMI 3.0 standard headers (fmpy's copy, BSD-2-Clause) and ``buildDescription.xml``;
* binaries/<FMI 3.0 platform tuple>/: x86_64-linux with the local C compiler, the others with ``zig cc``.
"""
from __future__ import annotations

import ctypes
import hashlib
import json
import tempfile
import uuid
import xml.etree.ElementTree as ET
from pathlib import Path
from xml.dom.minidom import parseString

from fmu_shim.native import package as p2

HERE = Path(__file__).resolve().parent
C_SOURCE = HERE / "mpc_native_fmi3.c"
MODEL_IDENTIFIER = "mpc_actuator_native_fmi3"
# FMI 2.0 platform folder (build_fmu.py --native's names) -> FMI 3.0 platform tuple
PLATFORM_TUPLES = {"linux64": "x86_64-linux", "win64": "x86_64-windows", "darwin64": "x86_64-darwin",
                   "darwin-aarch64": "aarch64-darwin", "linux-aarch64": "aarch64-linux"}
FMI3_HEADERS = ("fmi3PlatformTypes.h", "fmi3FunctionTypes.h", "fmi3Functions.h")
# the functions an FMI 3.0 co-simulation FMU exports (checked on every binary)
FMI3_CS_FUNCTIONS = (
    "fmi3GetVersion", "fmi3SetDebugLogging", "fmi3InstantiateCoSimulation", "fmi3FreeInstance",
    "fmi3EnterInitializationMode", "fmi3ExitInitializationMode", "fmi3EnterEventMode", "fmi3Terminate", "fmi3Reset",
    "fmi3GetFloat64", "fmi3SetFloat64", "fmi3GetBoolean", "fmi3SetBoolean", "fmi3GetFMUState", "fmi3SetFMUState",
    "fmi3FreeFMUState", "fmi3SerializedFMUStateSize", "fmi3SerializeFMUState", "fmi3DeserializeFMUState",
    "fmi3EnterStepMode", "fmi3DoStep", "fmi3GetOutputDerivatives", "fmi3UpdateDiscreteStates")


def fmi3_header_dir() -> Path:
    """fmpy's copy of the FMI 3.0 standard headers (fmpy is a dependency of the project)."""
    import fmpy
    d = Path(fmpy.__file__).resolve().parent / "c-code"
    missing = [h for h in FMI3_HEADERS if not (d / h).is_file()]
    if missing:
        raise SystemExit(f"build_fmu --native --fmi 3: fmpy's FMI 3.0 headers {missing} not found in {d}")
    return d


def slave_model_description(start_values: dict | None) -> tuple[bytes, object]:
    """(completed modelDescription.xml of the pythonfmu3 slave, the slave instance), ``start_values`` baked in as
    mpc_actuator_fmi3.fmu bakes them."""
    bf = p2._build_fmu_module()
    from fmu_src.mpc_actuator_fmi3 import MpcActuatorFmi3
    with tempfile.TemporaryDirectory(prefix="mpc_native3_md_") as res:
        if start_values:
            (Path(res) / "start_values.json").write_text(json.dumps(bf.check_start_values(start_values)))
        slave = MpcActuatorFmi3(instance_name="native", resources=res)
        xml = ET.tostring(slave.to_xml(), encoding="UTF-8")
    return bf.complete_model_description_fmi3(xml), slave


def variables_header(md: bytes, slave, token: str) -> str:
    """mpc_native_vars.h for FMI 3.0 value references (``package.vars_header``), plus VR_TIME."""
    return p2.vars_header(list(ET.fromstring(md).find("ModelVariables")), slave, token,
                          "fmu_shim/native/package_fmi3.py", "build_fmu --native --fmi 3", time_vr=True)


def native_model_description(md: bytes, token: str) -> bytes:
    """The slave's completed modelDescription with the native FMU's token, generation tool and CoSimulation."""
    root = ET.fromstring(md)
    root.set("instantiationToken", token)
    root.set("generationTool", "mpc-actuator build_fmu.py --native --fmi 3 (fmu_shim/native)")
    cs = root.find("CoSimulation")
    cs.attrib.clear()
    cs.attrib.update(modelIdentifier=MODEL_IDENTIFIER, needsExecutionTool="false",
                     canBeInstantiatedOnlyOncePerProcess="false", canGetAndSetFMUState="true",
                     canSerializeFMUState="true", canHandleVariableCommunicationStepSize="true",
                     hasEventMode="false", providesIntermediateUpdate="false")
    xml = parseString(ET.tostring(root, encoding="UTF-8")).toprettyxml(indent="  ", encoding="UTF-8")
    return b"\n".join(line for line in xml.splitlines() if line.strip()) + b"\n"


def build_description() -> str:
    """sources/buildDescription.xml (FMI 3.0 section 2.5.2): one C99 source file to compile."""
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<fmiBuildDescription fmiVersion="3.0">\n'
            f'  <BuildConfiguration modelIdentifier="{MODEL_IDENTIFIER}">\n'
            '    <SourceFileSet language="C99">\n      <SourceFile name="mpc_native_fmi3.c"/>\n    </SourceFileSet>\n'
            '  </BuildConfiguration>\n</fmiBuildDescription>\n')


def generate_sources(start_values: dict | None = None) -> tuple[dict, bytes]:
    """({file name: text} of sources/, modelDescription.xml bytes)."""
    from fmu_shim.native.codegen import generate_header
    md, slave = slave_model_description(start_values)
    gen = generate_header()
    texts = {"mpc_native_fmi3.c": C_SOURCE.read_text(), "mpc_native.c": p2.C_SOURCE.read_text(),
             "mpc_native_gen.h": gen}
    h = hashlib.sha256()
    for part in (*texts.values(), md.decode()):
        h.update(part.encode() + b"\0")
    token = "{" + str(uuid.UUID(bytes=h.digest()[:16], version=4)) + "}"
    texts["mpc_native_vars.h"] = variables_header(md, slave, token)
    hdr = fmi3_header_dir()
    texts.update({name: (hdr / name).read_text() for name in FMI3_HEADERS})
    texts["buildDescription.xml"] = build_description()
    return texts, native_model_description(md, token)


def build_native_fmi3(out: Path, start_values: dict | None = None, platforms=("linux64",)) -> Path:
    """Write the FMI 3.0 native FMU to ``out`` (atomically) and return its path; ``platforms`` in
    ``build_fmu.py --native``'s names (linux64, win64, ...)."""
    files, md = generate_sources(start_values)

    def exports_fmi3_only(lib: Path, plat: str) -> None:
        if plat == "linux64":
            dll = ctypes.CDLL(str(lib))
            missing = [f for f in FMI3_CS_FUNCTIONS if not hasattr(dll, f)]
            exported_fmi2 = [f for f in ("fmi2DoStep", "fmi2Instantiate") if hasattr(dll, f)]
        else:
            names = p2.exported_symbols(lib, plat)
            missing = sorted(set(FMI3_CS_FUNCTIONS) - names)
            exported_fmi2 = sorted(n for n in names if n.startswith("fmi2"))
        if missing or exported_fmi2:
            raise SystemExit(f"build_fmu --native --fmi 3: the {plat} library does not export {missing} or "
                             f"exports FMI 2.0 functions {exported_fmi2}")
    return p2.write_native_fmu(out, files, md, platforms, PLATFORM_TUPLES, "mpc_native_fmi3.c", MODEL_IDENTIFIER,
                               exports_fmi3_only)
