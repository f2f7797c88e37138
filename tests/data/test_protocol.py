"""The test protocol (paper Table 2) against hand-computed cases."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from harness.data import protocol as P


# ---------------------------------------------------------------- Table 2
def test_table2_kinds_fields_and_columns():
    assert list(P.TESTS) == ["T1", "T2", "T3", "T4", "T5", "T6", "T7", "T8"]
    assert P.SWEEP_TESTS == ("T1", "T7")
    assert P.TIME_SERIES_TESTS == ("T2", "T3", "T4", "T5", "T6", "T8")
    assert P.BLOCKED_TESTS == ("T7", "T8")
    assert P.FIELDS_T == {"T1": 0.23, "T2": 0.06, "T3": 0.11, "T4": 0.16, "T5": 0.23, "T6": 0.23,
                          "T7": 0.23, "T8": 0.23}
    assert [P.TESTS[n].drive for n in P.TESTS] == ["sweep", "step", "step", "step", "step", "sine", "sweep", "step"]
    assert P.TESTS["T1"].columns == ("gap_mm", "current_A", "displacement_mm")
    assert P.TESTS["T7"].columns == ("gap_mm", "current_A", "force_N")
    assert P.TESTS["T8"].columns == ("time_s", "voltage_V", "current_A", "force_N")
    assert P.TESTS["T4"].columns == ("time_s", "voltage_V", "current_A", "displacement_mm")
    assert P.TESTS["T6"].frequency_hz == 1.0 and P.TESTS["T5"].frequency_hz is None
    assert P.TESTS["T8"].measured == "force_N" and P.TESTS["T2"].measured == "displacement_mm"
    assert P.TESTS["T1"].is_sweep and P.TESTS["T6"].is_time_series
    assert P.IDENTIFICATION_TESTS == ("T3", "T5", "T8")


def test_gap_rules():
    # gap of maximum T1 displacement: 4 mm (first of equal maxima)
    g = P.max_displacement_gap_mm([6.0, 5.0, 4.0, 3.0, 2.0], [1.0, 2.0, 3.5, 3.5, 0.5])
    assert g == 4.0
    assert [P.planned_gap_mm(n, g) for n in ("T2", "T3", "T4", "T5")] == [6.0] * 4
    assert P.planned_gap_mm("T6", g) == 7.0
    assert P.planned_gap_mm("T8", g) == 2.0 and P.planned_gap_mm("T8") == 2.0
    assert P.TESTS["T6"].gap_rule == P.GapRule(offset_mm=3.0) and P.TESTS["T8"].gap_rule == P.GapRule(fixed_mm=2.0)
    for bad in ("T1", "T7", "T9"):
        with pytest.raises(P.ProtocolError):
            P.planned_gap_mm(bad, g)
    with pytest.raises(P.ProtocolError):
        P.planned_gap_mm("T5")            # needs the T1 gap
    with pytest.raises(P.ProtocolError):
        P.GapRule(offset_mm=2.0, fixed_mm=2.0)
    with pytest.raises(P.ProtocolError):
        P.max_displacement_gap_mm([1.0, 2.0], [1.0])


# ---------------------------------------------------------------- timing
def test_sweep_timing_constants_and_manifest_override():
    assert (P.SWEEP_HOLD_S, P.SWEEP_AVERAGE_S, P.SAMPLE_PERIOD_S) == (1.5, 0.3, 1e-3)
    assert P.SWEEP_GAPS_MM[0] == 25 and P.SWEEP_GAPS_MM[-1] == 0 and len(P.SWEEP_GAPS_MM) == 26
    assert P.sweep_timing(None) == P.SweepTiming(1.5, 0.3, 1e-3)
    assert P.sweep_timing({}) == P.SweepTiming(1.5, 0.3, 1e-3)
    timing = P.sweep_timing({"sweep_hold_s": 2, "sweep_average_s": 0.5, "sample_period_s": 0.002})
    assert (timing.hold_s, timing.average_s, timing.sample_period_s) == (2.0, 0.5, 0.002)
    assert (timing.hold_source, timing.average_source, timing.sample_period_source) == ("manifest",) * 3
    assert timing.readings_averaged == 250.0 and P.sweep_timing({}).readings_averaged is None
    assert P.sweep_timing(SimpleNamespace(rig={"sweep_hold_s": 3.0})).hold_s == 3.0
    # no sample period in the manifest: the median period of the dataset's time series
    rec = SimpleNamespace(time_s=12.0 + np.arange(50) * 0.004, voltage_V=np.zeros(50))
    ds = SimpleNamespace(rig={}, samples=[SimpleNamespace(tests={"T5": rec})])
    timing = P.sweep_timing(ds)
    assert timing.sample_period_s == pytest.approx(0.004, rel=1e-9) and timing.sample_period_source == "data"


def test_time_grid_and_sweep_average_window():
    t = P.time_grid(1.5)
    assert t.size == 1501 and t[0] == 0.0 and t[-1] == pytest.approx(1.5, abs=1e-12)
    m = P.sweep_average_mask(t, 0.3)
    assert int(m.sum()) == 300                      # 1.201 .. 1.500 s at 1 ms
    assert t[m][0] == pytest.approx(1.201, abs=1e-12) and m[-1]
    t2 = P.time_grid(1.0, 0.25)                     # 0, .25, .5, .75, 1
    assert np.allclose(t2, [0.0, 0.25, 0.5, 0.75, 1.0])
    assert list(P.sweep_average_mask(t2, 0.5)) == [False, False, False, True, True]


def test_sample_period_is_the_median_spacing():
    assert P.sample_period([0.0, 0.001, 0.002, 0.0035]) == pytest.approx(0.001, abs=1e-15)
    assert P.sample_period([0.0, 0.5]) == 0.5
    with pytest.raises(P.SamplePeriodError):
        P.sample_period([0.0])
    with pytest.raises(P.SamplePeriodError):
        P.sample_period([1.0, 0.5, 0.0])
    assert issubclass(P.SamplePeriodError, ValueError)


# ---------------------------------------------------------------- step onset
def test_step_onset_half_maximum_rule():
    t = [0.0, 0.1, 0.2, 0.3, 0.4]
    assert P.step_onset(t, [0, 0, 2, 2, 2]) == (0.2, 2)
    on = P.step_onset(t, [0, 1, 3, 3, 3])           # half maximum 1.5: 1 is below it
    assert on.time_s == 0.2 and on.index == 2
    assert P.step_onset(t, [0, 1.5, 2.9, 3, 3]).index == 2   # exactly half is not above it
    assert P.step_onset(t, [-1, 0.2, 0.3, 0.1, 0]).index == 1   # max 0.3: 0.2 > 0.15
    with pytest.raises(P.NoStepError, match="never rises above 0 V"):
        P.step_onset(t, [0, 0, -1, -1, 0])
    assert issubclass(P.NoStepError, ValueError)


def test_drives_and_their_onset():
    t = P.time_grid(P.PRE_STEP_S + P.STEP_POST_S)
    assert t.size == 3001
    V = P.step_voltage(t, 12.0)
    assert P.step_onset(t, V) == (pytest.approx(0.2, abs=1e-12), 200)
    assert np.all(V[:200] == 0.0) and np.all(V[200:] == 12.0)
    assert P.step_level(V, 200) == 12.0
    ts = P.time_grid(P.PRE_STEP_S + P.T6_PERIODS / P.T6_FREQUENCY_HZ)
    Vs = P.sine_voltage(ts, 10.0)
    # raised cosine 5*(1 - cos(2 pi tau)) exceeds 5 V from tau = 0.25 s on
    assert 0.45 - 1e-9 <= P.step_onset(ts, Vs).time_s <= 0.451 + 1e-9
    assert Vs[200] == 0.0 and Vs[700] == pytest.approx(10.0)         # tau = 0.5 s: peak
    assert P.step_level(Vs, P.step_onset(ts, Vs).index) is None


def test_step_level_pure_steps_only():
    assert P.step_level([0, 0, 2, 2], 2) == 2.0
    assert P.step_level([0, 1, 2, 2], 2) is None     # not at rest before
    assert P.step_level([0, 0, 2, 2.1], 2) is None   # not constant after
    assert P.step_level([0, 0, 2], 2) is None        # a single sample after the onset


def test_steady_window_last_fraction_after_the_onset_at_least_10_samples():
    assert P.steady_window(3001, 200) == slice(3001 - 1400, None)      # int(0.5 * 2801) = 1400
    assert P.steady_window(3001, 200, 0.25) == slice(3001 - 700, None)
    assert P.steady_window(30, 20) == slice(20, None)                  # 10 post-onset samples: the last 10
    assert P.steady_window(100, 0, 0.5) == slice(50, None)


# ---------------------------------------------------------------- noise floor
_RIG = {"sensors": {"displacement_mm": {"noise_sigma": 0.005, "resolution": 0.002,
                                        "noise_floor": math.sqrt(0.005 ** 2 + 0.002 ** 2 / 12)},
                    "force_N": {"noise_sigma": 0.0005},
                    "current_A": {"noise_sigma": 0.002, "noise_floor": 0.0}}}


def test_noise_floor_from_the_manifest():
    assert P.noise_floor(_RIG, "displacement_mm") == pytest.approx(5.0332e-3, rel=1e-4)
    assert P.noise_floor(_RIG, "displacement_mm", quantization=False) == 0.005
    assert P.noise_floor(_RIG, "force_N") == 0.0005                   # no floor stated: its sigma
    assert P.noise_floor(_RIG, "current_A") is None                   # 0 is no floor
    assert P.noise_floor(_RIG, "current_A", quantization=False) == 0.002
    assert P.noise_floor(SimpleNamespace(rig=_RIG), "displacement_mm", quantization=False) == 0.005
    for rig in (None, {}, {"sensors": None}, {"sensors": {"force_N": "x"}}):
        assert P.noise_floor(rig, "force_N") is None
        assert P.noise_floor(rig, "force_N", quantization=False) is None


def test_rig_manifest_floor_is_sqrt_sigma2_plus_q2_over_12():
    from harness.data import rig
    d = rig.rig_description()
    for col, (sigma, q) in {"displacement_mm": (0.005, 0.002), "force_N": (0.0005, 0.0001),
                            "current_A": (0.002, 0.001)}.items():
        assert P.noise_floor(d, col) == pytest.approx(math.sqrt(sigma ** 2 + q ** 2 / 12), rel=1e-12)
        assert P.noise_floor(d, col, quantization=False) == sigma


def _record(y_pre, n_post=5):
    y = np.concatenate([np.asarray(y_pre, float), np.zeros(n_post)])
    V = np.concatenate([np.zeros(len(y_pre)), np.full(n_post, 3.0)])
    return SimpleNamespace(time_s=np.arange(y.size) * 1e-3, voltage_V=V, displacement_mm=y, force_N=None)


def test_record_noise_floor_hand_case():
    # 20 quiet samples with differences 1, 2, ..., 19: median 10, |d - 10| has median 5
    y = np.concatenate([[0.0], np.cumsum(np.arange(1.0, 20.0))])
    r = _record(y)
    assert P.record_noise_floor(r.voltage_V, r.displacement_mm) == pytest.approx(1.4826 * 5 / math.sqrt(2))
    short = _record(y[:19])                                          # 19 quiet samples: too few
    assert P.record_noise_floor(short.voltage_V, short.displacement_mm) is None
    # no step at all: the whole record is quiet
    assert P.record_noise_floor(np.zeros(20), y) == pytest.approx(1.4826 * 5 / math.sqrt(2))


def test_record_noise_floor_of_white_noise():
    rng = np.random.default_rng(1)
    r = _record(rng.normal(0.0, 0.01, 20000))
    assert P.record_noise_floor(r.voltage_V, r.displacement_mm) == pytest.approx(0.01, rel=0.05)


def test_estimate_noise_floor_median_over_records():
    y = np.concatenate([[0.0], np.cumsum(np.arange(1.0, 20.0))])
    recs = [_record(y), _record(2 * y), _record(4 * y), _record(y[:5]),
            SimpleNamespace(gap_mm=np.zeros(3), displacement_mm=np.zeros(3))]   # a sweep: skipped
    assert P.estimate_noise_floor(recs, "displacement_mm") == pytest.approx(2 * 1.4826 * 5 / math.sqrt(2))
    ds = SimpleNamespace(samples=[SimpleNamespace(tests={"T2": recs[0], "T3": recs[2]})])
    assert P.estimate_noise_floor(ds, "displacement_mm") == pytest.approx(2.5 * 1.4826 * 5 / math.sqrt(2))
    with pytest.raises(P.NoiseFloorError, match="cannot estimate the noise of force_N"):
        P.estimate_noise_floor(recs, "force_N")
    assert issubclass(P.NoiseFloorError, ValueError)


def _diagnosis_onset_as_written_before(V):
    """The diagnosis' own onset rule (diagnose._prepare before the protocol module): half maximum,
    walked back to the last zero sample; a pure step keeps it, anything else starts at 0."""
    k_on = int(np.argmax(V > 0.5 * np.max(V))) if np.any(V > 0) else 0
    while k_on > 0 and V[k_on - 1] != 0.0:
        k_on -= 1
    post = V[k_on:]
    step = (np.all(V[:k_on] == 0.0) and post.size > 1
            and np.ptp(post) <= 1e-9 * max(abs(float(post[0])), 1e-12))
    return (k_on if step else 0), (float(post[0]) if step else None)


def test_the_diagnosis_rule_is_step_onset_plus_step_level():
    """Walking back to the last zero sample never changes a pure step's onset, so the diagnosis' rule
    is: index = step_onset (0 without a positive voltage), kept only when step_level finds a pure step."""
    def with_protocol(V):
        try:
            k = P.step_onset(np.arange(V.size) * 1e-3, V).index
        except P.NoStepError:
            k = 0
        level = P.step_level(V, k)
        return (k if level is not None else 0), level

    assert P.step_level(np.zeros(4), 0) == 0.0             # no drive at all: a 0 V "step" at sample 0
    assert P.step_level(np.full(4, -1.0), 0) == -1.0       # constant from the start
    rng = np.random.default_rng(0)
    levels = np.array([0.0, 0.0, 1.0, 2.0, 2.0, 0.5, -1.0, 1.0 + 1e-12])
    for _ in range(20000):
        n = int(rng.integers(2, 8))
        V = rng.choice(levels, n)
        if rng.random() < 0.5:
            k = int(rng.integers(0, n))
            V[:k] = 0.0
            V[k:] = rng.choice(levels)
        assert with_protocol(V) == _diagnosis_onset_as_written_before(V), V


# ---------------------------------------------------------------- conventions estimated from the data
def test_quantized_quiet_noise_includes_the_quantization():
    """0.3x our laser (sigma 1.5 um) on a 2 um grid: the MAD of the differences is useless (few distinct
    values); the estimate is the noise floor sqrt(sigma^2 + q^2/12) within 5 %."""
    rng = np.random.default_rng(3)
    y = np.round(rng.normal(0.0, 1.5e-3, 4000) / 2e-3) * 2e-3
    r = _record(y)
    want = math.sqrt(1.5e-3 ** 2 + 2e-3 ** 2 / 12)
    assert P.record_noise_floor(r.voltage_V, r.displacement_mm) == pytest.approx(want, rel=0.05)


def test_tail_noise_floor_removes_level_and_slope():
    rng = np.random.default_rng(4)
    y = 0.3 + 0.01 * np.linspace(0, 1, 4000) + rng.normal(0.0, 0.002, 4000)
    assert P.tail_noise_floor(y) == pytest.approx(0.002, rel=0.06)
    assert P.tail_noise_floor(y[:40]) is None                       # 10 samples: too few


@pytest.mark.parametrize("n_avg", [1, 75])
def test_sweep_reading_noise_single_and_averaged(n_avg):
    """Readings of n_avg samples of noise 0.5 mN on a blocked-force-like profile (exponential in the gap,
    1 mm grid): the pooled estimate of 11 sweeps is 0.5 mN / sqrt(n_avg) within 30 % (its standard error on
    white noise: 10 %), one sweep's within 80 % (standard error 27 % for two, more for one)."""
    rng = np.random.default_rng(n_avg)
    g = np.arange(25.0, -1.0, -1.0)
    noise = 5e-4 / math.sqrt(n_avg)
    sweeps = [(g, 0.22 * k * np.exp(-g / 5.5) + rng.normal(0.0, noise, g.size)) for k in np.linspace(0.5, 1.5, 11)]
    assert P.pooled_sweep_reading_noise(sweeps) == pytest.approx(noise, rel=0.3)
    assert P.sweep_reading_noise(*sweeps[0]) == pytest.approx(noise, rel=0.8)
    assert P.sweep_reading_noise(g[:6], sweeps[0][1][:6]) is None
    assert P.pooled_sweep_reading_noise([]) is None


def test_sweep_reading_noise_irregular_grid_by_hand():
    """Linear readings on an irregular grid have zero deviation from their neighbours' line."""
    g = np.array([0.0, 0.5, 1.0, 2.0, 3.5, 5.0, 8.0])
    assert P.sweep_reading_noise(g, 2.0 * g + 1.0) == pytest.approx(0.0, abs=1e-12)


def test_step_delay_voltage_by_hand():
    t = np.arange(6) * 0.004
    V = np.array([0.0, 0.0, 0.0, 12.0, 12.0, 12.0])
    out = P.step_delay_voltage(t, V, 3, 0.001)          # step 1 ms before the sample at 12 ms
    assert np.allclose(out, [0, 0, 3.0, 12, 12, 12]) and V[2] == 0.0
    assert np.allclose(P.step_delay_voltage(t, V, 3, 0.0), V)
