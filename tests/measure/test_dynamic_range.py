"""Dynamic range (seed 000 §4.2–§4.5): the seed's worked figures and a measured sensor."""

import json

import pytest

from viform._validate import ViformError
from viform.measure.dynamic_range import (
    dynamic_range_db,
    dynamic_range_from_dark_db,
    levels_for_dynamic_range,
    measure_spike_dynamic_range,
    shortest_interval_s,
    subthreshold_dynamic_range_db,
)


def test_seed_figures():
    assert dynamic_range_db(10e-9, 1.0) == pytest.approx(160.0)
    assert dynamic_range_db(10e-9, 10.0) == pytest.approx(180.0)
    assert subthreshold_dynamic_range_db(10e-9, 10e-3, 100) == pytest.approx(160.0)
    assert shortest_interval_s(100, 1e5) == pytest.approx(3.5e-9, abs=0.05e-9)  # seed: 3.5 ns
    assert dynamic_range_from_dark_db(100, 10e-9, 100) == pytest.approx(160.0)  # Q/Id = 1 s


def test_levels_for_180_db():
    # §4.5: keeping 180 dB with τ̆ = 1 s needs N = 10 levels (τ̌ = 10 ns)
    assert levels_for_dynamic_range(10e-9, 1.0, 180.0) == 10
    assert levels_for_dynamic_range(10e-9, 0.1, 180.0) == 100


def test_bad_input():
    with pytest.raises(ViformError, match="shortest_s"):
        dynamic_range_db(0, 1)
    with pytest.raises(ViformError, match="longest_s"):
        dynamic_range_db(1, 0.5)


def test_measured_sensor_agrees_with_formula():
    m = measure_spike_dynamic_range()
    assert m["shortest_s_measured"] == pytest.approx(m["shortest_s_formula"])
    assert abs(m["dr_measured_db"] - m["dr_formula_db"]) <= m["tolerance_db"]


def test_dr_cli_json():
    from click.testing import CliRunner

    from viform.cli import _load_commands
    from viform.cli.app import cli

    _load_commands()
    r = CliRunner().invoke(cli, ["dr", "--json", "--shortest", "1e-8", "--longest", "10"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.output)
    assert [round(e.get("computed_db", 0), 6) for e in out["seed_examples"][:3]] == [160.0, 180.0, 160.0]
    assert out["dr_db"] == pytest.approx(180.0)


def test_dr_cli_takes_a_sensors_q_clock_and_dark_current():
    """DR = 20·log10(τ̂/τ̌) with τ̌ = 1/clock and τ̂ = Q/Id: 40 kHz, Q = 100 e-, 20 e-/s → 20·log10(2e5) dB."""
    import math

    from click.testing import CliRunner

    from viform.cli import _load_commands
    from viform.cli.app import cli

    _load_commands()
    r = CliRunner().invoke(cli, ["dr", "--json", "--clock-hz", "40000", "--threshold-electrons", "100",
                                 "--dark-current-e-per-s", "20"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.output)
    assert out["dr_db"] == pytest.approx(20 * math.log10((100 / 20) * 40000), abs=1e-9)


def test_dr_cli_refuses_half_a_range():
    """--shortest alone used to be ignored silently; it is now an error naming what is missing."""
    from viform.cli import main

    assert main(["dr", "--shortest", "1e-5"]) == 2
