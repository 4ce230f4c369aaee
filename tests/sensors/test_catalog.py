"""The sensor catalogue: every sensor by one name, every parameter reachable by name with its unit
and allowed range, ranges that are the models' own, and the settings of one command equal to
another's."""

import dataclasses
import math
import re

import numpy as np
import pytest

from viform._validate import ViformError
from viform.sensors import catalog
from viform.sensors.base import Sensor
from viform.sensors.catalog import SENSORS, make_sensor

ENTRIES = sorted(SENSORS)


@pytest.mark.parametrize("name", ENTRIES)
def test_every_entry_builds_a_sensor_whose_defaults_are_allowed(name):
    e = SENSORS[name]
    assert e.family in catalog.FAMILIES and e.label and e.description
    sensor = e.build()
    assert isinstance(sensor, Sensor)
    for p in e.parameters.values():
        assert p.check(p.default) == p.default or (p.default is None and p.optional), p.name
        if p.kind in ("float", "int") and p.name.endswith(("_s", "_hz", "_m", "_electrons", "_v", "_f")):
            assert p.unit, p.name  # a physical quantity carries its unit


def _candidates(p):
    """Values other than the default, in the allowed range, most ordinary first."""
    d = p.default
    if p.kind == "bool":
        return [not d]
    if p.kind == "choice":
        return [c for c in p.choices if c != d]
    if p.kind == "text":
        return ["640x480"]  # the high-speed camera's readout window
    if d is None:
        out = {"adc_range_v": [1.0], "register_capacity_electrons": [1e4], "pixel_clock_hz": [120e6],
               "ae_saturated_cut": [0.125], "threshold_level": [3], "laser_divergence_x_rad": [0.05],
               "laser_divergence_y_rad": [0.05]}
        return out.get(p.name, [1.0])
    if p.kind == "int":
        return [v for v in (d - 1, d + 1, d + 2) if p.low is None or v >= p.low]
    if d == 0:
        return [v for v in (1e-3, 0.01, 0.1) if p.high is None or v < p.high]
    return [d * f for f in (0.5, 0.9, 1.1, 2.0) if p.high is None or d * f <= p.high]


def _holds(sensor, p, value) -> bool:
    """Whether the built sensor holds ``value`` where parameter ``p`` says it goes."""
    par = getattr(sensor, "parameters", None)
    pixel = par.pixel if hasattr(par, "pixel") else par
    where = {"pixel": pixel, "optics": getattr(pixel, "optics", None), "camera": sensor, "ccd": par,
             "laser": getattr(sensor, "laser", None), "receiver": getattr(sensor, "receiver", None)}.get(p.where)
    if where is None or not hasattr(where, p.field):
        return False
    got = getattr(where, p.field)
    return got == value or (isinstance(value, float) and isinstance(got, float) and math.isclose(got, value))


@pytest.mark.parametrize("name", ENTRIES)
def test_every_parameter_is_reached_by_name(name):
    """Each parameter set alone changes the built sensor: the value lands where the parameter says
    (pixel, optics, camera, CCD, laser, receiver), or a shorthand changes what it stands for."""
    e = SENSORS[name]
    default = e.build().describe()
    for p in e.parameters.values():
        built = None
        for value in _candidates(p):
            try:
                built = e.build(**{p.name: value})
            except ViformError:
                continue
            break
        assert built is not None, f"{name}: no value of {p.name} builds"
        assert _holds(built, p, value) or built.describe() != default, f"{name}: {p.name}={value!r} had no effect"


def _by(p, value):
    return {p.where: {p.field: value}}


#: Bounds the table declares that the model checks only when it is used, not when it is built.
CHECKED_LATER = {"fixed_pattern_seed"}
@pytest.mark.parametrize("name", ENTRIES)
def test_declared_ranges_are_the_models_own(name):
    """Just outside a declared bound the model itself refuses the value (the table is not looser than
    the model), and at or just inside it the model's own rule for it accepts it (not stricter; a limit
    across parameters, e.g. a swing that no longer reaches the overflow threshold, may still refuse it)."""
    e = SENSORS[name]
    for p in e.parameters.values():
        if p.kind not in ("float", "int") or p.name in CHECKED_LATER:
            continue
        for bound, is_open, side in ((p.low, p.low_open, -1), (p.high, p.high_open, +1)):
            if bound is None:
                continue
            step = 1 if p.kind == "int" else max(abs(bound), 1.0) * 1e-6
            outside = bound if is_open else bound + side * step
            inside = bound - side * step if is_open else bound
            if p.kind == "int":
                outside, inside = int(outside), int(inside)
            with pytest.raises((ViformError, ValueError)):
                e.make(_by(p, outside), None, None)
            try:
                e.make(_by(p, inside), None, None)
            except ViformError as exc:  # a limit across parameters may refuse it (other defaults), its own rule not
                own = re.match(rf"{re.escape(p.field)} = \S+ is not allowed", str(exc))
                assert own is None, (name, p.name, exc)


def test_errors_name_the_parameter_its_unit_and_what_is_allowed():
    with pytest.raises(ViformError, match=r"quantum_efficiency = 2.0 e⁻/photon is not allowed: it must be a number "
                                          r"in \(0, 1\]"):
        make_sensor("cmos", quantum_efficiency=2.0)
    with pytest.raises(ViformError, match=r"'nope' is not a parameter of sensor 'cmos'"):
        make_sensor("cmos", nope=1)
    with pytest.raises(ViformError, match=r"exposure_s = 0.05 s \(allowed: a number > 0\).*frame period"):
        make_sensor("cmos", exposure_s=0.05)  # the model's own limit, across parameters
    p = SENSORS["spikeone"].parameter("threshold_level")
    with pytest.raises(ViformError, match=r"threshold_level = 'x' is not a number: it must be a whole number in "
                                          r"\[0, 15\]"):
        p.parse("x")
    assert p.parse("7") == 7 and SENSORS["cmos"].parameter("noise").parse("off") is False


def test_exposure_and_overrides_reach_the_presets_that_fix_them():
    """Issue 33: ``--set exposure_s`` on cmos and seed003-4t raised Python's 'multiple values for
    keyword argument': the preset's value is now a default the setting replaces."""
    assert make_sensor("cmos", exposure_s=0.002).exposure_s == 0.002
    assert make_sensor("seed003-4t", exposure_s=0.01, frame_rate_hz=60.0).frame_rate_hz == 60.0
    seg = make_sensor("seed001-2seg", exposure_s=65e-6)
    assert sum(seg.segment_times_s) == pytest.approx(65e-6)
    assert seg.segment_times_s[0] / seg.segment_times_s[1] == pytest.approx(5.0)  # ratios kept
    over = make_sensor("seed003-overflow", short_integration_s=0.02e-3)
    assert over.integration_times_s == (32.8e-3, 0.5e-3, 0.02e-3)


def test_one_name_one_camera():
    """capture's, compare's and dataset's spikeone are one camera; 'spike' is seed 000's Q = 100 e⁻ model."""
    from viform.datasets.build import resolve_preset
    from viform.measure.comparison import compare_entry, make_compare_sensor
    from viform.sensors.spike_presets import load_spike_preset

    chip = load_spike_preset("spikeone")
    assert make_sensor("spikeone").parameters == chip.parameters == make_compare_sensor("spikeone").parameters
    assert resolve_preset("spikeone")[0] == chip.parameters
    assert make_sensor("spike").parameters.threshold_electrons == 100.0
    with pytest.raises(ViformError, match="now 'spikeone'"):
        compare_entry("spike")
    assert make_sensor("spikeone", threshold_level=0).parameters.threshold_electrons == 1250.0


def test_highspeed_parasitic_light_reaches_the_frames():
    """The high-speed camera's storage nodes gather PLS × the photo-rate while the rows are read:
    row r (of H) waits (r + 1)/H × t_ro, so the frame gains PLS·η·E·t_ro·(H + 1)/(2H) e⁻ on average."""
    from viform.light.scenes import StillScene

    lux = 400.0
    scene = StillScene(np.full((40, 40), lux))
    # the camera's own shutter leaks (PLS 0.01 by default): the reference has none
    base = make_sensor("highspeed", ae=False, exposure_s=100e-6, prnu_fraction=0.0, dsnu_electrons=0.0,
                       parasitic_light_sensitivity=0.0)
    t_ro = base.frame_period_s
    leaky = make_sensor("highspeed", ae=False, exposure_s=100e-6, prnu_fraction=0.0, dsnu_electrons=0.0,
                        parasitic_light_sensitivity=0.05, readout_time_s=t_ro)
    p = base.parameters
    gray_per_e = p.system_gain_dn_per_e / (1 << (p.adc_bits - 8))
    a = base.capture_frames(scene, 4, seed=1).frames_dn.astype(float).mean()
    b = leaky.capture_frames(scene, 4, seed=1).frames_dn.astype(float).mean()
    expected = 0.05 * p.optics.electrons_per_lux_second * lux * t_ro * (40 + 1) / (2 * 40) * gray_per_e
    assert expected > 5  # several gray levels: the 8-bit rounding does not hide it
    assert b - a == pytest.approx(expected, rel=0.05)


def test_spike_sensor_applies_catalogue_settings_to_any_parameters():
    base = dataclasses.replace(SENSORS["spike"].build().parameters, clock_hz=10e3)
    s = catalog.spike_sensor(base, threshold_level=1, quantum_efficiency=0.5)
    assert s.parameters.threshold_electrons == 2500.0 and s.parameters.optics.quantum_efficiency == 0.5
    assert s.parameters.clock_hz == 10e3
    with pytest.raises(ViformError, match="not a parameter of a spike camera"):
        catalog.spike_sensor(base, exposure_s=1.0)
