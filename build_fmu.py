"""Build mpc_actuator.fmu (FMI 2.0 co-simulation) with pythonfmu and complete its modelDescription.xml.

    python build_fmu.py [--out PATH] [--start-values JSON] [--no-status-shim]   (default: ./mpc_actuator.fmu)
    python build_fmu.py --fmi 3 [--out PATH] [--start-values JSON]            (./mpc_actuator_fmi3.fmu)
    python build_fmu.py --controller [--out PATH] [--no-status-shim]           (./mpc_controller.fmu)
    python build_fmu.py --native [PLATFORMS] [--fmi 3] [--out PATH] [--start-values JSON] (./mpc_actuator_native.fmu)

pythonfmu writes neither units nor InitialUnknowns nor output dependencies; this script adds them after the build:

* <UnitDefinitions> with SI base-unit exponents and display units (mm and um for m, mN for N, mT for T, ...), and a
  ``unit`` attribute on every Real variable with its default ``displayUnit`` (mm on lengths, mN on forces, mT on the
  field, see DISPLAY_UNITS);
* ModelStructure/Outputs with dependencies (the actuator's outputs at a communication point do not depend directly
  on the input V: no direct feedthrough; the controller's V depends on x_ref and x_meas) and
  ModelStructure/InitialUnknowns listing every output (all have initial="calculated", FMI 2.0 section 3.3.1 / 4.3.1);
* DefaultExperiment startTime=0, stopTime=1, stepSize=1e-3 (fmpy then samples every 1 ms: 1000 intervals is its
  limit before it doubles the interval).

Status shim (``fmu_shim/fmi2_status_shim.c``, README "The FMU"): compiled here with the system C compiler
(``$CC``, sysconfig's CC, ``cc`` or ``gcc``; else ``zig cc`` from the PyPI package ziglang), it becomes
``binaries/linux64/mpc_actuator.so`` around pythonfmu's binary (renamed ``mpc_actuator_pythonfmu.so``): fmi2Error
for recoverable errors, FMU state, Python start-up in native hosts. Other platforms keep pythonfmu's stock
binaries; ``--no-status-shim`` builds without it.

The zip is rewritten into a temporary file next to the target and moved into place atomically.
"""
from __future__ import annotations

import argparse
import ast
import importlib.util
import ctypes
import json
import os
import platform
import shlex
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from contextlib import contextmanager
from pathlib import Path
from xml.dom.minidom import parseString

HERE = Path(__file__).resolve().parent
SRC_DIR = HERE / "fmu_src"
SCRIPT = SRC_DIR / "mpc_actuator.py"
MODEL_IDENTIFIER = "mpc_actuator"

# status shim: C source (outside fmu_src, which is shipped into the FMU), compiler flags, and the suffix
# the shim expects on the inner (pythonfmu) library's name: <id>.so -> <id>_pythonfmu.so
SHIM_SRC = HERE / "fmu_shim" / "fmi2_status_shim.c"
SHIM_CFLAGS = ("-shared", "-fPIC", "-O2", "-Wall", "-Wextra", "-pthread", "-fvisibility=hidden")
SHIM_LIBS = ("-ldl",)
INNER_SUFFIX = "_pythonfmu"
# every FMI 2.0 co-simulation function (and the common ones): the shim must export all of them
FMI2_CS_FUNCTIONS = (
    "fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate", "fmi2FreeInstance",
    "fmi2SetupExperiment", "fmi2EnterInitializationMode", "fmi2ExitInitializationMode", "fmi2Terminate",
    "fmi2Reset", "fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean", "fmi2GetString", "fmi2SetReal",
    "fmi2SetInteger", "fmi2SetBoolean", "fmi2SetString", "fmi2GetFMUstate", "fmi2SetFMUstate",
    "fmi2FreeFMUstate", "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate",
    "fmi2GetDirectionalDerivative", "fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives",
    "fmi2DoStep", "fmi2CancelStep", "fmi2GetStatus", "fmi2GetRealStatus", "fmi2GetIntegerStatus",
    "fmi2GetBooleanStatus", "fmi2GetStringStatus")
NO_SHIM_WARNING = ("build_fmu: warning: built without the status shim (--no-status-shim): invalid parameters "
                   "and failed steps give fmi2Fatal instead of fmi2Error, and the instance cannot be reset")

# name -> (SI base-unit exponents kg, m, s, A, K; display units {name: factor}), display = factor*value: the scales
# an importer may show values in (the model computes in SI); DISPLAY_UNITS: the one a variable is shown in by default
UNITS: dict[str, tuple[dict[str, int], dict[str, float]]] = {
    "1": ({}, {}), "m": ({"m": 1}, {"mm": 1000.0, "um": 1e6}), "m/s": ({"m": 1, "s": -1}, {"mm/s": 1000.0}),
    "N": ({"kg": 1, "m": 1, "s": -2}, {"mN": 1000.0}), "A": ({"A": 1}, {"mA": 1000.0}),
    "V": ({"kg": 1, "m": 2, "s": -3, "A": -1}, {}), "T": ({"kg": 1, "s": -2, "A": -1}, {"mT": 1000.0}),
    "Ohm": ({"kg": 1, "m": 2, "s": -3, "A": -2}, {}), "H": ({"kg": 1, "m": 2, "s": -2, "A": -2}, {"mH": 1000.0}),
    "kg": ({"kg": 1}, {"g": 1000.0}), "N/m": ({"kg": 1, "s": -2}, {"N/mm": 1e-3}),
    "N/m3": ({"kg": 1, "m": -2, "s": -2}, {}), "N.s/m": ({"kg": 1, "s": -1}, {}),
    "N.m/T2": ({"kg": -1, "m": 2, "s": 2, "A": 2}, {}), "T/A": ({"kg": 1, "s": -2, "A": -2}, {"mT/A": 1000.0}),
    # effect parameters (fmu_src.specs.EFFECT_SPECS)
    "K/W": ({"kg": -1, "m": -2, "s": 3, "K": 1}, {}), "s": ({"s": 1}, {"ms": 1000.0}),
    "1/T2": ({"kg": -2, "s": 4, "A": 2}, {}), "N/m5": ({"kg": 1, "m": -4, "s": -2}, {}),
}

# Units of the non-parameter Reals and of rtol; parameters take theirs from fmu_src.specs.ALL_SPECS.
VARIABLE_UNITS = {"V": "V", "x": "m", "v": "m/s", "F": "N", "I": "A", "B": "T", "rtol": "1",
                  "x_sensor": "m", "F_sensor": "N", "x_ref": "m", "x_meas": "m", "Kp": "V/m", "Ki": "V/m.s",
                  "Kd": "V.s/m", "Tf": "s", "Tt": "s", "V_min": "V", "V_max": "V"}   # 2nd line: the controller
DISPLAY_UNITS = {"m": "mm", "m/s": "mm/s", "N": "mN", "T": "mT", "H": "mH", "kg": "g"}   # A, V and s stay SI

# Initial values after fmi2ExitInitializationMode: I = x = v = F = B = x_sensor = F_sensor = 0
# whatever the parameters; contact = (r0 == 0 and not blocked).
INITIAL_DEPENDENCIES = {"contact": ("r0", "blocked")}
# Outputs depend on no input (the actuator: V enters only the derivatives) but the controller's V (feedthrough)
OUTPUT_DEPENDENCIES = {"V": ("x_ref", "x_meas")}
CONTROLLER_SCRIPT, CONTROLLER_IDENTIFIER = SRC_DIR / "mpc_controller.py", "mpc_controller"


def _specs():
    """This tree's ``fmu_src.specs`` (pure Python: units, descriptions)."""
    sys.path.insert(0, str(HERE))
    try:
        from fmu_src import specs
    finally:
        sys.path.remove(str(HERE))
    return specs


def _unit_tables() -> tuple[dict, dict]:
    """(variable name -> unit, unit -> (SI base-unit exponents, display units)) from the specs and UNITS; a unit
    of the specs without a line in UNITS gets its SI exponents read from the unit string."""
    specs = _specs()
    units = {**{s.name: s.unit for s in specs.ALL_SPECS}, **VARIABLE_UNITS, "time": "s"}
    return units, {**UNITS, **{u: (specs.si_exponents(u), {}) for u in units.values() if u not in UNITS}}


def _set_unit(el: ET.Element, name: str, tables: tuple[dict, dict]) -> str:
    """Give the type element ``el`` of variable ``name`` its unit, its display unit (DISPLAY_UNITS) and a shortest
    round-trip start value (pythonfmu writes %.16g); returns the unit."""
    units, unit_defs = tables
    if name not in units:
        raise SystemExit(f"build_fmu: no unit known for real variable {name!r}")
    unit = units[name]
    if unit not in unit_defs:
        raise SystemExit(f"build_fmu: unit {unit!r} of {name!r} has no definition")
    el.set("unit", unit)
    if el.get("start") is not None:
        el.set("start", repr(float(el.get("start"))))
    if unit in DISPLAY_UNITS:
        el.set("displayUnit", DISPLAY_UNITS[unit])
    return unit


def _insert_unit_definitions(root: ET.Element, unit_defs: dict, used: set) -> None:
    """Replace <UnitDefinitions> by the used units, right after <CoSimulation> (the schema's order)."""
    for old in root.findall("UnitDefinitions"):
        root.remove(old)
    udefs = ET.Element("UnitDefinitions")
    for name in unit_defs:
        if name not in used:
            continue
        exps, displays = unit_defs[name]
        u = ET.SubElement(udefs, "Unit", name=name)
        ET.SubElement(u, "BaseUnit", {k: str(v) for k, v in exps.items()})
        for dname, factor in displays.items():
            ET.SubElement(u, "DisplayUnit", name=dname, factor=repr(factor))
    children = list(root)
    root.insert(next(i for i, c in enumerate(children) if c.tag == "CoSimulation") + 1, udefs)


def complete_model_description(xml_bytes: bytes, fmu_state: bool = False) -> bytes:
    """Return the modelDescription with units, ModelStructure and DefaultExperiment completed.

    ``fmu_state``: declare canGetAndSetFMUstate and canSerializeFMUstate (the status shim implements them over
    the slave's complete state; pythonfmu's stock binary does not, so they stay false without the shim)."""
    root = ET.fromstring(xml_bytes)
    cs = root.find("CoSimulation")
    for flag in ("canGetAndSetFMUstate", "canSerializeFMUstate"):
        cs.set(flag, "true" if fmu_state else "false")
    tables = _unit_tables()

    # -- ScalarVariables: unit / displayUnit on every Real --------------------------------
    variables = root.find("ModelVariables")
    svs = list(variables.findall("ScalarVariable"))
    index = {sv.get("name"): i + 1 for i, sv in enumerate(svs)}  # 1-based, document order
    used = set()
    for sv in svs:
        real = sv.find("Real")
        if real is None:
            continue
        used.add(_set_unit(real, sv.get("name"), tables))
        if not sv.get("description"):
            raise SystemExit(f"build_fmu: variable {sv.get('name')!r} has no description")
    _insert_unit_definitions(root, tables[1], used)

    # -- DefaultExperiment ----------------------------------------------------------------
    de = root.find("DefaultExperiment")
    if de is None:
        de = ET.Element("DefaultExperiment")
        children = list(root)
        root.insert(children.index(root.find("ModelVariables")), de)
    de.attrib.clear()
    for key, value in (("startTime", "0.0"), ("stopTime", "1.0"), ("stepSize", "0.001")):
        de.set(key, value)

    # -- ModelStructure ---------------------------------------------------------------------
    root.remove(root.find("ModelStructure"))
    ms = ET.SubElement(root, "ModelStructure")
    outputs = [sv for sv in svs if sv.get("causality") == "output"]
    if outputs:
        out_el = ET.SubElement(ms, "Outputs")
        for sv in outputs:
            deps = " ".join(str(index[n]) for n in OUTPUT_DEPENDENCIES.get(sv.get("name"), ()))   # "": none
            ET.SubElement(out_el, "Unknown", index=str(index[sv.get("name")]), dependencies=deps)
    initial = [sv for sv in outputs if sv.get("initial") in (None, "calculated", "approx")]
    initial += [sv for sv in svs if sv.get("causality") == "calculatedParameter"]
    if initial:
        init_el = ET.SubElement(ms, "InitialUnknowns")
        for sv in sorted(initial, key=lambda s: index[s.get("name")]):  # ascending order required
            deps = " ".join(str(index[n]) for n in INITIAL_DEPENDENCIES.get(sv.get("name"), ()))
            attrs = {} if sv.get("name") in OUTPUT_DEPENDENCIES else {"dependencies": deps}   # none: on all
            ET.SubElement(init_el, "Unknown", index=str(index[sv.get("name")]), **attrs)
    return parseString(ET.tostring(root, encoding="UTF-8")).toprettyxml(indent="  ", encoding="UTF-8")


def _strip_blank_lines(xml: bytes) -> bytes:
    return b"\n".join(line for line in xml.splitlines() if line.strip()) + b"\n"


# ----------------------------------------------------------------------------------------
# status shim
# ----------------------------------------------------------------------------------------
def shim_platform() -> str | None:
    """FMI platform folder the shim is compiled for on this machine (linux64), or None if unsupported."""
    if sys.platform.startswith("linux") and platform.machine().lower() in ("x86_64", "amd64"):
        return "linux64"
    return None


@contextmanager
def _replacing(target: Path):
    """Yield a temporary file name next to ``target``; when the block succeeds the file gets the mode a plain
    open() would give (0666 minus the umask; mkstemp makes 0600) and atomically replaces ``target``; when it
    fails the file is removed."""
    fd, tmp = tempfile.mkstemp(prefix=target.name + ".", suffix=".tmp", dir=target.parent)
    os.close(fd)
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, target)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def find_c_compiler() -> list[str] | None:
    """Command (argv) of a C compiler: $CC, sysconfig's CC, cc or gcc (the first found on PATH), else the
    Zig toolchain's ``zig cc`` when the PyPI package ``ziglang`` is installed (``make setup`` installs it
    only on a machine without a C compiler), else None."""
    candidates = [os.environ.get("CC"), sysconfig.get_config_var("CC"), "cc", "gcc"]
    for cand in candidates:
        argv = shlex.split(cand) if cand else []
        if argv and shutil.which(argv[0]):
            return [shutil.which(argv[0])] + argv[1:]
    if importlib.util.find_spec("ziglang") is not None:
        return [sys.executable, "-m", "ziglang", "cc"]
    return None


def compile_status_shim(out: Path) -> Path:
    """Compile fmu_shim/fmi2_status_shim.c into the shared library ``out``; check that it exports every FMI 2.0
    co-simulation function. Exits with a clear message when no compiler is found or compilation fails."""
    out = Path(out)
    plat = shim_platform()
    if plat is None:
        raise SystemExit(f"build_fmu: the status shim is built for linux64 only (this is {sys.platform}, "
                         f"{platform.machine()}); pass --no-status-shim to build with pythonfmu's stock binaries")
    cc = find_c_compiler()
    if cc is None:
        raise SystemExit(
            "build_fmu: no C compiler found (looked for $CC, sysconfig's CC "
            f"{sysconfig.get_config_var('CC')!r}, cc and gcc on PATH, and the PyPI package ziglang). The status shim "
            f"({SHIM_SRC.relative_to(HERE)}) that makes bad parameters return fmi2Error needs one: install gcc "
            "or `pip install ziglang` (a C toolchain from PyPI), "
            "or pass --no-status-shim to build without it (bad parameters then give fmi2Fatal).")
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = [*cc, *SHIM_CFLAGS, "-o", str(out), str(SHIM_SRC), *SHIM_LIBS]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0 or not out.is_file():
        raise SystemExit(f"build_fmu: compiling the status shim failed:\n  {shlex.join(cmd)}\n{proc.stderr}")
    if proc.stderr.strip():
        print(f"build_fmu: compiler warnings for the status shim:\n{proc.stderr}", file=sys.stderr)
    lib = ctypes.CDLL(str(out))  # loads only the shim (the inner library is loaded at fmi2Instantiate)
    missing = [f for f in FMI2_CS_FUNCTIONS if not hasattr(lib, f)]
    if missing:
        raise SystemExit(f"build_fmu: the status shim does not export {missing}")
    return out


def postprocess(fmu: Path, status_shim: Path | None = None, *, model_identifier: str = MODEL_IDENTIFIER,
                complete_md: bool = True) -> None:
    """Rewrite the zip (temp file + atomic replace): complete modelDescription.xml (``complete_md``) and, with
    ``status_shim`` (a library from compile_status_shim), put the shim in place of binaries/linux64/<model_identifier>.so
    and rename pythonfmu's binary to <model_identifier>_pythonfmu.so (the actuator's and the controller's FMU).
    Only the shim's platform (linux64) is wrapped; other platforms' binaries are left as pythonfmu made them.
    """
    fmu = Path(fmu)
    plat = shim_platform() if status_shim else None
    stock = f"binaries/{plat}/{model_identifier}.so"
    inner = f"binaries/{plat}/{model_identifier}{INNER_SUFFIX}.so"
    with _replacing(fmu) as tmp:
        with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zout:
            names = zin.namelist()
            if status_shim and (stock not in names or inner in names or SHIM_MARKER in names):
                raise SystemExit(f"build_fmu: cannot add the status shim: expected {stock} and no {inner} "
                                 f"in the FMU (found {[n for n in names if n.startswith('binaries/')]})")
            for item in zin.infolist():
                data = zin.read(item.filename)
                if item.filename == "modelDescription.xml" and complete_md:
                    data = _strip_blank_lines(complete_model_description(data, fmu_state=bool(status_shim)))
                if status_shim and item.filename == stock:
                    renamed = zipfile.ZipInfo(inner, date_time=item.date_time)
                    renamed.external_attr = item.external_attr
                    zout.writestr(renamed, data, compress_type=zipfile.ZIP_DEFLATED)
                    data = Path(status_shim).read_bytes()
                zout.writestr(item, data, compress_type=zipfile.ZIP_DEFLATED)
            if status_shim:
                # tells the slave which platforms' binaries are the shim (fmu_src/mpc_actuator.py: there it
                # reports recoverable errors without raising; elsewhere it must raise)
                zout.writestr(SHIM_MARKER, json.dumps({"platforms": [plat]}) + "\n",
                              compress_type=zipfile.ZIP_DEFLATED)


SHIM_MARKER = "resources/status_shim.json"   # {"platforms": ["linux64"]}: binaries that are the status shim


def add_status_shim(fmu: Path, model_identifier: str) -> None:
    """Wrap the linux64 binary of any pythonfmu FMU with the status shim (used by benchmarks/bench_fmu_step.py
    for its trivial FMU); the modelDescription is left alone."""
    with tempfile.TemporaryDirectory(prefix="status_shim_") as tmpd:
        shim = compile_status_shim(Path(tmpd) / f"{model_identifier}.so")
        postprocess(fmu, status_shim=shim, model_identifier=model_identifier, complete_md=False)


PYTHON_JSON = "python.json"           # resources/python.json: the interpreter the status shim starts
PYTHON_ENV = "MPC_ACTUATOR_PYTHON"    # overrides it (path of a JSON file of the same form)


def python_description() -> dict:
    """The interpreter running this build, as the status shim needs it to start Python in a host without one
    (fmu_shim/fmi2_status_shim.c, prepare_python): libpython (LIBDIR/LDLIBRARY), home (sys.base_prefix, the
    standard library) and paths (this environment's site-packages: numpy, scipy, numba; PYTHONHOME bypasses
    venvs). Exits when this Python has no shared libpython (a host cannot load a static one)."""
    libpython = Path(sysconfig.get_config_var("LIBDIR") or "") / (sysconfig.get_config_var("LDLIBRARY") or "")
    if libpython.suffix != ".so" or not libpython.is_file():
        raise SystemExit(f"build_fmu: this Python ({sys.executable}) has no shared libpython ({libpython}); the FMU "
                         "needs one in a native host (build Python with --enable-shared)")
    home = sys.base_prefix if sys.base_exec_prefix == sys.base_prefix else f"{sys.base_prefix}:{sys.base_exec_prefix}"
    paths = list(dict.fromkeys([sysconfig.get_path("purelib"), sysconfig.get_path("platlib")]))
    return {"format": "mpc_actuator-python/1", "version": f"{sys.version_info.major}.{sys.version_info.minor}",
            "libpython": str(libpython.resolve()), "home": home, "paths": paths}


NUMBA_CACHE_SUFFIXES = (".nbi", ".nbc")
_COMPILE_SCRIPT = """
import os, sys
import fmu_src
assert os.path.dirname(os.path.abspath(fmu_src.__file__)) == sys.argv[1], (fmu_src.__file__, sys.argv[1])
from fmu_src.model import compile_all
compile_all()
"""


def add_numba_cache(fmu: Path, workdir: Path) -> list[str]:
    """Ship numba's cache of the FMU's compiled integrator in resources/fmu_src/__pycache__.

    Extracts the FMU's own resources/fmu_src into ``workdir``, compiles every entry point there in a
    fresh interpreter (``fmu_src.model.compile_all``; numba writes its cache next to the sources) and
    adds the cache files to the FMU. numba keys the cache to the contents of the physics sources
    (``fmu_src.integrator._PhysicsCacheLocator``: a hash, no file times) and to the CPU, so an FMU
    extracted anew on this machine (fmpy extracts into a new temp dir every time) loads the compiled
    code instead of compiling for seconds; on another CPU numba compiles (and caches) at first use.
    Returns the names added.
    """
    workdir = Path(workdir)
    with zipfile.ZipFile(fmu) as z:
        members = [n for n in z.namelist() if n.startswith("resources/fmu_src/")]
        z.extractall(workdir, members=members)
    src = (workdir / "resources").resolve()
    # start from this tree's own cache when it is there: entries are keyed to the sources' contents
    # (the same as the FMU's), so valid ones load instead of compiling and stale ones are ignored
    own = SRC_DIR / "__pycache__"
    if own.is_dir():
        (src / "fmu_src" / "__pycache__").mkdir(exist_ok=True)
        for p in own.iterdir():
            if p.suffix in NUMBA_CACHE_SUFFIXES:
                shutil.copyfile(p, src / "fmu_src" / "__pycache__" / p.name)
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CACHE")}
    env["PYTHONPATH"] = str(src)
    proc = subprocess.run([sys.executable, "-c", _COMPILE_SCRIPT, str(src / "fmu_src")], cwd=src, env=env,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"build_fmu: compiling the integrator for the FMU's cache failed:\n{proc.stderr}")
    cache = sorted(p for p in (src / "fmu_src" / "__pycache__").iterdir() if p.suffix in NUMBA_CACHE_SUFFIXES)
    if not cache:
        raise SystemExit("build_fmu: numba wrote no cache files")
    names = []
    with zipfile.ZipFile(fmu, "a", zipfile.ZIP_DEFLATED) as z:
        for p in cache:
            name = f"resources/fmu_src/__pycache__/{p.name}"
            z.write(p, name)
            names.append(name)
    return names


def check_start_values(values: dict) -> dict:
    """Validate start values to bake in ({name: value}, SI, FMU variable names); returns a clean copy."""
    sys.path.insert(0, str(HERE)) if str(HERE) not in sys.path else None
    from fmu_src.specs import EFFECT_SPECS, SPECS, TERM_SPECS, Params
    known = {s.name for s in SPECS + EFFECT_SPECS + TERM_SPECS}
    clean = {}
    for name, value in values.items():
        if name == "blocked":
            clean[name] = bool(value)
        elif name in known or name == "rtol":
            clean[name] = float(value)
        else:
            raise ValueError(f"start value for unknown parameter {name!r} (known: {sorted(known | {'blocked', 'rtol'})})")
    Params(**{k: v for k, v in clean.items() if k != "rtol"}).validated()
    return clean


def shipped_modules(script: Path = SCRIPT) -> list[str]:
    """File names in fmu_src of the modules the slave (``SCRIPT``) imports, directly or through each other
    (read from their import statements), and the package's __init__.py: what the FMU ships."""
    found, todo = {"__init__.py"}, [script]
    while todo:
        for node in ast.walk(ast.parse(todo.pop().read_text())):
            if isinstance(node, ast.Import):
                mods = [a.name.split(".")[1] for a in node.names if a.name.startswith("fmu_src.")]
            elif isinstance(node, ast.ImportFrom) and (node.level > 0 or (node.module or "").split(".")[0] == "fmu_src"):
                sub = node.module.split(".")[0 if node.level else 1:] if node.module else []
                mods = sub[:1] if sub else [a.name for a in node.names]   # from .x import y / from . import x
            else:
                continue
            for mod in mods:
                path = SRC_DIR / f"{mod}.py"
                if path.is_file() and path.name not in found:
                    found.add(path.name)
                    todo.append(path)
    return sorted(found)


def build(out: str | os.PathLike = HERE / f"{MODEL_IDENTIFIER}.fmu", start_values: dict | None = None,
          status_shim: bool = True, fmi: str = "2", controller: bool = False) -> Path:
    """Build the FMU at ``out`` and return its path (``fmi="3"``: the FMI 3.0 FMU, ``build_fmi3``).

    ``start_values`` ({parameter name: SI value}) are baked in: shipped as resources/start_values.json, read by
    the slave at instantiation, and therefore also the start values the modelDescription declares.

    ``status_shim`` (default): compile fmu_shim/fmi2_status_shim.c with the system C compiler and wrap pythonfmu's
    linux64 binary with it (fmi2Error instead of fmi2Fatal for reported errors; see the module docstring); exits
    with a clear message if there is no compiler. False: pythonfmu's stock binaries only (a warning is printed).
    ``controller``: build the controller FMU (fmu_src/mpc_controller.py) instead.
    """
    if str(fmi) == "3":
        if controller:
            raise SystemExit("build_fmu: the controller FMU is FMI 2.0 only (no --fmi 3 with --controller)")
        if not status_shim:
            raise SystemExit("build_fmu: --no-status-shim is for FMI 2.0 only (the FMI 3.0 FMU has no shim)")
        return build_fmi3(out, start_values=start_values)
    from pythonfmu.builder import FmuBuilder
    script, ident = (CONTROLLER_SCRIPT, CONTROLLER_IDENTIFIER) if controller else (SCRIPT, MODEL_IDENTIFIER)
    out = Path(out).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    if str(HERE) not in sys.path:  # the builder imports the slave, which imports fmu_src
        sys.path.insert(0, str(HERE))
    with tempfile.TemporaryDirectory(prefix="mpc_fmu_build_") as tmpd:
        # the shim first: no compiler -> fail before anything else is done
        shim = compile_status_shim(Path(tmpd) / "shim" / f"{ident}.so") if status_shim else None
        staged = Path(tmpd) / f"{ident}.fmu"
        modules = shipped_modules(script)   # only the fmu_src modules the slave imports
        (Path(tmpd) / "fmu_src").mkdir()
        for name in modules:
            shutil.copy2(SRC_DIR / name, Path(tmpd) / "fmu_src" / name)
        project = [Path(tmpd) / "fmu_src"]
        if shim:   # where the shim finds Python in a host without one (resources/python.json)
            pj = Path(tmpd) / PYTHON_JSON
            pj.write_text(json.dumps(python_description(), indent=2) + "\n")
            project.append(pj)
        if start_values:
            sv = Path(tmpd) / "start_values.json"
            sv.write_text(json.dumps(check_start_values(start_values), indent=2) + "\n")
            project.append(sv)
        built = Path(FmuBuilder.build_FMU(script, dest=staged, project_files=project))
        postprocess(built, status_shim=shim, model_identifier=ident)
        add_numba_cache(built, Path(tmpd) / "numba_cache")
        names = zipfile.ZipFile(built).namelist()
        required = [f"resources/{script.name}", f"binaries/linux64/{ident}.so"]
        required += [f"resources/fmu_src/{name}" for name in modules]
        extra = [n for n in names if n.startswith("resources/fmu_src/") and n.endswith(".py")
                 and n not in required]
        if extra:
            raise SystemExit(f"build_fmu: {extra} in the FMU but not imported by the slave")
        if shim:
            required.append(f"binaries/{shim_platform()}/{ident}{INNER_SUFFIX}.so")
        for name in required:
            if name not in names:
                raise SystemExit(f"build_fmu: {name} missing from the FMU")
        # move into place atomically (same filesystem: copy next to the target first)
        with _replacing(out) as tmp, open(built, "rb") as src, open(tmp, "wb") as dst:
            dst.write(src.read())
    if not status_shim:
        print(NO_SHIM_WARNING, file=sys.stderr)
    return out


# ----------------------------------------------------------------------------------------
# FMI 3.0 (pythonfmu3): the same slave through fmu_src/mpc_actuator_fmi3.py
# ----------------------------------------------------------------------------------------
SCRIPT_FMI3 = SRC_DIR / "mpc_actuator_fmi3.py"
MODEL_IDENTIFIER_FMI3 = "mpc_actuator_fmi3"


def complete_model_description_fmi3(xml_bytes: bytes) -> bytes:
    """pythonfmu3's modelDescription completed like the FMI 2.0 one: UnitDefinitions, a unit on every Float64
    (default display units: mm on lengths, mN on forces, ...), Output dependencies (none: no direct feedthrough), InitialUnknown dependencies
    (contact on r0 and blocked), start values by repr, variable communication step sizes."""
    root = ET.fromstring(xml_bytes)
    tables = _unit_tables()
    root.find("CoSimulation").set("canHandleVariableCommunicationStepSize", "true")
    variables = root.find("ModelVariables")
    vr = {v.get("name"): v.get("valueReference") for v in variables}
    used = {_set_unit(v, v.get("name"), tables) for v in variables if v.tag == "Float64"}
    _insert_unit_definitions(root, tables[1], used)
    ms = root.find("ModelStructure")
    for el in ms:
        if el.tag == "Output":
            el.set("dependencies", "")
        elif el.tag == "InitialUnknown":
            name = next(n for n, r in vr.items() if r == el.get("valueReference"))
            deps = INITIAL_DEPENDENCIES.get(name, ())
            if deps:
                el.set("dependencies", " ".join(vr[d] for d in deps))
            else:
                el.set("dependencies", "")
    return parseString(ET.tostring(root, encoding="UTF-8")).toprettyxml(indent="  ", encoding="UTF-8")


def build_fmi3(out: str | os.PathLike = HERE / f"{MODEL_IDENTIFIER_FMI3}.fmu", start_values: dict | None = None) -> Path:
    """Build the FMI 3.0 co-simulation FMU at ``out`` with pythonfmu3 (no status shim: see README.md);
    ``start_values`` as for ``build``."""
    from pythonfmu3.builder import FmuBuilder as Fmu3Builder

    out = Path(out).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    if str(HERE) not in sys.path:
        sys.path.insert(0, str(HERE))
    with tempfile.TemporaryDirectory(prefix="mpc_fmu3_build_") as tmpd:
        project = [SRC_DIR]
        if start_values:
            sv = Path(tmpd) / "start_values.json"
            sv.write_text(json.dumps(check_start_values(start_values), indent=2) + "\n")
            project.append(sv)
        built = Path(Fmu3Builder.build_FMU(SCRIPT_FMI3, dest=Path(tmpd) / "stage", project_files=project))
        with zipfile.ZipFile(built) as zin, zipfile.ZipFile(Path(tmpd) / "done.fmu", "w", zipfile.ZIP_DEFLATED) as zout:
            for item in zin.infolist():
                data = zin.read(item.filename)
                if item.filename == "modelDescription.xml":
                    data = _strip_blank_lines(complete_model_description_fmi3(data))
                zout.writestr(item, data, compress_type=zipfile.ZIP_DEFLATED)
        done = Path(tmpd) / "done.fmu"
        add_numba_cache(done, Path(tmpd) / "numba_cache")
        with _replacing(out) as tmp, open(done, "rb") as src, open(tmp, "wb") as dst:
            dst.write(src.read())
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="FMU file to write (default: ./<model identifier>.fmu)")
    ap.add_argument("--start-values", help="JSON file {parameter: SI value} to bake in as start values")
    ap.add_argument("--no-status-shim", action="store_true",
                    help="do not compile the C status shim (no C compiler needed; bad parameters then give "
                         "fmi2Fatal instead of fmi2Error)")
    ap.add_argument("--fmi", choices=("2", "3"), default="2",
                    help="FMI version: 2 (default, mpc_actuator.fmu) or 3 (pythonfmu3, mpc_actuator_fmi3.fmu: no status "
                         "shim, no FMU state; see README.md)")
    ap.add_argument("--controller", action="store_true", help="build the controller FMU (mpc_controller.fmu)")
    ap.add_argument("--native", nargs="?", const="linux64", metavar="PLATFORMS",
                    help="build mpc_actuator_native.fmu: the model compiled to C, no Python needed (fmu_shim/native); "
                         "PLATFORMS: comma-separated FMI platform folders (default linux64; e.g. linux64,win64,darwin64)")
    args = ap.parse_args(argv)
    ident = ("mpc_actuator_native" + ("_fmi3" if args.fmi == "3" else "")) if args.native else \
        MODEL_IDENTIFIER_FMI3 if args.fmi == "3" else CONTROLLER_IDENTIFIER if args.controller else MODEL_IDENTIFIER
    args.out = args.out or str(HERE / f"{ident}.fmu")
    sv = None
    if args.start_values:
        try:
            sv = json.loads(Path(args.start_values).read_text())
            sv = check_start_values(sv)
        except (OSError, ValueError) as e:
            raise SystemExit(f"build_fmu: --start-values {args.start_values}: {e}")
    if args.native:
        from fmu_shim.native.package import build_native   # --fmi 3: mpc_actuator_native_fmi3.fmu (FMI 3.0 CS)
        path = build_native(args.out, start_values=sv, platforms=tuple(args.native.split(",")), fmi=args.fmi)
    else:
        path = build(args.out, start_values=sv, status_shim=not args.no_status_shim, fmi=args.fmi,
                     controller=args.controller)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
