"""Build mpc_actuator.fmu (FMI 2.0 co-simulation) with pythonfmu and complete its modelDescription.xml.

    python build_fmu.py [--out PATH]        (default: ./mpc_actuator.fmu)

pythonfmu writes neither units nor InitialUnknowns nor output dependencies;
this script adds them after the build:

* <UnitDefinitions> with SI base-unit exponents (and the display unit mm for m),
  and a ``unit`` attribute on every Real variable (``displayUnit="mm"`` on lengths);
* ModelStructure/Outputs with dependencies (outputs at a communication point do
  not depend directly on the input V: no direct feedthrough) and
  ModelStructure/InitialUnknowns listing every output (all have initial="calculated",
  FMI 2.0 section 3.3.1 / 4.3.1);
* DefaultExperiment startTime=0, stopTime=1, stepSize=1e-3 (fmpy then samples
  every 1 ms: 1000 intervals is its limit before it doubles the interval).

The zip is rewritten into a temporary file next to the target and moved into
place atomically.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
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

# name -> (SI base-unit exponents kg, m, s, A, K; display units {name: factor}), display = factor*value
UNITS: dict[str, tuple[dict[str, int], dict[str, float]]] = {
    "1": ({}, {}),
    "m": ({"m": 1}, {"mm": 1000.0}),
    "m/s": ({"m": 1, "s": -1}, {}),
    "N": ({"kg": 1, "m": 1, "s": -2}, {}),
    "A": ({"A": 1}, {}),
    "V": ({"kg": 1, "m": 2, "s": -3, "A": -1}, {}),
    "T": ({"kg": 1, "s": -2, "A": -1}, {}),
    "Ohm": ({"kg": 1, "m": 2, "s": -3, "A": -2}, {}),
    "H": ({"kg": 1, "m": 2, "s": -2, "A": -2}, {}),
    "kg": ({"kg": 1}, {}),
    "N/m": ({"kg": 1, "s": -2}, {}),
    "N/m3": ({"kg": 1, "m": -2, "s": -2}, {}),
    "N.s/m": ({"kg": 1, "s": -1}, {}),
    "N.m/T2": ({"kg": -1, "m": 2, "s": 2, "A": 2}, {}),
    "T/A": ({"kg": 1, "s": -2, "A": -2}, {}),
    # effect parameters (fmu_src.effects.EFFECT_SPECS)
    "K/W": ({"kg": -1, "m": -2, "s": 3, "K": 1}, {}),
    "s": ({"s": 1}, {}),
    "1/T2": ({"kg": -2, "s": 4, "A": 2}, {}),
    "N/m5": ({"kg": 1, "m": -4, "s": -2}, {}),
}

# Units of the non-parameter Reals and of rtol; parameters take theirs from fmu_src.params.SPECS
# and fmu_src.effects.EFFECT_SPECS.
VARIABLE_UNITS = {"V": "V", "x": "m", "v": "m/s", "F": "N", "I": "A", "B": "T", "rtol": "1",
                  "x_sensor": "m", "F_sensor": "N"}
DISPLAY_UNITS = {"m": "mm"}

# Initial values after fmi2ExitInitializationMode: I = x = v = F = B = x_sensor = F_sensor = 0
# whatever the parameters; contact = (r0 == 0 and not blocked).
INITIAL_DEPENDENCIES = {"contact": ("r0", "blocked")}


def _spec_units() -> dict[str, str]:
    sys.path.insert(0, str(HERE))
    try:
        from fmu_src.effects import ALL_SPECS
    finally:
        sys.path.remove(str(HERE))
    return {s.name: s.unit for s in ALL_SPECS}


def _indent(elem: ET.Element, level: int = 0) -> None:
    ET.indent(elem, space="  ", level=level)


def complete_model_description(xml_bytes: bytes) -> bytes:
    """Return the modelDescription with units, ModelStructure and DefaultExperiment completed."""
    root = ET.fromstring(xml_bytes)
    units = {**_spec_units(), **VARIABLE_UNITS}

    # -- ScalarVariables: unit / displayUnit on every Real --------------------------------
    variables = root.find("ModelVariables")
    svs = list(variables.findall("ScalarVariable"))
    index = {sv.get("name"): i + 1 for i, sv in enumerate(svs)}  # 1-based, document order
    used = set()
    for sv in svs:
        real = sv.find("Real")
        if real is None:
            continue
        name = sv.get("name")
        if name not in units:
            raise SystemExit(f"build_fmu: no unit known for Real variable {name!r}")
        unit = units[name]
        if unit not in UNITS:
            raise SystemExit(f"build_fmu: unit {unit!r} of {name!r} has no definition")
        real.set("unit", unit)
        if real.get("start") is not None:  # shortest round-trip repr (pythonfmu writes %.16g)
            real.set("start", repr(float(real.get("start"))))
        used.add(unit)
        if unit in DISPLAY_UNITS:
            real.set("displayUnit", DISPLAY_UNITS[unit])
        if not sv.get("description"):
            raise SystemExit(f"build_fmu: variable {name!r} has no description")

    # -- UnitDefinitions (schema order: CoSimulation, UnitDefinitions, TypeDefinitions, LogCategories, ...)
    for old in root.findall("UnitDefinitions"):
        root.remove(old)
    udefs = ET.Element("UnitDefinitions")
    for name in UNITS:
        if name not in used:
            continue
        exps, displays = UNITS[name]
        u = ET.SubElement(udefs, "Unit", name=name)
        ET.SubElement(u, "BaseUnit", {k: str(v) for k, v in exps.items()})
        for dname, factor in displays.items():
            ET.SubElement(u, "DisplayUnit", name=dname, factor=repr(factor))
    children = list(root)
    pos = next(i for i, c in enumerate(children) if c.tag == "CoSimulation") + 1
    root.insert(pos, udefs)

    # -- DefaultExperiment ----------------------------------------------------------------
    de = root.find("DefaultExperiment")
    if de is None:
        de = ET.Element("DefaultExperiment")
        children = list(root)
        root.insert(children.index(root.find("ModelVariables")), de)
    de.attrib.clear()
    de.set("startTime", "0.0")
    de.set("stopTime", "1.0")
    de.set("stepSize", "0.001")

    # -- ModelStructure ---------------------------------------------------------------------
    old = root.find("ModelStructure")
    root.remove(old)
    ms = ET.SubElement(root, "ModelStructure")
    outputs = [sv for sv in svs if sv.get("causality") == "output"]
    if outputs:
        out_el = ET.SubElement(ms, "Outputs")
        for sv in outputs:
            # No direct feedthrough: V only enters the derivatives, so outputs at a
            # communication point depend on no input ("" = no dependency; absent = all).
            ET.SubElement(out_el, "Unknown", index=str(index[sv.get("name")]), dependencies="")
    initial = [sv for sv in outputs if sv.get("initial") in (None, "calculated", "approx")]
    initial += [sv for sv in svs if sv.get("causality") == "calculatedParameter"]
    if initial:
        init_el = ET.SubElement(ms, "InitialUnknowns")
        for sv in sorted(initial, key=lambda s: index[s.get("name")]):  # ascending order required
            deps = " ".join(str(index[n]) for n in INITIAL_DEPENDENCIES.get(sv.get("name"), ()))
            ET.SubElement(init_el, "Unknown", index=str(index[sv.get("name")]), dependencies=deps)

    return parseString(ET.tostring(root, encoding="UTF-8")).toprettyxml(indent="  ", encoding="UTF-8")


def _strip_blank_lines(xml: bytes) -> bytes:
    return b"\n".join(line for line in xml.splitlines() if line.strip()) + b"\n"


@contextmanager
def _replacing(target: Path):
    """Yield a temporary file name next to ``target``; when the block succeeds the file
    atomically replaces ``target``, when it fails the file is removed."""
    fd, tmp = tempfile.mkstemp(prefix=target.name + ".", suffix=".tmp", dir=target.parent)
    os.close(fd)
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def postprocess(fmu: Path) -> None:
    """Rewrite modelDescription.xml inside the zip (temp file + atomic replace)."""
    fmu = Path(fmu)
    with _replacing(fmu) as tmp, zipfile.ZipFile(fmu) as zin, \
            zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = _strip_blank_lines(complete_model_description(data))
            zout.writestr(item, data, compress_type=zipfile.ZIP_DEFLATED)


def check_start_values(values: dict) -> dict:
    """Validate start values to bake in ({name: value}, SI, FMU variable names); returns a clean copy."""
    sys.path.insert(0, str(HERE)) if str(HERE) not in sys.path else None
    from fmu_src.params import Params, SPECS
    from fmu_src.effects import EFFECT_SPECS
    known = {s.name for s in SPECS + EFFECT_SPECS}
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


def build(out: str | os.PathLike = HERE / f"{MODEL_IDENTIFIER}.fmu", start_values: dict | None = None) -> Path:
    """Build the FMU at ``out`` and return its path.

    ``start_values`` ({parameter name: SI value}) are baked in: shipped as
    resources/start_values.json, read by the slave at instantiation, and therefore
    also the start values the modelDescription declares.
    """
    from pythonfmu.builder import FmuBuilder

    out = Path(out).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    if str(HERE) not in sys.path:  # the builder imports the slave, which imports fmu_src
        sys.path.insert(0, str(HERE))
    with tempfile.TemporaryDirectory(prefix="mpc_fmu_build_") as tmpd:
        staged = Path(tmpd) / f"{MODEL_IDENTIFIER}.fmu"
        project = [SRC_DIR]
        if start_values:
            sv = Path(tmpd) / "start_values.json"
            sv.write_text(json.dumps(check_start_values(start_values), indent=2) + "\n")
            project.append(sv)
        built = Path(FmuBuilder.build_FMU(SCRIPT, dest=staged, project_files=project))
        postprocess(built)
        names = zipfile.ZipFile(built).namelist()
        for required in ("resources/mpc_actuator.py", "resources/fmu_src/__init__.py",
                         "resources/fmu_src/model.py", "resources/fmu_src/params.py",
                         "resources/fmu_src/field.py", "resources/fmu_src/coil.py",
                         "resources/fmu_src/diaphragm.py", "resources/fmu_src/effects.py", "binaries/linux64/mpc_actuator.so"):
            if required not in names:
                raise SystemExit(f"build_fmu: {required} missing from the FMU")
        # move into place atomically (same filesystem: copy next to the target first)
        with _replacing(out) as tmp, open(built, "rb") as src, open(tmp, "wb") as dst:
            dst.write(src.read())
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(HERE / f"{MODEL_IDENTIFIER}.fmu"), help="FMU file to write")
    ap.add_argument("--start-values", help="JSON file {parameter: SI value} to bake in as start values")
    args = ap.parse_args(argv)
    sv = None
    if args.start_values:
        try:
            sv = json.loads(Path(args.start_values).read_text())
            sv = check_start_values(sv)
        except (OSError, ValueError) as e:
            raise SystemExit(f"build_fmu: --start-values {args.start_values}: {e}")
    path = build(args.out, start_values=sv)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
