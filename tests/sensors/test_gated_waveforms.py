"""Drive waveforms of the gated interline CCD (seed 004, Figs. 2–3 and the four-stage text)."""

import pytest

from viform._validate import ViformError
from viform.light.laser import PulsedLaser, round_trip_time_s
from viform.sensors.gated_waveforms import (
    SUB_HIGH_V,
    SUB_LOW_V,
    V_LOW_V,
    V_MID_V,
    V_READ_V,
    drive_waveforms,
    trace_csv,
    trace_vcd,
)


def test_icx618_four_stage_sequence_matches_fig3():
    """Seed 004 Fig. 3: each laser pulse is followed, t_откл = 2R/c later, by the falling edge
    of SUB; V2 and V3 go to +15 V t_нак = τ + t_min after that; this repeats X times with the
    laser period; then one vertical transfer. Exposure = X · t_нак. Times exact to 1 ps."""
    laser = PulsedLaser(pulse_width_s=135e-9, repetition_hz=12.5e3)
    tr = drive_waveforms("icx618", gate_range_m=150.0, pulses=4, laser=laser, lines=5)
    fires = tr.edges("LASER", laser.peak_power_w)
    sub_fall = tr.edges("SUB", SUB_LOW_V)
    read = tr.edges("V2", V_READ_V)
    assert len(fires) == len(sub_fall) == len(read) == 4
    assert (tr.edges("V3", V_READ_V) == read).all()
    assert len(tr.edges("V1", V_READ_V)) == 0 and len(tr.edges("V4", V_READ_V)) == 0
    delay = round_trip_time_s(150.0)
    assert delay == pytest.approx(1.0007e-6, rel=1e-4)                 # 2R/c at 150 m
    assert sub_fall - fires == pytest.approx([delay] * 4, abs=1e-12)
    assert read - sub_fall == pytest.approx([135e-9 + 1e-6] * 4, abs=1e-12)
    assert fires[1:] - fires[:-1] == pytest.approx([80e-6] * 3, abs=1e-12)  # t_изл = 1/12.5 kHz
    assert tr.info["exposure_s"] == pytest.approx(4 * (135e-9 + 1e-6))
    # the photodiodes are erased (SUB high) whenever they are not integrating a gate
    assert tr.level_at("SUB", fires[0] + delay / 2) == SUB_HIGH_V
    # levels the seed gives: V-phases −5.5 / 0 V, readout +15 V; SUB 0 / +20 V
    for v in ("V1", "V2", "V3", "V4"):
        assert set(tr.levels[v]) <= {V_LOW_V, V_MID_V, V_READ_V}
    assert set(tr.levels["SUB"]) == {SUB_LOW_V, SUB_HIGH_V}
    # no readout pulse during the vertical transfer (stage 4): all +15 V edges come first
    assert read.max() < dict((s[0][0], s[1]) for s in tr.stages)["4"]


def test_part_differences_named_by_the_seed():
    """ICX659: +15 V on V1 and V3 (seed); ICX445: needs VHLD and VST too; ICX279: interlaced."""
    t659 = drive_waveforms("icx659", 150.0, 2, lines=2)
    assert len(t659.edges("V1", V_READ_V)) == 2 and len(t659.edges("V3", V_READ_V)) == 2
    assert len(t659.edges("V2", V_READ_V)) == 0
    t445 = drive_waveforms("icx445", 150.0, 2, lines=2)
    assert {"VHLD", "VST"} <= set(t445.levels)
    assert t445.info["drive"]["cols"] == 1280 and t445.info["drive"]["rows"] == 600
    assert drive_waveforms("icx279", 150.0, 1, lines=1).info["interlaced"]


def test_csv_and_vcd_traces():
    tr = drive_waveforms("icx618", 75.0, 2, lines=1)
    csv = trace_csv(tr).splitlines()
    assert csv[0].startswith("time_s,LASER_w,RETURN_rel,SUB_v,V1_v")
    assert len(csv) == tr.times_s.size + 1
    vcd = trace_vcd(tr).splitlines()
    stamps = [int(v[1:]) for v in vcd if v.startswith("#")]
    assert stamps == sorted(stamps) and stamps[0] == 0
    assert "$var real 64 # SUB $end" in vcd


def test_gate_beyond_pulse_period_is_refused():
    with pytest.raises(ViformError, match="gate_range_m"):
        drive_waveforms("icx618", 20_000.0, 2)
    with pytest.raises(ViformError, match="part"):
        drive_waveforms("icx999", 150.0, 2)


def test_waveform_figure_describes_the_run_not_the_shortened_drawing(tmp_path, monkeypatch):
    """The top panel draws the first 4 pulses only; its title must still give the run's X and
    frame time (the console's), and say how much is drawn."""
    import viform._io as vio
    from viform.sensors import gated_waveforms as gw

    titles = []

    def grab(path, fig, **kw):
        titles.extend(ax.get_title() for ax in fig.axes)

    monkeypatch.setattr(vio, "save_figure", grab)
    full = gw.drive_waveforms("icx618", 150.0, 20)
    short = gw.drive_waveforms("icx618", 150.0, 4, lines=3)
    gw.plot_waveforms(tmp_path / "w.png", short, full)
    top = titles[0]
    assert "X = 20 pulses" in top and f"frame {full.info['frame_s'] * 1e3:.4g} ms" in top
    assert "first 4 of 20 pulses" in top


@pytest.mark.parametrize("part", ["icx618", "icx445", "icx279", "icx659"])
def test_drawn_gate_is_the_modelled_gate(part):
    """One timing model (issue 28): the drive drawn for a sensor opens (SUB falls) and closes
    (readout pulse ends, SUB rises) exactly where the sensor's physics collects light, and the
    fraction of a return the drawing lets in (RETURN high while SUB is low) equals the fraction
    of a reflector's electrons the model counts in its gate, from before the gate to past it."""
    import numpy as np

    from viform.light.active import ActiveScene, PointRetroreflector
    from viform.sensors.gated_ccd import GatedInterlineCCD

    ccd = GatedInterlineCCD(pulses=3, gate_range_m=150.0)
    t = ccd.timing
    tr = ccd.drive_waveforms(part, lines=2)
    fires = tr.edges("LASER", ccd.laser.peak_power_w)
    reads = tr.drive.readout_gates
    assert tr.edges("SUB", SUB_LOW_V) - fires == pytest.approx([t.open_s] * 3, abs=1e-12)
    assert tr.edges(reads[0], V_READ_V) - fires == pytest.approx([t.transfer_start_s] * 3, abs=1e-12)
    ends = tr.edges(reads[0], V_MID_V)
    ends = np.array([e for e in ends if any(0 < e - f < ccd.laser.period_s for f in fires)])[:3]
    assert ends - fires == pytest.approx([t.close_s] * 3, abs=1e-12)
    rises = tr.edges("SUB", SUB_HIGH_V)[-3:]
    assert rises - fires == pytest.approx([t.close_s] * 3, abs=1e-12)   # SUB stays low through the pulse
    tau = ccd.laser.pulse_width_s
    for r in (120.0, 140.0, 150.0, 300.0, 460.0, 480.0):
        tr_r = drive_waveforms(part, pulses=1, lines=1, target_range_m=r, timing=t)
        grid = np.linspace(0.0, tr_r.stages[1][2], 400_001)
        idx = np.searchsorted(tr_r.times_s, grid, side="right") - 1
        inside = (tr_r.levels["RETURN"][idx] > 0) & (tr_r.levels["SUB"][idx] == SUB_LOW_V)
        drawn = inside.sum() * (grid[1] - grid[0]) / tau
        scene = ActiveScene(range_m=np.full((9, 9), np.inf), reflectance=0.0, ambient_lux=0.0,
                            retroreflectors=[PointRetroreflector(r, 4.0, 4.0)])
        g = ccd.geometry
        model = g.retroreflector_electrons(scene, t.open_s, t.close_s).sum() / g.retroreflector_electrons(scene).sum()
        assert drawn == pytest.approx(model, abs=0.01)
