"""Build mpc_actuator_native.fmu: the model compiled to C, no Python at run time (``python build_fmu.py --native``).

* modelDescription.xml: the pythonfmu slave's own (``fmu_src.mpc_actuator.MpcActuator(...).to_xml()``, with the
  baked start values if any) completed by ``build_fmu.complete_model_description`` exactly as for
  mpc_actuator.fmu, so the variables, value references, units, descriptions and start values are the same; only
  the CoSimulation element differs (modelIdentifier ``mpc_actuator_native``, needsExecutionTool false, FMU state,
  source files) and the GUID (a hash of the generated sources);
* sources/: ``mpc_native.c`` (this folder), ``mpc_native_gen.h`` (``codegen.generate_header``: the equations
  traced from fmu_src) and ``mpc_native_vars.h`` (value references and start values, from the modelDescription):
  a source FMU that any C99 compiler builds;
* binaries/<platform>/: compiled here, linux64 with the local C compiler (``build_fmu.find_c_compiler``), other
  platforms with ``zig cc -target ...`` (PyPI package ziglang) when asked (``platforms``).
"""
from __future__ import annotations

import ctypes
import hashlib
import json
import shlex
import subprocess
import sys
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from xml.dom.minidom import parseString

HERE = Path(__file__).resolve().parent
C_SOURCE = HERE / "mpc_native.c"
MODEL_IDENTIFIER = "mpc_actuator_native"
# -ffp-contract=off: no fused multiply-add (clang, zig cc, contracts a*b + c into one FMA where the target has it:
# 455 of them in the aarch64 binaries), so that every binary does the operations numba does in fmu_src
CFLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-fvisibility=hidden", "-ffp-contract=off")
# FMI platform folder -> (zig target, shared-library suffix)
TARGETS = {
    "linux64": ("x86_64-linux-gnu", ".so"),
    "win64": ("x86_64-windows-gnu", ".dll"),
    "darwin64": ("x86_64-macos", ".dylib"),
    "darwin-aarch64": ("aarch64-macos", ".dylib"),
    "linux-aarch64": ("aarch64-linux-gnu", ".so"),
}
# variable kinds of mpc_native.c (VR_KIND)
KINDS = ("VK_NONE", "VK_INPUT", "VK_OUTPUT", "VK_PARAM", "VK_RTOL", "VK_BLOCKED", "VK_CONTACT", "VK_STATE", "VK_DER")


def me_states() -> list[tuple[str, str, str]]:
    """(name, unit, description) of the model-exchange state vector: I, x, v, then every effect state (in
    ``fmu_src.specs.BLOCK.state`` order; 0 while its effect is off), then every lag state of the generic term set
    (``fmu_src.terms.LAGS`` order; 0 while every term is off)."""
    from fmu_src.specs import EFFECTS
    from fmu_src.terms import LAGS
    base = [("I", "A", "coil current"), ("x", "m", "centre displacement toward the coil"),
            ("v", "m/s", "centre velocity toward the coil")]
    return (base + [(st.name, st.unit, st.description) for e in EFFECTS.values() for st in e.state_specs]
            + [(g.state, g.unit, f"term set: lag state, lags {g.description}") for g in LAGS.values()])


def _rate_unit(unit: str) -> str:
    """Unit of the time derivative of a quantity in ``unit`` (as the specs write units)."""
    num, _, den = unit.partition("/")
    if not den:
        return f"{num}/s"
    return f"{num}/{den}.s" if not den.startswith("s") else f"{num}/s{int(den[1:] or 1) + 1}"


def _build_fmu_module():
    sys.path.insert(0, str(HERE.parents[1])) if str(HERE.parents[1]) not in sys.path else None
    import build_fmu
    return build_fmu


def slave_model_description(start_values: dict | None) -> tuple[bytes, object]:
    """(completed modelDescription.xml of the pythonfmu slave, the slave instance) with ``start_values`` baked in
    the way the pythonfmu FMU bakes them (resources/start_values.json read by the slave)."""
    bf = _build_fmu_module()
    from fmu_src.mpc_actuator import MpcActuator
    with tempfile.TemporaryDirectory(prefix="mpc_native_md_") as res:
        if start_values:
            (Path(res) / "start_values.json").write_text(json.dumps(bf.check_start_values(start_values)))
        slave = MpcActuator(instance_name="native", resources=res)
        xml = ET.tostring(slave.to_xml(), encoding="UTF-8")
    return bf.complete_model_description(xml, fmu_state=True), slave


def variables_header(md: bytes, slave, guid: str) -> str:
    """mpc_native_vars.h: per value reference its kind and index, names; the start values; the GUID."""
    return vars_header(ET.fromstring(md).find("ModelVariables").findall("ScalarVariable"), slave, guid,
                       "fmu_shim/native/package.py", "build_fmu --native")


def vars_header(variables, slave, guid: str, generator: str, what: str, time_vr: bool = False) -> str:
    """mpc_native_vars.h from the modelDescription's variables (FMI 2.0 ScalarVariables or FMI 3.0 typed
    variables: name, valueReference, causality): per value reference its kind (``KINDS``: the model exchange's
    y.<state> and der(y.<state>) locals by their place in ``me_states``) and index, names; the start values of the
    ``slave``; the GUID (FMI 3.0: instantiation token); with ``time_vr`` VR_TIME, the independent variable's value
    reference. ``SystemExit`` naming a variable that has no place in the native FMU (``what``: the command)."""
    from fmu_shim.native.codegen import c_double, output_slots
    from fmu_src.specs import ALL_SPECS, BLOCK
    slots = output_slots()
    states = [n for n, _, _ in me_states()]
    n_vr = max(int(v.get("valueReference")) for v in variables) + 1
    kind, index, names = ["VK_NONE"] * n_vr, [0] * n_vr, ['""'] * n_vr
    vr_time = None
    for v in variables:
        name, vr, caus = v.get("name"), int(v.get("valueReference")), v.get("causality")
        names[vr] = f'"{name}"'
        if caus == "independent" and time_vr:
            vr_time = vr
        elif caus == "input" and name == "V":
            kind[vr] = "VK_INPUT"
        elif caus == "output" and name == "contact":
            kind[vr] = "VK_CONTACT"
        elif caus == "output":
            kind[vr], index[vr] = "VK_OUTPUT", slots[name]
        elif caus == "parameter" and name == "rtol":
            kind[vr] = "VK_RTOL"
        elif caus == "parameter" and name == "blocked":
            kind[vr] = "VK_BLOCKED"
        elif caus == "parameter" and name in BLOCK.param:
            kind[vr], index[vr] = "VK_PARAM", BLOCK.param[name]
        elif caus == "local" and name.startswith("y.") and name[2:] in states:
            kind[vr], index[vr] = "VK_STATE", states.index(name[2:])
        elif caus == "local" and name.startswith("der(y.") and name[6:-1] in states:
            kind[vr], index[vr] = "VK_DER", states.index(name[6:-1])
        else:
            raise SystemExit(f"{what}: variable {name!r} ({caus}) has no place in the native FMU")
    if time_vr and vr_time is None:
        raise SystemExit(f"{what}: the modelDescription has no independent variable (time)")
    lines = [f"/* Generated by {generator} from the FMU's modelDescription.xml: do not edit. */",
             "#ifndef MPC_NATIVE_VARS_H", "#define MPC_NATIVE_VARS_H",
             f'#define MODEL_GUID "{guid}"', f"#define N_VR {n_vr}"]
    lines += [f"#define VR_TIME {vr_time}"] if time_vr else []
    lines += ["enum { " + ", ".join(KINDS) + " };",
              f"static const int VR_KIND[N_VR] = {{{', '.join(kind)}}};",
              f"static const int VR_INDEX[N_VR] = {{{', '.join(map(str, index))}}};",
              f"static const char *const VR_NAMES[N_VR] = {{{', '.join(names)}}};",
              "static const double START_PARAMS[N_PARAMS] = {"
              + ", ".join(c_double(getattr(slave, s.name)) for s in ALL_SPECS) + "};",
              f"#define START_BLOCKED {1 if slave.blocked else 0}",
              f"#define START_RTOL {c_double(slave.rtol)}", f"#define START_V {c_double(slave.V)}", "#endif", ""]
    return "\n".join(lines)


def native_model_description(md: bytes, guid: str, sources: list[str]) -> bytes:
    """The slave's completed modelDescription with the native FMU's GUID, generation tool and CoSimulation."""
    root = ET.fromstring(md)
    root.set("guid", guid)
    root.set("generationTool", "mpc-actuator build_fmu.py --native (fmu_shim/native)")
    root.set("numberOfEventIndicators", "1")
    me = ET.Element("ModelExchange", modelIdentifier=MODEL_IDENTIFIER, needsExecutionTool="false",
                    completedIntegratorStepNotNeeded="true", canBeInstantiatedOnlyOncePerProcess="false",
                    canNotUseMemoryManagementFunctions="true", canGetAndSetFMUstate="true", canSerializeFMUstate="true")
    root.insert(list(root).index(root.find("CoSimulation")), me)
    _add_me_variables(root)
    cs = root.find("CoSimulation")
    cs.attrib.clear()
    cs.attrib.update(modelIdentifier=MODEL_IDENTIFIER, needsExecutionTool="false",
                     canHandleVariableCommunicationStepSize="true", canInterpolateInputs="false",
                     canBeInstantiatedOnlyOncePerProcess="false", canNotUseMemoryManagementFunctions="true",
                     canGetAndSetFMUstate="true", canSerializeFMUstate="true")
    for el in (me, cs):
        src = ET.SubElement(el, "SourceFiles")
        for name in sources:
            if name.endswith(".c"):
                ET.SubElement(src, "File", name=name)
    xml = parseString(ET.tostring(root, encoding="UTF-8")).toprettyxml(indent="  ", encoding="UTF-8")
    return b"\n".join(line for line in xml.splitlines() if line.strip()) + b"\n"


def _add_me_variables(root: ET.Element) -> None:
    """Model exchange: the state vector (locals y.<state>, start 0) and its derivatives (der(y.<state>)) after the
    co-simulation variables (whose value references stay), their units, ModelStructure/Derivatives and the
    derivatives among the InitialUnknowns."""
    from fmu_src.specs import si_exponents
    variables = root.find("ModelVariables")
    svs = variables.findall("ScalarVariable")
    vr = max(int(sv.get("valueReference")) for sv in svs) + 1
    units = root.find("UnitDefinitions")
    have = {u.get("name") for u in units}
    der_index = []
    for k, (name, unit, desc) in enumerate(me_states()):
        state_index = len(variables.findall("ScalarVariable")) + 1
        sv = ET.SubElement(variables, "ScalarVariable", name=f"y.{name}", valueReference=str(vr + 2 * k),
                           description=f"model-exchange state: {desc}", causality="local", variability="continuous",
                           initial="exact")
        ET.SubElement(sv, "Real", start="0.0", unit=unit, **({"displayUnit": "mm"} if unit == "m" else {}))
        sv = ET.SubElement(variables, "ScalarVariable", name=f"der(y.{name})", valueReference=str(vr + 2 * k + 1),
                           description=f"model-exchange state derivative: d/dt of y.{name}", causality="local",
                           variability="continuous", initial="calculated")
        ET.SubElement(sv, "Real", derivative=str(state_index), unit=_rate_unit(unit))
        der_index.append(state_index + 1)
        for u in (unit, _rate_unit(unit)):
            if u not in have:
                el = ET.SubElement(units, "Unit", name=u)
                ET.SubElement(el, "BaseUnit", {b: str(e) for b, e in si_exponents(u).items()})
                have.add(u)
    ms = root.find("ModelStructure")
    ders = ET.Element("Derivatives")
    for i in der_index:
        ET.SubElement(ders, "Unknown", index=str(i))
    ms.insert(1 if ms.find("Outputs") is not None else 0, ders)
    init = ms.find("InitialUnknowns")
    if init is None:
        init = ET.SubElement(ms, "InitialUnknowns")
    for i in der_index:
        ET.SubElement(init, "Unknown", index=str(i))


def generate_sources(start_values: dict | None = None) -> tuple[dict, bytes]:
    """({file name: text} of the C sources, modelDescription.xml bytes)."""
    from fmu_shim.native.codegen import generate_header
    md, slave = slave_model_description(start_values)
    gen = generate_header()
    c_src = C_SOURCE.read_text()
    h = hashlib.sha256()
    for part in (gen, c_src, md.decode()):
        h.update(part.encode() + b"\0")
    guid = "{" + str(uuid.UUID(bytes=h.digest()[:16], version=4)) + "}"
    files = {"mpc_native.c": c_src, "mpc_native_gen.h": gen, "mpc_native_vars.h": variables_header(md, slave, guid)}
    return files, native_model_description(md, guid, list(files))


def compiler_for(platform: str) -> list[str]:
    """argv of the C compiler for an FMI platform folder: linux64 the local compiler (else zig cc), others zig cc."""
    bf = _build_fmu_module()
    if platform == "linux64":
        cc = bf.find_c_compiler()
        if cc is None:
            raise SystemExit("build_fmu --native: no C compiler found ($CC, cc, gcc, or `pip install ziglang`)")
        return cc
    import importlib.util
    if importlib.util.find_spec("ziglang") is None:
        raise SystemExit(f"build_fmu --native: cross-compiling for {platform} needs zig cc: pip install ziglang "
                         "(the [cc] extra)")
    return [sys.executable, "-m", "ziglang", "cc", "-target", TARGETS[platform][0]]


def compile_library(src_dir: Path, platform: str, out: Path, source: str = "mpc_native.c") -> Path:
    """Compile ``source`` (with the other sources in ``src_dir``) into the shared library ``out`` for ``platform``."""
    cmd = [*compiler_for(platform), *CFLAGS, "-shared"]
    if platform != "win64":
        cmd.append("-fPIC")
    cmd += ["-o", str(out), str(src_dir / source)]
    if not platform.startswith("darwin") and platform != "win64":
        cmd.append("-lm")
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0 or not out.is_file():
        raise SystemExit(f"build_fmu --native: compiling for {platform} failed:\n  {shlex.join(cmd)}\n{proc.stderr}")
    if proc.stderr.strip():
        print(f"build_fmu --native: compiler warnings ({platform}):\n{proc.stderr}", file=sys.stderr)
    return out


def exported_symbols(lib: Path, platform: str) -> set[str]:
    """Names a shared library exports, read with LLVM's object tools (Debian's llvm package: llvm-readobj's COFF
    export table for win64, llvm-nm's defined global symbols for ELF and Mach-O, Mach-O's leading _ removed)."""
    import shutil
    if platform == "win64":
        tool = shutil.which("llvm-readobj")
        cmd = [tool, "--coff-exports", str(lib)]
    else:
        tool = shutil.which("llvm-nm")
        cmd = [tool, "--defined-only", "-g", str(lib)]
    if tool is None:
        raise SystemExit("build_fmu --native: checking the exports of a cross-compiled library needs LLVM's object "
                         "tools (llvm-nm, llvm-readobj: apt-get install llvm)")
    out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
    if platform == "win64":
        return {line.split(":", 1)[1].strip() for line in out.splitlines() if line.strip().startswith("Name:")}
    names = {line.split()[-1] for line in out.splitlines() if len(line.split()) == 3 and line.split()[1] in "TD"}
    return {n[1:] if platform.startswith("darwin") and n.startswith("_") else n for n in names}


def build_native(out: Path, start_values: dict | None = None, platforms=("linux64",), fmi: str = "2") -> Path:
    """Write the native FMU to ``out`` (atomically) and return its path; ``fmi="3"``: the FMI 3.0 co-simulation
    variant (``package_fmi3.build_native_fmi3``)."""
    if fmi == "3":
        from fmu_shim.native.package_fmi3 import build_native_fmi3
        return build_native_fmi3(out, start_values=start_values, platforms=platforms)
    files, md = generate_sources(start_values)

    def exports_fmi2(lib: Path, plat: str) -> None:
        fmi2_functions = _build_fmu_module().FMI2_CS_FUNCTIONS
        if plat == "linux64":
            dll = ctypes.CDLL(str(lib))
            missing = [f for f in fmi2_functions if not hasattr(dll, f)]
        else:
            missing = sorted(set(fmi2_functions) - exported_symbols(lib, plat))
        if missing:
            raise SystemExit(f"build_fmu --native: the {plat} library does not export {missing}")
    return write_native_fmu(out, files, md, platforms, {plat: plat for plat in TARGETS}, "mpc_native.c",
                            MODEL_IDENTIFIER, exports_fmi2)


def write_native_fmu(out: Path, files: dict, md: str, platforms, folders: dict, source: str, model_identifier: str,
                     check) -> Path:
    """Compile the generated sources ``files`` ({name: text}; ``source`` the one compiled) for ``platforms``
    (``build_fmu.py --native``'s names) into ``<model_identifier><suffix>``, check each library with ``check(lib, platform)`` (a SystemExit naming
    what is wrong), and write the FMU to ``out`` atomically: ``md`` as modelDescription.xml, the sources, each
    library in ``binaries/<folders[platform]>/``. Returns the FMU's path (FMI 2.0 and 3.0 alike)."""
    bf = _build_fmu_module()
    out = Path(out).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="mpc_native_build_") as tmpd:
        src = Path(tmpd) / "sources"
        src.mkdir()
        for name, text in files.items():
            (src / name).write_text(text)
        libs = {}
        for plat in platforms:
            if plat not in folders:
                raise SystemExit(f"build_fmu --native: unknown platform {plat!r} (known: {', '.join(folders)})")
            folder = Path(tmpd) / folders[plat]
            folder.mkdir()
            lib = compile_library(src, plat, folder / f"{model_identifier}{TARGETS[plat][1]}", source=source)
            check(lib, plat)
            libs[f"binaries/{folders[plat]}/{lib.name}"] = lib
        with bf._replacing(out) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", md)
            for name, text in files.items():
                z.writestr(f"sources/{name}", text)
            for name, lib in libs.items():
                z.write(lib, name)
    return out
