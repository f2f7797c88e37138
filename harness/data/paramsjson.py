"""Parameter sets as JSON: the one encoder and decoder of the project, units in every key.

Every JSON file that carries model parameters stores them as an object
{key: SI value}, the key being the parameter's name (``fmu_src.specs.SPECS``,
``fmu_src.specs.EFFECT_SPECS``) and its unit joined by "_", the unit spelled as
a key can carry it ("N.m/T2" -> "N_m_per_T2", ``UNIT_SUFFIX``):

    "a_m", "D_m", "kB_T_per_A", "R_Ohm", "L_H", "Em_N_m_per_T2", "K1_N_per_m3",
    "K2_N_per_m", "C_N_s_per_m", "m_kg"                       (the paper's parameters)
    "Rth_K_per_W", "tau_th_s", "ksat_per_T2", "Kc_N_per_m", "tau_c_s",
    "K5_N_per_m5", "lam_1", "tau_s_s"                         (effects; 0 = off)
    "c_quad_drag_N_s2_per_m2", ..., "tau_P_s", ...           (the term set, fmu_src.terms; written when a
                                                              term is on; 0 = off)
    "r0_m", "blocked"                                         (per-test settings, optional)

Writers: rig.true_parameters of a synthetic manifest (``harness.data.rig``),
identification.json (the paper's parameters only), generalization.json,
extended_params.json (``harness.analysis.diagnose``), the cross-check references
(with "r0_m" and "blocked"). ``read_params_file`` reads the per-sample files:
{"samples": {id: {"parameters": {key: value}}}}, also without the "samples" or
"parameters" level.

Reading is strict: an unknown key, a key with another unit, a missing paper
parameter, a value that is not a number (or an object with a numeric "value")
or not finite, and a value the model refuses (``Params.validated``) raise
``ParamsJSONError`` naming the file (or the place given as ``source``) and the key.
"""
from __future__ import annotations

import difflib
import json
import math
from pathlib import Path

from fmu_src.specs import EFFECT_SPECS, SPECS, TERM_SPECS, Params

__all__ = ["ParamsJSONError", "UNIT_SUFFIX", "KEYS", "PAPER", "EFFECTS", "TERMS", "BLOCKED_KEY",
           "unit_key", "params_to_json", "params_from_json", "read_params_file"]


def _spelled(unit: str) -> str:
    """How a unit stands in a JSON key: "." -> "_", "/" -> "_per_" ("N.m/T2" -> "N_m_per_T2", "1/T2" -> "per_T2")."""
    num, slash, den = unit.replace("(", "").replace(")", "").partition("/")
    head = num.replace(".", "_")
    return ("" if num == "1" else head + "_") + "per_" + den.replace(".", "_") if slash else head


# unit (as in the specs / the modelDescription) -> how it stands in a JSON key
UNIT_SUFFIX = {u: _spelled(u) for u in dict.fromkeys([s.unit for s in SPECS + EFFECT_SPECS + TERM_SPECS] + ["1", "m2"])}
BLOCKED_KEY = "blocked"   # the blocked-mode flag (a bool, no unit) of the cross-check references


class ParamsJSONError(ValueError):
    """A parameter object or file that cannot be read; the message names the file (or place) and the key."""


def unit_key(name: str, unit: str) -> str:
    """The JSON key of a quantity: ``unit_key("Em", "N.m/T2") == "Em_N_m_per_T2"``."""
    try:
        return f"{name}_{UNIT_SUFFIX[unit]}"
    except KeyError:
        raise ValueError(f"{name}: no JSON key spelling for unit {unit!r} (known: {', '.join(UNIT_SUFFIX)})") from None


_SPECS = {s.name: s for s in SPECS + EFFECT_SPECS + TERM_SPECS}
KEYS = {name: unit_key(name, s.unit) for name, s in _SPECS.items()}   # parameter name -> key (r0 included)
_NAMES = {k: n for n, k in KEYS.items()}
PAPER = tuple(s.name for s in SPECS if s.name != "r0")   # what every parameter object must hold
EFFECTS = tuple(s.name for s in EFFECT_SPECS)
TERMS = tuple(s.name for s in TERM_SPECS)      # the generic term set (fmu_src.terms): c_<term>, tau_<lag>


def _number(x):
    x = float(x)
    return x if math.isfinite(x) else None   # JSON has no nan/inf: null


def params_to_json(p: Params, *, effects: bool = True, gap: bool = False) -> dict:
    """The parameters of p as {key: SI value} (non-finite values as None, i.e. null).

    The paper's parameters without the per-test gap r0, then (``effects``) every effect
    parameter and the term set's nonzero ones (``fmu_src.terms``, e.g. "c_quad_drag_N_s2_per_m2"), then
    (``gap``) "r0_m" and "blocked".
    """
    names = PAPER + (EFFECTS if effects else ())
    d = {KEYS[n]: _number(getattr(p, n)) for n in names}
    if effects:   # the generic term set (fmu_src.terms): only its parameters that are not 0 (files stay as they were)
        d.update({KEYS[s.name]: _number(getattr(p, s.name)) for s in TERM_SPECS if getattr(p, s.name) != 0.0})
    if gap:
        d[KEYS["r0"]] = _number(p.r0)
        d[BLOCKED_KEY] = bool(p.blocked)
    return d


def _where(source, key=None) -> str:
    parts = [str(source)] if source is not None else []
    if key is not None:
        parts.append(f"key {key!r}")
    return ": ".join(parts) + ": " if parts else ""


def _name_of(key: str, source) -> str:
    """The parameter a key stands for, or ParamsJSONError (unknown key, wrong or missing unit)."""
    if key in _NAMES:
        return _NAMES[key]
    stems = [n for n in KEYS if key == n or key.startswith(n + "_")]
    if stems:
        name = max(stems, key=len)
        unit = _SPECS[name].unit
        got = key[len(name) + 1:]
        what = f"wrong unit suffix {got!r}" if got else "no unit suffix"
        raise ParamsJSONError(f"{_where(source, key)}{what}: {name} is in {unit}, "
                              f"the key must be {KEYS[name]!r}")
    close = difflib.get_close_matches(key, list(_NAMES) + [BLOCKED_KEY], n=1)
    hint = f"did you mean {close[0]!r}?" if close else f"known keys: {', '.join(list(_NAMES) + [BLOCKED_KEY])}"
    raise ParamsJSONError(f"{_where(source, key)}unknown key; {hint}")


def _value(v, key: str, source) -> float:
    if isinstance(v, dict):      # {"value": number, "std": ..., ...}
        if "value" not in v:
            raise ParamsJSONError(f"{_where(source, key)}an object value needs a \"value\" entry, got {sorted(v)}")
        v = v["value"]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ParamsJSONError(f"{_where(source, key)}must be a number, got {json.dumps(v)}")
    try:
        x = float(v)
    except OverflowError:
        x = math.inf
    if not math.isfinite(x):
        raise ParamsJSONError(f"{_where(source, key)}must be finite, got {json.dumps(v)}")
    return x


def params_from_json(d: dict, source=None, *, required=PAPER) -> Params:
    """Params from {key: value} (the inverse of ``params_to_json``), checked and validated.

    ``source`` names where d came from (a file, "file: sample W20-D45") in every error.
    The parameters in ``required`` must be there (default: the paper's, without r0);
    the others keep their defaults (effects off, r0 at the default gap). A value is a
    number or an object with a numeric "value" (e.g. {"value": 0.05, "std": 0.001}).
    """
    if not isinstance(d, dict):
        raise ParamsJSONError(f"{_where(source)}expected an object of parameters, got {type(d).__name__}")
    kw = {}
    for key, v in d.items():
        if key == BLOCKED_KEY:
            if not isinstance(v, bool):
                raise ParamsJSONError(f"{_where(source, key)}must be true or false, got {json.dumps(v)}")
            kw["blocked"] = v
            continue
        kw[_name_of(key, source)] = _value(v, key, source)
    missing = [KEYS[n] for n in required if n not in kw]
    if missing:
        raise ParamsJSONError(f"{_where(source)}missing required key(s) {', '.join(map(repr, missing))}")
    try:
        return Params(**kw).validated()
    except ValueError as e:
        raise ParamsJSONError(f"{_where(source)}{e}") from None


def read_params_file(path) -> dict:
    """{sample id: Params} from a parameter file (identification.json, generalization.json,
    extended_params.json, or any {"samples": {id: {"parameters": {key: value}}}}; the
    "samples" and "parameters" levels may be left out). Errors name the file, sample and key."""
    try:
        data = json.loads(Path(path).read_text())
    except OSError as e:
        raise ParamsJSONError(f"{path}: cannot read: {e.strerror or e}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ParamsJSONError(f"{path}: not valid JSON: {e}") from None
    samples = data.get("samples", data) if isinstance(data, dict) else None
    if not isinstance(samples, dict) or not samples:
        raise ParamsJSONError(f"{path}: expected an object of samples")
    out = {}
    for sid, entry in samples.items():
        d = entry.get("parameters", entry) if isinstance(entry, dict) else None
        if not isinstance(d, dict):
            raise ParamsJSONError(f"{path}: sample {sid}: no parameters object")
        out[sid] = params_from_json(d, f"{path}: sample {sid}")
    return out
