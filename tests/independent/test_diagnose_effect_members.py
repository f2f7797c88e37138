"""The blind diagnosis on the effect members of the independent matrix (``tests/independent/generator.py``).

Done criteria of the issue "Measured data from any rig" (diagnosis side): on every effect member, including
forms outside the catalogue (two-time-constant heating, two-branch creep, tanh and Langevin saturation),
the verdict names the cause whose form the hidden effect has (``coil_heating`` for any heating,
``viscoelastic_creep`` for any creep, ``filler_saturation`` for any saturation law), possibly with an
"unexplained remainder" for the part of another form; and the held-out RMSE falls by at least half
whenever the paper model's is at least three noise floors. The data come from independent physics
(``tests/independent/physics.py``: its own equations and ``scipy.integrate.solve_ivp``), never the
project's simulator.

Each member is a whole eleven-sample dataset and a whole diagnosis (minutes): marked ``slow``
(deselected by default; ``pytest -m slow tests/independent/test_diagnose_effect_members.py``).
"""
from __future__ import annotations

import pytest

from harness.analysis import diagnosis as dg
from harness.data.dataset import read_dataset
from tests.independent.bounds import blind
from tests.independent.generator import MATRIX, make_member

#: which catalogue cause each hidden form must be named as
EXPECTED = {"coil_heating": "coil_heating", "coil_heating_2tau": "coil_heating",
            "viscoelastic_creep": "viscoelastic_creep", "creep_2tau": "viscoelastic_creep",
            "filler_saturation": "filler_saturation", "saturation_tanh": "filler_saturation",
            "saturation_langevin": "filler_saturation", "edge_stiffening": "edge_stiffening",
            "motional_emf": "motional_emf", "sensor_lag": "sensor_lag"}
EFFECT_MEMBERS = [name for name, m in MATRIX.items() if m.effects]


def test_every_effect_form_has_an_expected_cause():
    assert {e for n in EFFECT_MEMBERS for e in MATRIX[n].effects} <= set(EXPECTED)
    assert set(EXPECTED.values()) <= set(dg.CANDIDATES)


@pytest.mark.slow
@pytest.mark.parametrize("name", EFFECT_MEMBERS)
def test_effect_member_is_named_and_the_gain_is_at_least_half(name, tmp_path):
    ds = blind(read_dataset(make_member(name, tmp_path / name)))
    diag = dg.diagnose(ds)
    (form,) = MATRIX[name].effects
    ov = diag.gain["overall_normalized_rmse"]
    msg = (f"{name}: verdict {diag.verdict!r}, held-out RMSE {ov}, remainder "
           f"{diag.remainder.get('where')}, candidates "
           f"{ {n: (c['accepted'], c['reason']) for n, c in diag.candidates.items()} }")
    assert diag.cause == EXPECTED[form], msg
    assert diag.verdict.startswith(EXPECTED[form]), msg
    if ov["before"] >= 3.0:
        assert ov["after"] <= 0.5 * ov["before"], msg
