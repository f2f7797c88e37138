"""harness.control.mpc: its predictions are the FMU model's (fmu_src.model.simulate on the same voltages,
same tolerance), and its settings are checked."""
from __future__ import annotations

import numpy as np
import pytest

from fmu_src.model import simulate
from fmu_src.specs import Params
from harness.control.mpc import Mpc, MpcSettings, rollouts


@pytest.mark.parametrize("effects", [{}, {"ksat": 3.0, "Rth": 8.0, "tau_th": 4.0}])
def test_rollouts_are_the_model(effects):
    p = Params().with_(**effects)
    mpc = Mpc(p, MpcSettings(rtol=1e-8))
    mpc.model.reset(0.0)
    S0, W0 = mpc.model.integ.S.copy(), mpc.model.integ.W.copy()
    rng = np.random.default_rng(0)
    V = rng.uniform(0, 25, size=(3, 12))
    X = np.empty_like(V)
    assert rollouts(S0, W0, mpc.model.integ.coef, 0.0, 0.01, V, X) == 0
    t = np.arange(13) * 0.01
    for c in range(3):
        ref = simulate(p, t, np.append(V[c], 0.0), rtol=1e-8)["x"][1:]
        assert X[c] == pytest.approx(ref, abs=1e-12)


def test_mpc_first_move_toward_a_setpoint():
    p = Params()
    mpc = Mpc(p)
    V = mpc.command(0.0, np.full(mpc.s.horizon, 1e-3), (0.0, 0.0, 0.0))
    assert mpc.s.V_min_V <= V <= mpc.s.V_max_V and V > mpc.feedforward(1e-3)   # pushes harder than the hold
    assert mpc.last_predicted[-1] == pytest.approx(1e-3, abs=0.1e-3)


@pytest.mark.parametrize("kw, msg", [({"dt_s": 0.0}, "dt_s"), ({"blocks": (1, 0)}, "blocks"),
                                     ({"V_max_V": -1.0}, "V_max_V"), ({"margin_m": -1e-3}, "margin_m")])
def test_settings_are_checked(kw, msg):
    with pytest.raises(ValueError, match=msg):
        MpcSettings(**kw)
