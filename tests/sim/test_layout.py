"""The vectorized simulator's layouts come from fmu_src.specs: adding an effect (README, "Adding an effect")
needs no edit in harness.sim. Checked on the real catalogue and on a catalogue with one more effect."""
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

from fmu_src.specs import ALL_SPECS, BASE_STATES, BLOCK, EFFECTS
from fmu_src.terms import LAG_STATES
from harness.data import rig
from harness.sim import core, physics
from harness.sim.simulator import PARAM_FIELDS, Runs

ROOT = Path(__file__).resolve().parents[2]


def _runs(cases):
    n = len(cases)
    return Runs(params={k: np.array([getattr(p, k) for p in cases], dtype=float) for k in PARAM_FIELDS},
                blocked=np.zeros(n, dtype=bool), V=np.full(n, 5.0), dt=1e-3)


def test_layouts_follow_the_catalogue():
    """Every effect state is in the core's RK4 state (in catalogue order) or, for the effect the core solves
    exactly (the sensor lag), nowhere in it; every parameter, switch and state of fmu_src.specs.BLOCK gets
    its entry in the core's parameter block; a run with an effect that has states on is never frozen."""
    lag = core.EXACT_EFFECT
    assert lag in EFFECTS
    want = list(BASE_STATES) + [s for name, e in EFFECTS.items() if name != lag for s in e.states]
    assert list(core.Y_STATES) == want + list(LAG_STATES) and core.NY_EFFECTS == len(want)   # then the term set's
    assert list(core.STATE_COLUMNS[:len(want)]) == want and len(set(core.STATE_COLUMNS)) == len(core.STATE_COLUMNS)
    assert list(PARAM_FIELDS) == [s.name for s in ALL_SPECS]
    assert list(physics.FLAG_NAMES) == [e.switch for e in EFFECTS.values()]
    base = rig.true_params(20, 45)
    everything = base.with_(Rth=8.0, tau_th=4.0, ksat=3.0, Kc=8.0, tau_c=1.0, K5=1e7, lam=0.3, tau_s=0.005)
    c = physics.constants(_runs([base, everything]))
    P = physics.param_blocks(c)
    for name, i in BLOCK.param.items():
        if not any(name in physics.TIME_CONSTANTS[e] for e in physics.SLOW_EFFECTS):
            assert P[1, i] == getattr(everything, name), name
    for name, i in BLOCK.switch.items():
        assert P[0, i] == 0.0
        assert P[1, i] == (0.0 if name == lag else 1.0), name
    for name, i in BLOCK.state.items():
        pos = core.Y_STATES.index(name) if name in core.Y_STATES else -1
        assert P[1, i] == physics.STATE_POSITION[name] == pos, name
    slow = [name for name, e in EFFECTS.items() if any(s in core.Y_STATES for s in e.states)]
    assert list(physics.SLOW_EFFECTS) == slow and slow
    assert list(c["slow"]) == [False, True]
    # the term set off in both: its switch 0 and the runs integrate only the effects' states
    assert list(P[:, BLOCK.terms]) == [0.0, 0.0] and list(P[:, core.C_NY]) == [core.NY_EFFECTS] * 2


def test_term_set_layout():
    """The term set's switch, lag switches and lag-state positions in the core's parameter block: on only in
    the run with a term on, the lag switch only for the lag its term uses, the lag states at their places in
    y (after the effects' states), the run integrating them and never frozen (a lag state is slow)."""
    base = rig.true_params(20, 45)
    on = base.with_(c_force_lag=0.2, tau_F=0.01, c_quad_drag=1.0)
    c = physics.constants(_runs([base, on]))
    P = physics.param_blocks(c)
    assert list(P[:, BLOCK.terms]) == [0.0, 1.0]
    assert {g: list(P[:, i]) for g, i in BLOCK.lag_on.items()} == {
        "P": [0.0, 0.0], "F": [0.0, 1.0], "I": [0.0, 0.0], "Fs": [0.0, 0.0], "dahl": [0.0, 0.0]}
    for z, i in BLOCK.lag_state.items():
        assert P[1, i] == core.Y_STATES.index(z) >= core.NY_EFFECTS
    assert list(P[:, core.C_NY]) == [core.NY_EFFECTS, core.NY]
    assert list(c["slow"]) == [False, True]
    # a term without a lag is not slow
    assert list(physics.constants(_runs([on.with_(c_force_lag=0.0)]))["slow"]) == [False]


_NEW_EFFECT = '''
    EffectSpec(
        "test_relaxation",
        (_effect_param("kz", "1/s", "test_relaxation: switch (0 = off)"),
         _effect_param("tau_z", "s", "test_relaxation: time constant")),
        (StateSpec("z", "m", "a relaxing state without equations"),),
        "a test effect", "nowhere", rig_magnitude_1=lambda p: {"kz": 1.0, "tau_z": 0.02}, rig_fixed=("tau_z",),
        positive_when_on=("tau_z",)),
)}
'''

_SCRIPT = '''
import sys, types
import numpy as np
import fmu_src
src = open(sys.argv[1]).read()
head, sep, tail = src.partition("\\n)}\\n\\nEFFECT_SPECS")
assert sep, "catalogue end not found"
mod = types.ModuleType("fmu_src.specs")
mod.__file__ = sys.argv[1]
sys.modules["fmu_src.specs"] = mod
exec(compile(head + __NEW_EFFECT__ + "\\nEFFECT_SPECS" + tail, sys.argv[1], "exec"), mod.__dict__)
fmu_src.specs = mod
from harness.sim import core, physics
from harness.sim.simulator import PARAM_FIELDS, Runs, simulate
from harness.data import rig
assert core.Y_STATES[core.NY_EFFECTS - 1] == "z", core.Y_STATES
assert physics.STATE_POSITION["z"] == core.NY_EFFECTS - 1
assert "kz" in PARAM_FIELDS and "tau_z" in physics.TIME_CONSTANTS["test_relaxation"]
assert "test_relaxation" in physics.SLOW_EFFECTS
base = rig.true_params(20, 45)
cases = [base, base.with_(kz=1.0, tau_z=0.02)]
runs = Runs(params={k: np.array([getattr(p, k) for p in cases], dtype=float) for k in PARAM_FIELDS},
            blocked=np.zeros(2, dtype=bool), V=np.full(2, 5.0), dt=1e-3)
c = physics.constants(runs)
assert list(c["slow"]) == [False, True]
assert physics.substeps(c, 1e-3)[1] >= 1e-3 / 0.02 / 0.3      # the state's time constant bounds the step
P = physics.param_blocks(c)
assert P[1, mod.BLOCK.state["z"]] == core.NY_EFFECTS - 1 and P[0, mod.BLOCK.switch["test_relaxation"]] == 0
from harness.sim.settings import Schedule
res = simulate(runs, Schedule(t_end=0.05, fine_s=0.05))
# no equations for it in fmu_src.effects: its state keeps rate 0 and the rest of the model is unchanged
assert np.array_equal(res.x[0], res.x[1]) and np.array_equal(res.I[0], res.I[1]) and res.x[0, -1] > 0
print("ok", core.Y_STATES)
'''


def test_a_new_effect_state_needs_no_edit_in_harness_sim():
    """A catalogue with one more effect (a state z with a time constant; fmu_src/specs.py with one more
    EffectSpec, in a fresh interpreter with numba's JIT off so that no compiled cache is touched): the
    simulator integrates z as a state of y, maps it into the parameter block, bounds the step by its time
    constant, never freezes a run with it on, and runs."""
    script = _SCRIPT.replace("__NEW_EFFECT__", repr(textwrap.dedent(_NEW_EFFECT)))
    env = dict(os.environ, NUMBA_DISABLE_JIT="1", PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-c", script, str(ROOT / "fmu_src" / "specs.py")], env=env, cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.startswith("ok ('I', 'x', 'v', 'dT', 'xc', 'z', 'z_P'"), proc.stdout
