"""harness.data.paramsjson: the one encoder/decoder of parameter JSON (units in every key).

Round trip of every parameter (effects included), files in the layouts the code wrote
before the module existed (literal text), and errors that name the file and the key.
"""
import json
import math
import re

import pytest

from fmu_src.specs import EFFECT_SPECS, SPECS, Params
from harness.data import paramsjson as pj
from harness.cli import load_params_file

# The keys as they stand in the files (fixed on purpose: renaming one breaks existing files).
PAPER_KEYS = ["a_m", "D_m", "kB_T_per_A", "R_Ohm", "L_H", "Em_N_m_per_T2", "K1_N_per_m3", "K2_N_per_m",
              "C_N_s_per_m", "m_kg"]
EFFECT_KEYS = ["Rth_K_per_W", "tau_th_s", "ksat_per_T2", "Kc_N_per_m", "tau_c_s", "K5_N_per_m5", "lam_1",
               "tau_s_s"]

# Every parameter away from its default (effects on, the rules between them kept).
ALL_ON = Params(a=0.016, r0=0.004, D=0.06, kB=0.3, R=14.5, L=0.11, Em=0.05, K1=3.1e5, K2=41.0, C=0.45, m=0.0045,
                blocked=True, Rth=8.5, tau_th=4.5, ksat=3.5, Kc=12.0, tau_c=0.8, K5=1.5e9, lam=0.06, tau_s=0.004)


def _write(tmp_path, text, name="params.json"):
    f = tmp_path / name
    f.write_text(text)
    return f


# ------------------------------------------------------------------------ keys, round trip
def test_keys_derive_from_the_specs():
    assert [pj.KEYS[n] for n in pj.PAPER] == PAPER_KEYS
    assert [pj.KEYS[n] for n in pj.EFFECTS] == EFFECT_KEYS
    assert pj.KEYS["r0"] == "r0_m"
    for s in SPECS + EFFECT_SPECS:
        assert pj.KEYS[s.name] == pj.unit_key(s.name, s.unit) == f"{s.name}_{pj.UNIT_SUFFIX[s.unit]}"
    # the units diagnose writes for its shared effect parameters
    assert pj.unit_key("creep_ratio", "1") == "creep_ratio_1" and pj.unit_key("Rth", "K/W") == "Rth_K_per_W"
    with pytest.raises(ValueError, match="'furlong'"):
        pj.unit_key("x", "furlong")


def test_encoder_layout():
    d = pj.params_to_json(ALL_ON)
    assert list(d) == PAPER_KEYS + EFFECT_KEYS
    assert d["Em_N_m_per_T2"] == 0.05 and d["tau_s_s"] == 0.004
    assert list(pj.params_to_json(ALL_ON, effects=False)) == PAPER_KEYS
    assert list(pj.params_to_json(ALL_ON, gap=True)) == PAPER_KEYS + EFFECT_KEYS + ["r0_m", "blocked"]
    # JSON has no nan: non-finite values are written as null (and refused when read, see below)
    assert pj.params_to_json(Params(R=math.nan))["R_Ohm"] is None
    json.dumps(pj.params_to_json(Params(R=math.inf)), allow_nan=False)


def test_round_trip_of_every_parameter():
    text = json.dumps(pj.params_to_json(ALL_ON, gap=True), allow_nan=False)
    back = pj.params_from_json(json.loads(text), "mem")
    assert back == ALL_ON
    for f in ALL_ON.as_dict():
        assert getattr(back, f) == getattr(ALL_ON, f), f
    # without the per-test settings: everything but r0 and blocked comes back, those take their defaults
    back = pj.params_from_json(json.loads(json.dumps(pj.params_to_json(ALL_ON))))
    assert back == ALL_ON.with_(r0=Params().r0, blocked=False)
    # the paper's parameters alone: effects off
    back = pj.params_from_json(pj.params_to_json(ALL_ON, effects=False))
    assert back == Params(**{n: getattr(ALL_ON, n) for n in pj.PAPER})


def test_round_trip_through_a_file(tmp_path):
    data = {"samples": {"W20-D45": {"parameters": pj.params_to_json(ALL_ON)},
                        "W10-D30": {"parameters": pj.params_to_json(Params())}}}
    f = _write(tmp_path, json.dumps(data, indent=2))
    got = pj.read_params_file(f)
    assert list(got) == ["W20-D45", "W10-D30"]
    assert got["W20-D45"] == ALL_ON.with_(r0=Params().r0, blocked=False) and got["W10-D30"] == Params()
    assert load_params_file(f) == got


# ------------------------------------------------------------------------ old files
# rig.true_parameters of a manifest, as harness.data.rig.params_to_json wrote it (W20-D45, filler_saturation 1)
OLD_RIG_TRUE_PARAMETERS = """{"W20-D45": {"a_m": 0.015, "D_m": 0.045, "kB_T_per_A": 0.29, "R_Ohm": 15.0,
"L_H": 0.12, "Em_N_m_per_T2": 0.04228422200399211, "K1_N_per_m3": 1453827.1604938267, "K2_N_per_m": 52.0,
"C_N_s_per_m": 0.5608921464952065, "m_kg": 0.005, "Rth_K_per_W": 0.0, "tau_th_s": 0.0, "ksat_per_T2": 3.0,
"Kc_N_per_m": 0.0, "tau_c_s": 0.0, "K5_N_per_m5": 0.0, "lam_1": 0.0, "tau_s_s": 0.0}}"""

# identification.json as harness.analysis.identification.identify.sample_to_json wrote it (trimmed: one front row)
OLD_IDENTIFICATION = """{
  "format": "mpc-actuator-identification/1",
  "synthetic": true,
  "samples": {
    "W10-D30": {
      "wt_pct": 10.0,
      "diameter_mm": 30.0,
      "parameters": {
        "a_m": 0.015,
        "D_m": 0.03,
        "kB_T_per_A": 0.29,
        "R_Ohm": 15.012,
        "L_H": 0.1199,
        "Em_N_m_per_T2": 0.01002,
        "K1_N_per_m3": 6398000.0,
        "K2_N_per_m": 60.1,
        "C_N_s_per_m": 0.359,
        "m_kg": 0.00178
      },
      "parameter_std": {"R_Ohm_std": 0.002, "L_H_std": 0.0001, "Em_N_m_per_T2_std": null},
      "steady_state": {"T3_x_mm": 0.31},
      "pareto_front": [{"C_N_s_per_m": 0.359, "m_kg": 0.00178, "T3_ste_s": 0.001, "T3_rmse_mm": 0.002,
                        "T5_ste_s": 0.003, "T5_rmse_mm": 0.004, "J": 0.0}],
      "chosen_index": 0,
      "evaluations": 400
    }
  }
}
"""

# generalization.json as harness.analysis.identification.generalize.write_generalization wrote it (surfaces trimmed)
OLD_GENERALIZATION = """{
  "format": "mpc-actuator-generalization/1",
  "surfaces": {"nodes": [{"sample": "W10-D30", "wt_pct": 10.0, "diameter_mm": 30.0, "Em_N_m_per_T2": 0.01}]},
  "samples": {
    "W15-D45": {
      "parameters": {
        "a_m": 0.015,
        "D_m": 0.045,
        "kB_T_per_A": 0.29,
        "R_Ohm": 15.0,
        "L_H": 0.12,
        "Em_N_m_per_T2": 0.0285,
        "K1_N_per_m3": 1358000.0,
        "K2_N_per_m": 46.0,
        "C_N_s_per_m": 0.5,
        "m_kg": 0.0045
      }
    }
  },
  "skipped": {}
}
"""

# extended_params.json as harness.analysis.diagnose.extended_params_json wrote it
OLD_EXTENDED = """{
  "format": "mpc-actuator-params/1",
  "synthetic": true,
  "source": "harness.analysis.diagnose",
  "cause": "coil_heating",
  "effects": ["coil_heating"],
  "shared_effect_parameters": {"Rth_K_per_W": {"value": 7.98, "std": 0.05}, "tau_th_s": {"value": 3.99, "std": 0.02}},
  "samples": {
    "W20-D45": {
      "wt_pct": 20.0, "diameter_mm": 45.0, "role": "training",
      "parameters": {"a_m": 0.015, "D_m": 0.045, "kB_T_per_A": 0.29, "R_Ohm": 15.0, "L_H": 0.12,
                     "Em_N_m_per_T2": 0.0423, "K1_N_per_m3": 1453827.0, "K2_N_per_m": 52.0,
                     "C_N_s_per_m": 0.56, "m_kg": 0.005, "Rth_K_per_W": 7.98, "tau_th_s": 3.99,
                     "ksat_per_T2": 0.0, "Kc_N_per_m": 0.0, "tau_c_s": 0.0, "K5_N_per_m5": 0.0,
                     "lam_1": 0.0, "tau_s_s": 0.0}
    }
  },
  "shared_effect_parameter_std": {"Rth_K_per_W": 0.05, "tau_th_s": 0.02}
}
"""

# a cross-check reference (references/<sample>/<test>_params.json), with the gap and blocked mode
OLD_REFERENCE = """{
  "a_m": 0.015,
  "D_m": 0.045,
  "kB_T_per_A": 0.29,
  "R_Ohm": 15.0,
  "L_H": 0.12,
  "Em_N_m_per_T2": 0.04228422200399211,
  "K1_N_per_m3": 1453827.1604938267,
  "K2_N_per_m": 52.0,
  "C_N_s_per_m": 0.5608921464952065,
  "m_kg": 0.005,
  "Rth_K_per_W": 0.0,
  "tau_th_s": 0.0,
  "ksat_per_T2": 0.0,
  "Kc_N_per_m": 0.0,
  "tau_c_s": 0.0,
  "K5_N_per_m5": 0.0,
  "lam_1": 0.0,
  "tau_s_s": 0.0,
  "r0_m": 0.002,
  "blocked": true
}
"""


def test_reads_old_rig_true_parameters():
    tp = json.loads(OLD_RIG_TRUE_PARAMETERS)
    p = pj.params_from_json(tp["W20-D45"], "manifest.json")
    assert p == Params(D=0.045, Em=0.04228422200399211, K1=1453827.1604938267, K2=52.0, C=0.5608921464952065,
                       m=0.005, ksat=3.0)
    from harness.data import rig   # the old entry point still reads it
    assert rig.params_from_json(tp["W20-D45"]) == p
    assert json.dumps(rig.params_to_json(p)) == json.dumps(tp["W20-D45"])   # and writes it byte for byte


def test_reads_old_identification_file(tmp_path):
    got = pj.read_params_file(_write(tmp_path, OLD_IDENTIFICATION, "identification.json"))
    assert got == {"W10-D30": Params(D=0.03, R=15.012, L=0.1199, Em=0.01002, K1=6398000.0, K2=60.1, C=0.359,
                                     m=0.00178)}


def test_reads_old_generalization_file(tmp_path):
    got = load_params_file(_write(tmp_path, OLD_GENERALIZATION, "generalization.json"))
    assert got == {"W15-D45": Params(Em=0.0285, K1=1358000.0, K2=46.0, C=0.5, m=0.0045)}


def test_reads_old_extended_params_file(tmp_path):
    got = load_params_file(_write(tmp_path, OLD_EXTENDED, "extended_params.json"))
    assert got == {"W20-D45": Params(Em=0.0423, K1=1453827.0, K2=52.0, C=0.56, m=0.005, Rth=7.98, tau_th=3.99)}


def test_reads_old_reference_file_and_value_objects(tmp_path):
    p = pj.params_from_json(json.loads(OLD_REFERENCE), "T8_params.json", required=pj.PAPER + ("r0",))
    assert p.r0 == 0.002 and p.blocked is True and p.K2 == 52.0
    assert json.dumps(pj.params_to_json(p, gap=True), indent=2) + "\n" == OLD_REFERENCE
    # values may be {"value": number, ...} (as the CLI has always accepted)
    d = dict(json.loads(OLD_REFERENCE), Em_N_m_per_T2={"value": 0.05, "std": 0.001})
    assert pj.params_from_json(d).Em == 0.05


def test_old_files_without_the_samples_or_parameters_level(tmp_path):
    entry = json.loads(OLD_RIG_TRUE_PARAMETERS)
    assert pj.read_params_file(_write(tmp_path, json.dumps(entry)))["W20-D45"].ksat == 3.0
    wrapped = {"W20-D45": {"parameters": entry["W20-D45"]}}
    assert pj.read_params_file(_write(tmp_path, json.dumps(wrapped)))["W20-D45"].ksat == 3.0


# ------------------------------------------------------------------------ bad input
def _file_with(tmp_path, **changes):
    """identification.json in the old layout with the parameters of W10-D30 changed (None: key removed)."""
    data = json.loads(OLD_IDENTIFICATION)
    par = data["samples"]["W10-D30"]["parameters"]
    for k, v in changes.items():
        if v is None:
            par.pop(k)
        else:
            par[k] = v
    return _write(tmp_path, json.dumps(data), "identification.json")


def _raw_file(tmp_path, key, raw):
    """The same file with one value written as raw JSON text (NaN, Infinity, null, ...)."""
    data = json.loads(OLD_IDENTIFICATION)
    data["samples"]["W10-D30"]["parameters"][key] = "@@"
    return _write(tmp_path, json.dumps(data).replace('"@@"', raw), "identification.json")


BAD = [
    # (how to break the file, key named, what the message says)
    (lambda tp: _file_with(tp, Em_N_per_T2=0.01), "Em_N_per_T2", r"wrong unit suffix 'N_per_T2': Em is in N\.m/T2, "
                                                                 r"the key must be 'Em_N_m_per_T2'"),
    (lambda tp: _file_with(tp, R_kOhm=0.015, R_Ohm=None), "R_kOhm", r"wrong unit suffix 'kOhm'.*'R_Ohm'"),
    (lambda tp: _file_with(tp, L=0.12, L_H=None), "L", r"no unit suffix: L is in H, the key must be 'L_H'"),
    (lambda tp: _file_with(tp, Emm_N_m_per_T2=0.01), "Emm_N_m_per_T2", r"unknown key; did you mean 'Em_N_m_per_T2'"),
    (lambda tp: _file_with(tp, colour_nm=550.0), "colour_nm",
     r"unknown key; known keys: a_m, r0_m, D_m, .*, tau_s_s, c_quad_drag_N_s2_per_m2, .*, blocked$"),
    (lambda tp: _file_with(tp, K2_N_per_m="60.1"), "K2_N_per_m", r"must be a number, got \"60\.1\""),
    (lambda tp: _file_with(tp, K2_N_per_m=True), "K2_N_per_m", r"must be a number, got true"),
    (lambda tp: _file_with(tp, K2_N_per_m=[60.1]), "K2_N_per_m", r"must be a number, got \[60\.1\]"),
    (lambda tp: _raw_file(tp, "K2_N_per_m", "null"), "K2_N_per_m", r"must be a number, got null"),
    (lambda tp: _file_with(tp, K2_N_per_m={"std": 1.0}), "K2_N_per_m", r"needs a \"value\" entry"),
    (lambda tp: _raw_file(tp, "m_kg", "NaN"), "m_kg", r"must be finite, got NaN"),
    (lambda tp: _raw_file(tp, "m_kg", "-Infinity"), "m_kg", r"must be finite, got -Infinity"),
    (lambda tp: _raw_file(tp, "m_kg", "1e999"), "m_kg", r"must be finite"),
    (lambda tp: _raw_file(tp, "m_kg", "1" + "0" * 400), "m_kg", r"must be finite"),
    (lambda tp: _file_with(tp, blocked="yes"), "blocked", r"must be true or false, got \"yes\""),
]


@pytest.mark.parametrize("make,key,what", BAD, ids=[f"{i}-{b[1]}" for i, b in enumerate(BAD)])
def test_bad_value_or_key_names_file_sample_and_key(tmp_path, make, key, what):
    f = make(tmp_path)
    with pytest.raises(pj.ParamsJSONError) as ei:
        pj.read_params_file(f)
    msg = str(ei.value)
    assert msg.startswith(f"{f}: sample W10-D30: key {key!r}: "), msg
    assert isinstance(ei.value, ValueError)
    assert re.search(what, msg), msg
    # the CLI says the same, after "--params"
    with pytest.raises(SystemExit, match=re.escape(f"error: --params {f}: sample W10-D30: key {key!r}: ")):
        load_params_file(f)


def test_missing_required_keys_are_all_named(tmp_path):
    f = _file_with(tmp_path, R_Ohm=None, m_kg=None)
    with pytest.raises(pj.ParamsJSONError) as ei:
        pj.read_params_file(f)
    assert str(ei.value) == f"{f}: sample W10-D30: missing required key(s) 'R_Ohm', 'm_kg'"
    # r0 is only required where asked for (the cross-check references)
    d = json.loads(OLD_REFERENCE)
    del d["r0_m"]
    assert pj.params_from_json(d).r0 == Params().r0
    with pytest.raises(pj.ParamsJSONError, match=r"^T2_params\.json: missing required key\(s\) 'r0_m'$"):
        pj.params_from_json(d, "T2_params.json", required=pj.PAPER + ("r0",))


def test_values_the_model_refuses_name_file_and_parameter(tmp_path):
    f = _file_with(tmp_path, m_kg=-1.0)
    with pytest.raises(pj.ParamsJSONError, match=r"sample W10-D30: parameter m \[kg\] must be > 0, got -1\.0$") as ei:
        pj.read_params_file(f)
    assert str(ei.value).startswith(str(f))
    f = _file_with(tmp_path, Rth_K_per_W=8.0)          # heating on without its time constant
    with pytest.raises(pj.ParamsJSONError, match=r"sample W10-D30: parameter tau_th \[s\] must be > 0 when Rth"):
        pj.read_params_file(f)


@pytest.mark.parametrize("text,what", [
    ("{not json", r"not valid JSON: Expecting property name"),
    ("[1, 2]", r"expected an object of samples"),
    ("{}", r"expected an object of samples"),
    ('{"samples": {"W10-D30": 3}}', r"sample W10-D30: no parameters object"),
    ('{"samples": {"W10-D30": {"parameters": [1]}}}', r"sample W10-D30: no parameters object"),
])
def test_bad_file_layout_names_the_file(tmp_path, text, what):
    f = _write(tmp_path, text)
    with pytest.raises(pj.ParamsJSONError, match=f"^{re.escape(str(f))}: {what}"):
        pj.read_params_file(f)


def test_unreadable_file_is_named(tmp_path):
    with pytest.raises(pj.ParamsJSONError, match=r"nope\.json: cannot read: No such file"):
        pj.read_params_file(tmp_path / "nope.json")


def test_decoder_without_a_file():
    with pytest.raises(pj.ParamsJSONError, match=r"^key 'R_ohm': wrong unit suffix 'ohm'"):
        pj.params_from_json({**pj.params_to_json(Params()), "R_ohm": 1.0})
    with pytest.raises(pj.ParamsJSONError, match=r"^expected an object of parameters, got list"):
        pj.params_from_json([1.0])


def test_term_parameters_round_trip_when_a_term_is_on():
    """The generic term set (fmu_src.terms; a term the diagnosis discovered): its nonzero parameters written with
    unit keys, read back exactly (the others read as 0); a parameter set without terms keeps the layout without them."""
    from fmu_src.specs import Params
    p = Params()
    assert not any(k.startswith("c_") for k in pj.params_to_json(p))
    q = p.with_(c_quad_drag=0.25, c_heat_softening=-3.5e-3, tau_P=4.0)
    d = pj.params_to_json(q)
    assert d["c_quad_drag_N_s2_per_m2"] == 0.25 and d["c_heat_softening_N_per_m_W"] == -3.5e-3
    assert d["tau_P_s"] == 4.0 and "c_x_quadratic_per_m" not in d       # only the term set's nonzero values
    back = pj.params_from_json(d)
    assert (back.c_quad_drag, back.c_heat_softening, back.tau_P) == (0.25, -3.5e-3, 4.0)
