"""Online tracking: the model beside a stream, chunk by chunk, gives the
offline answer (same model output within a small fraction of the noise, same
detection sample), whatever the chunking; a healthy stream raises nothing."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from condmon.diagnose.residuals import DetectionSettings, compute_residuals, detect, \
    noise_normalisation
from condmon.diagnose.structure import residual_generators
from condmon.diagnose.tracking import ModelTracker
from condmon.models.registry import load_plant_model
from condmon.simulate.plant import input_signals, integrate, sensor_readings
from condmon.simulate.plant import simulate_plant
from condmon.simulate.stepper import BatchStepper

HST = load_plant_model("hst")


def _columns(rec: pd.DataFrame) -> dict[str, np.ndarray]:
    return {c: rec[c].to_numpy() for c in rec.columns}


def _stream(tracker: ModelTracker, records: dict[str, pd.DataFrame], chunk: int) -> dict:
    cols = {u: _columns(r) for u, r in records.items()}
    n = max(len(r) for r in records.values())
    found = {}
    for k in range(0, n, chunk):
        part = {u: {c: v[k:k + chunk] for c, v in cs.items()} for u, cs in cols.items()
                if k < len(cs["t"])}
        for o in tracker.feed(part):
            assert o.dropped is None, o
            if o.detection is not None:
                found[o.unit] = o.detection
    return found


def test_the_stepper_follows_the_offline_solution_within_the_noise() -> None:
    t = np.arange(3001) * 0.01
    u = input_signals(HST, t)          # the built-in test: pump at 100 %, then 75 % at 20 s
    compiled = HST.compile()
    offline = sensor_readings(compiled, integrate(compiled, t, u), u, (), t)
    s = BatchStepper(HST)
    slot = s.add()
    online = np.empty_like(offline)
    online[0] = s.outputs([slot], u[:1].T)[:, 0]
    for k in range(1, len(t)):
        online[k] = s.step([slot], u[k - 1:k].T, np.array([0.01]))[:, 0]
    noise = np.array([x.noise for x in HST.sensors])
    err = np.abs(online - offline).max(axis=0) / noise
    assert err.max() < 1e-2, err


@pytest.mark.parametrize("chunk", [1, 37, 100, 1000])
def test_online_detection_is_the_offline_one_whatever_the_chunking(chunk: int) -> None:
    records = {"rv": simulate_plant(HST, ["Rv=+40%@10s"], seed=2, duration=16.0),
               "dm": simulate_plant(HST, ["Dm=-25%@6s"], seed=5, duration=12.0),
               "ok": simulate_plant(HST, seed=7, duration=16.0)}
    settings = DetectionSettings()
    gens = residual_generators(HST)
    offline = {}
    for unit, rec in records.items():
        r = compute_residuals(HST, rec, gens)
        offline[unit] = detect(r, noise_normalisation(HST, r, settings), settings)
    found = _stream(ModelTracker(HST, settings), records, chunk)
    assert not offline["ok"].detected and "ok" not in found  # a healthy stream: nothing
    for unit in ("rv", "dm"):
        assert found[unit].time == pytest.approx(offline[unit].time, abs=0.011), unit
        assert found[unit].onset == pytest.approx(offline[unit].onset, abs=0.011), unit
        assert set(found[unit].fired) <= set(offline[unit].fired)


def test_duplicates_and_gaps_are_counted_and_said() -> None:
    rec = _columns(simulate_plant(HST, seed=3, duration=6.0))
    tr = ModelTracker(HST, DetectionSettings())
    part = lambda a, b: {c: v[a:b] for c, v in rec.items()}  # noqa: E731
    assert tr.feed({"U": part(0, 100)})[0].samples == 100
    again = tr.feed({"U": part(0, 100)})[0]
    assert again.dropped is not None and again.dropped.startswith("a duplicate")
    assert tr.dropped == 1
    gap = tr.feed({"U": part(300, 400)})[0]
    assert gap.samples == 100 and "a gap of 2.01 s" in gap.notes[0]
    assert tr.detection("U") is None
    restart = tr.feed({"U": part(0, 100)})[0]  # the clock starts again from 0
    assert restart.samples == 100 and "the stream's clock went back" in restart.notes[0]


def test_a_stream_joined_while_the_plant_runs_raises_nothing_and_still_detects() -> None:
    """The model starts from the first readings of the states the sensors read
    (the others settle in the start-up): joining at t = 5 s is no fault."""
    settings = DetectionSettings()
    healthy = simulate_plant(HST, seed=8, duration=20.0).iloc[500:].reset_index(drop=True)
    faulty = simulate_plant(HST, ["Rv=+40%@12s"], seed=9, duration=20.0).iloc[500:]
    found = _stream(ModelTracker(HST, settings), {"ok": healthy, "rv": faulty}, 100)
    assert "ok" not in found
    assert 12.0 < found["rv"].time <= 13.0


def test_any_message_is_a_chunk_or_one_refusal() -> None:
    """Over arbitrary payloads (JSON or not), parsing gives a valid chunk or a
    DataError naming the unit and topic: never another exception."""
    import json as _json

    from hypothesis import given, settings
    from hypothesis import strategies as st

    from condmon.errors import DataError
    from condmon.io.stream import parse_chunk

    numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(),
                        st.booleans(), st.none(), st.text(max_size=3))
    columns = st.dictionaries(st.sampled_from(["t", "Ps", "omega_m", "end", "x"]),
                              st.one_of(st.lists(numbers, max_size=6), numbers), max_size=4)
    payloads = st.one_of(columns.map(lambda d: _json.dumps(d).encode()),
                         st.binary(max_size=40), st.text(max_size=40).map(str.encode))

    @settings(max_examples=400, deadline=None)
    @given(payloads)
    def check(payload: bytes) -> None:
        try:
            chunk = parse_chunk("condmon/U-1/samples", payload)
        except DataError as exc:
            assert "unit 'U-1' (topic condmon/U-1/samples)" in str(exc)
            assert "\n" not in str(exc)
            return
        lengths = {len(v) for v in chunk.columns.values()}
        assert len(lengths) <= 1 and (chunk.end or "t" in chunk.columns)
        assert all(np.all(np.isfinite(v)) for v in chunk.columns.values())

    check()


@pytest.mark.parametrize("t,ps,message", [
    ([0.0, 1e-9, 2e-9], [0.0, 0.0, 0.0], "1e+07 times shorter than the test's 0.01 s"),
    ([0.0, 1000.0], [0.0, 0.0], "1e+05 times longer than the test's 0.01 s: column 't' must be"
                                " in seconds (milliseconds given as seconds"),
    ([100.1, 100.1000001, 100.5], [0.0, 0.0, 0.0], "not uniformly sampled"),
    ([0.0, 0.01], [1e300, 1e300], "column 'Ps' reaches 1e+300 Pa at row 0, more than 10 spans"),
])
def test_a_stream_chunk_gets_the_record_checks(t: list[float], ps: list[float],
                                              message: str) -> None:
    """The same checks and messages as a record file's (diagnose.checks)."""
    from condmon.diagnose.checks import check_stream_chunk
    from condmon.errors import DataError

    cols = {"t": np.array(t), "Ps": np.array(ps), "omega_m": np.zeros(len(t))}
    with pytest.raises(DataError, match="unit 'U'") as err:
        check_stream_chunk(HST, cols, "unit 'U'")
    assert message in str(err.value)
