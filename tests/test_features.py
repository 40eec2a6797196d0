"""Signal features: declared statistics of a record's channels in its regimes' windows."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from condmon.errors import ConfigError, DataError
from condmon.features import compute_features, feature_statistic, spans_for
from condmon.models.features import FeatureSpec, parse_features

FS = 1000.0


def _sine(n: int = 4000, f: float = 50.0, amp: float = 1.0) -> np.ndarray:
    return amp * np.sin(2 * np.pi * f * np.arange(n) / FS)


@pytest.mark.parametrize("statistic, truth", [
    ("rms", 1 / math.sqrt(2)), ("std", 1 / math.sqrt(2)), ("mean", 0.0),
    ("peak_to_peak", 2.0), ("crest", math.sqrt(2)), ("kurtosis", 1.5),
    ("band_power", 0.5),
])
def test_statistics_of_a_sine_are_its_known_values(statistic: str, truth: float) -> None:
    # a unit sine: RMS 1/sqrt(2), crest sqrt(2), kurtosis 3/2, all its power (1/2) at 50 Hz
    value = feature_statistic(_sine(), statistic, FS, (40.0, 60.0))
    assert value == pytest.approx(truth, abs=2e-3)


def test_band_power_outside_the_tone_is_nothing_and_kurtosis_of_noise_is_three() -> None:
    x = _sine()
    assert feature_statistic(x, "band_power", FS, (100.0, 200.0)) < 1e-4
    noise = np.random.default_rng(3).normal(0.0, 1.0, 200_000)
    assert feature_statistic(noise, "kurtosis", FS) == pytest.approx(
        float(stats.kurtosis(noise, fisher=False)))
    assert feature_statistic(noise, "kurtosis", FS) == pytest.approx(3.0, abs=0.05)


def test_a_flat_channel_has_no_crest_or_kurtosis() -> None:
    flat = np.full(1000, 7.0)
    assert math.isnan(feature_statistic(flat, "crest", FS))
    assert math.isnan(feature_statistic(flat, "kurtosis", FS))
    est = compute_features({"acc": flat}, FS, [("", 0, 1000, True)],
                           [FeatureSpec("k", "acc", "kurtosis")])
    assert est.values == {} and "not computed" in est.notes[0]


@pytest.mark.parametrize("statistic", ["std", "rms", "kurtosis", "band_power"])
def test_the_batch_means_standard_error_is_the_scatter_of_independent_records(
        statistic: str) -> None:
    """The stated standard error against the scatter of the same feature over
    300 independent records of the same signal (white noise plus a tone)."""
    rng = np.random.default_rng(11)
    spec = FeatureSpec("f", "acc", statistic, band=(40.0, 60.0) if statistic == "band_power"
                       else None)
    values, ses = [], []
    for _ in range(300):
        x = _sine(2000, amp=0.5) + rng.normal(0.0, 1.0, 2000)
        v, se = compute_features({"acc": x}, FS, [("", 0, 2000, True)], [spec]).values["f"]
        values.append(v)
        ses.append(se)
    ratio = float(np.mean(ses) / np.std(values, ddof=1))
    assert 0.6 < ratio < 1.5, ratio


def test_features_are_keyed_by_the_regimes_of_their_windows() -> None:
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.normal(0, 1.0, 500), rng.normal(0, 3.0, 2500)])
    windows = [("forward", 0, 500, True), ("holding", 500, 3000, False)]
    moving = FeatureSpec("vib", "acc", "std")              # every used regime
    held = FeatureSpec("vib_hold", "acc", "std", regimes=("holding",))
    assert spans_for(moving, windows) == {"forward": [(0, 500)]}
    est = compute_features({"acc": x}, FS, windows, [moving, held])
    assert est.values["vib@forward"][0] == pytest.approx(1.0, abs=0.1)
    assert est.values["vib_hold@holding"][0] == pytest.approx(3.0, abs=0.15)
    # two windows of one regime: weighted by their samples
    two = compute_features({"acc": x}, FS, [("forward", 0, 500, True),
                                            ("forward", 500, 3000, True)], [moving])
    assert two.values["vib@forward"][0] == pytest.approx((500 * 1.0 + 2500 * 3.0) / 3000,
                                                         abs=0.1)


def test_an_unknown_channel_names_the_record_the_feature_and_the_columns() -> None:
    with pytest.raises(DataError, match=r"rec\.csv: feature 'vib' .* channel 'acc9', which the "
                                        r"record does not have; its columns: acc, p"):
        compute_features({"t": np.zeros(100), "acc": np.zeros(100), "p": np.zeros(100)}, FS,
                         [("", 0, 100, True)], [FeatureSpec("vib", "acc9", "std")], "rec.csv")


def test_a_band_above_the_records_nyquist_frequency_is_refused() -> None:
    spec = FeatureSpec("mesh", "acc", "band_power", band=(100.0, 300.0))
    with pytest.raises(ConfigError, match=r"rec\.csv: rig\.toml\[features\.mesh\]\.band: 300 Hz "
                                          r"is above the Nyquist frequency 250 Hz"):
        compute_features({"acc": np.zeros(1000)}, 500.0, [("", 0, 1000, True)], [spec],
                         "rec.csv", "rig.toml")


@pytest.mark.parametrize("entry, message", [
    ({"channel": "acc", "statistic": "variance"},
     r"unknown statistic 'variance'; allowed: rms, std, kurtosis, crest, peak_to_peak, mean, "
     r"band_power"),
    ({"channel": "acc", "statistic": "band_power"}, r"needs band = \[low, high\]"),
    ({"channel": "acc", "statistic": "band_power", "band": [60, 40]}, r"0 <= low < high"),
    ({"channel": "acc", "statistic": "band_power", "band": [10, 200]},
     r"200 Hz is above the Nyquist frequency 125 Hz"),
    ({"channel": "acc", "statistic": "std", "band": [1, 2]}, r"band_power\" only"),
    ({"channel": "acc", "statistic": "std", "regimes": ["sideways"]},
     r"unknown regime 'sideways'; allowed: forward, holding"),
    ({"channel": "", "statistic": "std"}, r"channel must name a record column"),
    ({"channel": "acc", "statistic": "std", "window": 3}, r"unknown key 'window'"),
])
def test_bad_declarations_are_refused_naming_the_file_and_the_feature(
        entry: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=r"rig\.toml\[features\.f\]"):
        parse_features({"f": entry}, "rig.toml", regimes=("forward", "holding"),
                       sample_rate=250.0)
    with pytest.raises(ConfigError, match=message):
        parse_features({"f": entry}, "rig.toml", regimes=("forward", "holding"),
                       sample_rate=250.0)


def test_a_feature_may_not_take_a_parameters_name() -> None:
    with pytest.raises(ConfigError, match="'Tc' is already a reported parameter"):
        parse_features({"Tc": {"channel": "acc", "statistic": "std"}}, "rig.toml",
                       reserved=("Tc",))


def test_a_ratio_feature_without_a_unit_is_dimensionless() -> None:
    """Kurtosis and crest factor are ratios: with no unit given they are "-",
    as the report prints them; a level keeps the unit given, or none."""
    got = {f.name: f.unit for f in parse_features({
        "k": {"channel": "acc", "statistic": "kurtosis"},
        "c": {"channel": "acc", "statistic": "crest"},
        "r": {"channel": "acc", "statistic": "rms"},
        "g": {"channel": "acc", "statistic": "rms", "unit": "g"}}, "rig.toml")}
    assert got == {"k": "-", "c": "-", "r": "", "g": "g"}


def _declaration(tmp_path: Path, features: str) -> Path:
    src = Path(__file__).resolve().parents[1] / "examples" / "hydraulic-actuator"
    for f in src.glob("*.toml"):
        (tmp_path / f.name).write_text(f.read_text())
    decl = tmp_path / "rotary-actuator.toml"
    decl.write_text(decl.read_text() + "\n" + features)
    return decl


def test_an_estimate_carries_its_features_and_stores_them_with_its_parameters(
        tmp_path: Path) -> None:
    from condmon.identify import estimate
    from condmon.io.rig import rig_layout
    from condmon.models.registry import get_model, load_plant_model
    from condmon.simulate.plant import simulate_plant

    decl = _declaration(tmp_path, '[features.vib]\nchannel = "theta"\nstatistic = "std"\n'
                                  'regimes = ["forward", "reverse"]\nunit = "rad"\n')
    rec = rig_layout(simulate_plant(load_plant_model(str(decl)), seed=1),
                     get_model(str(decl)).record).assign(F_Names="", F_Values=0.0, Prediction=0.0)
    res = estimate(rec, str(decl))
    stored = res.stored_values()
    assert {"vib@forward", "vib@reverse"} <= set(stored)
    assert res.unit_of("vib@forward") == "rad"
    doc = res.to_dict()
    assert doc["features"]["vib@forward"]["unit"] == "rad"


def test_a_feature_naming_a_channel_the_record_lacks_is_one_line_and_exit_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from condmon.cli.main import main
    from condmon.io.rig import rig_layout
    from condmon.models.registry import get_model, load_plant_model
    from condmon.simulate.plant import simulate_plant

    decl = _declaration(tmp_path, '[features.vib]\nchannel = "Accel_9"\nstatistic = "rms"\n')
    rec = rig_layout(simulate_plant(load_plant_model(str(decl)), seed=1),
                     get_model(str(decl)).record).assign(F_Names="", F_Values=0.0, Prediction=0.0)
    path = tmp_path / "rec.csv"
    rec.to_csv(path, index=False)
    assert main(["estimate", str(path), "--model", str(decl)]) == 2
    err = capsys.readouterr().err
    assert "channel 'Accel_9', which the record does not have" in err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("addition, message", [
    ('[features.mesh]\nchannel = "pA"\nstatistic = "band_power"\nband = [10.0, 200.0]\n',
     r"\[features\.mesh\]\.band: 200 Hz is above the Nyquist frequency 125 Hz"),
    ('[conditions.oil2]\nchannel = "Temp_9"\n',
     r"condition 'oil2' \(.*\[conditions\.oil2\]\) names channel 'Temp_9', which the "
     r"record does not have"),
    ('[features.vib]\nchannel = "Accel_7"\nstatistic = "std"\n',
     r"feature 'vib' .* names channel 'Accel_7', which the record does not have"),
])
def test_bad_declarations_are_one_line_and_exit_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], addition: str, message: str) -> None:
    """The acceptance's bad inputs through the CLI: a band above Nyquist, a
    condition naming a column the record lacks, an unknown feature channel."""
    import re

    from condmon.cli.main import main
    from condmon.io.rig import rig_layout
    from condmon.models.registry import get_model, load_plant_model
    from condmon.simulate.plant import simulate_plant

    good = _declaration(tmp_path, "")
    rec = rig_layout(simulate_plant(load_plant_model(str(good)), seed=1),
                     get_model(str(good)).record).assign(F_Names="", F_Values=0.0, Prediction=0.0)
    path = tmp_path / "rec.csv"
    rec.to_csv(path, index=False)
    bad = tmp_path / "bad"
    bad.mkdir()
    decl = _declaration(bad, addition)
    capsys.readouterr()
    assert main(["estimate", str(path), "--model", str(decl)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and re.search(message, err), err


def test_an_accuracy_of_zero_is_one_line_and_exit_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from condmon.cli.main import main

    decl = _declaration(tmp_path, "")
    decl.write_text(decl.read_text().replace('accuracy = "0.25 %", full_scale = 2.0684e7 }   # [Pa]',
                                             'accuracy = 0.0 }'))
    assert main(["estimate", "nothing.csv", "--model", str(decl)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "columns.pA.accuracy must be > 0" in err, err


def test_a_narrow_band_is_resolved_and_a_window_too_short_for_it_is_said() -> None:
    """A 20 Hz gear-mesh band at 10 kHz: the Welch segment grows until four bins
    fall in the band (with a fixed 256-sample segment, 39 Hz bins, the feature
    was silently not computed). A tone of amplitude 2 in it has power 2."""
    rng = np.random.default_rng(4)
    fs, n = 10000.0, 60000
    t = np.arange(n) / fs
    x = 2.0 * np.sin(2 * np.pi * 590.0 * t) + 0.1 * rng.standard_normal(n)
    spec = FeatureSpec("mesh", "acc", "band_power", band=(580.0, 600.0))
    est = compute_features({"acc": x}, fs, [("", 0, n, True)], [spec])
    value, se = est.values["mesh"]
    assert value == pytest.approx(2.0, rel=0.05) and 0 < se < 0.1
    short = compute_features({"acc": x[:500]}, fs, [("", 0, 500, True)], [spec])
    assert "mesh" not in short.values
    assert "needs windows of 2 x 2048 samples" in short.notes[0]
    assert "the longest window has 500" in short.notes[0]
