"""Real-chip spike presets and JSON preset files (seed 000 §6)."""

import json

import numpy as np
import pytest

from viform._validate import ViformError
from viform.light.scenes import StillScene
from viform.sensors import catalog
from viform.sensors.spike_presets import (
    DEFAULT_THRESHOLD_LEVEL,
    SPIKE_PRESET_NAMES,
    load_spike_preset,
    save_spike_preset,
    threshold_level_electrons,
    threshold_levels_electrons,
)


def test_chip_presets_have_the_chips_sizes_and_clocks():
    expected = {"spikeone": (250, 400, 40e3), "spiketwo": (1000, 1000, 20e3), "spiketwo-40k": (1000, 1000, 40e3)}
    assert set(expected) <= set(SPIKE_PRESET_NAMES)
    for name, (h, w, clock) in expected.items():
        p = load_spike_preset(name)
        assert (p.height, p.width, p.parameters.clock_hz) == (h, w, clock)
        # realistic threshold: real recordings need an effective Q of order 1e4 e⁻
        assert 5e3 <= p.parameters.threshold_electrons <= 2e4
        assert p.parameters.threshold_electrons == threshold_level_electrons(DEFAULT_THRESHOLD_LEVEL)
        sensor = p.sensor()
        assert (sensor.height, sensor.width) == (h, w)


def test_sixteen_levels_increasing_and_bounded():
    levels = threshold_levels_electrons()
    assert len(levels) == 16
    assert np.all(np.diff(levels) > 0)
    assert threshold_level_electrons(0) == levels[0]
    for bad in (-1, 16, 2.5):
        with pytest.raises(ViformError, match="threshold level"):
            threshold_level_electrons(bad)


def test_threshold_level_override_and_both_refused():
    p = load_spike_preset("spikeone")
    assert p.sensor(threshold_level=3).parameters.threshold_electrons == threshold_level_electrons(3)
    assert p.with_threshold_level(15).parameters.threshold_electrons == threshold_level_electrons(15)
    with pytest.raises(ViformError, match="threshold_level"):
        p.sensor(threshold_level=3, threshold_electrons=500)


def test_round_trip_through_json(tmp_path):
    p = load_spike_preset("spiketwo-40k").with_threshold_level(2)
    path = save_spike_preset(tmp_path / "chip.json", p)
    q = load_spike_preset(str(path))
    assert q == p


def test_presets_reachable_through_make_sensor():
    assert set(SPIKE_PRESET_NAMES) <= set(catalog.sensor_names("spike"))
    s = catalog.make_sensor("spiketwo")
    assert (s.height, s.width, s.parameters.clock_hz) == (1000, 1000, 20e3)
    assert "SpikeTwo" in catalog.describe("spiketwo")


def test_preset_sensor_fires_at_light_over_q():
    """A small crop of the spikeone preset fires at λ/Q per tick (noise-free model, exact
    up to one spike per pixel over the run)."""
    p = load_spike_preset("spikeone")
    s = p.sensor(height=4, width=4, photon_noise=False, dark_current_e_per_s=0.0)
    if hasattr(s.parameters, "gain_spread_fraction"):
        s = p.sensor(height=4, width=4, photon_noise=False, dark_current_e_per_s=0.0, gain_spread_fraction=0.0)
    q = s.parameters.threshold_electrons
    lux = float(s.parameters.optics.lux_from_electrons_per_s(0.1 * q * s.parameters.clock_hz))
    spikes = s.capture(StillScene(np.full((4, 4), lux)), 0.01, seed=1).spikes  # 400 ticks
    assert np.all(np.abs(spikes.sum(axis=0) - 40) <= 1)


def _write(tmp_path, d):
    path = tmp_path / "p.json"
    path.write_text(json.dumps(d))
    return str(path)


@pytest.mark.parametrize(
    "change, needle",
    [
        ({"colour": 1}, "unknown key 'colour'"),
        ({"sensor": {"treshold_electrons": 5}}, "sensor: unknown key 'treshold_electrons'"),
        ({"sensor": {"threshold_electrons": -5}}, "threshold_electrons = -5"),
        ({"sensor": {"threshold_electrons": "big"}}, "sensor.threshold_electrons = 'big'"),
        ({"sensor": {"photon_noise": 1}}, "sensor.photon_noise = 1"),
        ({"sensor": {"reset": "sometimes"}}, "reset = 'sometimes'"),
        ({"sensor": {"optics": {"pitch": 1}}}, "sensor.optics: unknown key 'pitch'"),
        ({"sensor": {"optics": {"quantum_efficiency": 3}}}, "quantum_efficiency"),
        ({"height": 0}, "height = 0"),
        ({"threshold_level": 16}, "threshold_level = 16"),
        ({"format": "other"}, "format = 'other'"),
    ],
)
def test_bad_preset_names_the_key(tmp_path, change, needle):
    d = load_spike_preset("spikeone").to_dict()
    for key, value in change.items():
        if key == "sensor":
            d["sensor"] = {**{k: v for k, v in d["sensor"].items() if k != "optics"}, **value}
        else:
            d[key] = value
    if "threshold_level" in change:
        d["sensor"].pop("threshold_electrons")
    with pytest.raises(ViformError, match=needle.replace("(", r"\(").replace(".", r"\.")):
        load_spike_preset(_write(tmp_path, d))


def test_unreadable_or_unknown_spec(tmp_path):
    with pytest.raises(ViformError, match="choose one of"):
        load_spike_preset("spikethree")
    with pytest.raises(ViformError, match="cannot be read"):
        load_spike_preset(str(tmp_path / "missing.json"))
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ViformError, match="not valid JSON"):
        load_spike_preset(str(bad))
    missing = tmp_path / "m.json"
    missing.write_text(json.dumps({"height": 4, "width": 4}))
    with pytest.raises(ViformError, match="missing key 'sensor'"):
        load_spike_preset(str(missing))
