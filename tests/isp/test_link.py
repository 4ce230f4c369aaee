"""Links, decimation and the DDR ring (seed 002 §3.2.5, §3.3)."""

import math

import numpy as np
import pytest

from viform._validate import ViformError
from viform.isp.link import (
    INTERFACES,
    DDRBuffer,
    RingBuffer,
    choose_decimation,
    link_plan,
    overrun_time_s,
)

SENSOR_HZ = 1e8 / 6e4  # seed operating point


def test_cameralink_full_555_fps_at_1280x720():
    """Seed 002 §3.3: 80 MHz, 8 px/clock, 40-cycle line and frame gaps → 555 fps."""
    cl = INTERFACES["cameralink"]
    assert cl.cycles_per_frame(720, 1280, 8) == 720 * (160 + 40) + 40
    assert int(cl.max_frame_rate_hz(720, 1280, 8)) == 555


def test_link_ranking_follows_table_3():
    r = {k: v.max_frame_rate_hz(720, 1280, 8) for k, v in INTERFACES.items()}
    assert r["coaxpress"] > r["cameralink"] > r["gige"]
    assert r["cameralink-hs"] > r["cameralink"] > r["usb3"] > r["gige"]
    # 10-bit pixels are slower than 8-bit on every link.
    assert all(v.max_frame_rate_hz(720, 1280, 10) < r[k] for k, v in INTERFACES.items())


def test_ddr_holds_2330_frames():
    """Seed 002 §3.2.5: 2 GB / (1280 × 720 × 8 bit) ≈ 2 330 frames."""
    ddr = DDRBuffer()
    assert ddr.capacity_frames(720, 1280, 8) == 2330
    assert ddr.record_duration_s(SENSOR_HZ, 720, 1280) == pytest.approx(2330 / SENSOR_HZ)


def test_seed_decimation_is_3_to_1_with_the_ring_4_to_1_strictly():
    """1 666.7 / 3 = 555.6 fps is 0.03 % above the link's 555.4 fps: strictly 4:1; the ring
    absorbs the excess for ≈ 5 000 s, so the seed's 3:1 holds for over an hour."""
    link = INTERFACES["cameralink"].max_frame_rate_hz(720, 1280)
    assert choose_decimation(SENSOR_HZ, link) == 4
    t = overrun_time_s(SENSOR_HZ, link, 3, 2330)
    assert 4000 < t < 6000
    assert choose_decimation(SENSOR_HZ, link, buffer_frames=2330, sustain_s=3600) == 3
    plan = link_plan(SENSOR_HZ, 720, 1280, "cameralink")
    assert plan["decimation"] == 3 and plan["buffer_capacity_frames"] == 2330


def test_fast_links_need_no_decimation_slow_ones_need_more():
    for name, n_min in (("coaxpress", 1), ("usb3", 4), ("gige", 13)):
        link = INTERFACES[name].max_frame_rate_hz(720, 1280)
        n = choose_decimation(SENSOR_HZ, link)
        assert SENSOR_HZ / n <= link < SENSOR_HZ / max(n - 1, 1) or n == 1
        assert n >= n_min


def test_link_too_slow_at_any_decimation_names_interface():
    with pytest.raises(ViformError, match="interface = 'gige'"):
        link_plan(SENSOR_HZ, 720, 1280, "gige", max_decimation=8)
    with pytest.raises(ViformError, match="interface"):
        link_plan(SENSOR_HZ, 720, 1280, "firewire")


def test_ring_counts_add_up_and_match_closed_form_overrun():
    """A small ring and a link 10 % too slow for 3:1: losses start at the predicted time."""
    sensor, link, cap, d = 1000.0, 300.0, 60, 3
    acct = RingBuffer(cap, sensor, link, d).run(3000)
    t_first = overrun_time_s(sensor, link, d, cap)  # (20 - 1.11) / 33.3 = 0.567 s
    assert t_first == pytest.approx((20 - 333.333 / 300) / 33.333, rel=1e-4)
    # The loss happens when the lost frame's slot is rewritten (frame i + C written).
    lost_at = (acct.overrun_indices[0] + cap + 1) / sensor
    assert lost_at == pytest.approx(t_first, abs=d / sensor + 1 / link)
    # Throughput after saturation is the link's.
    assert acct.transmitted == pytest.approx(link * 3.0, rel=0.02)
    # Every frame is transmitted, still buffered, or dropped, exactly once.
    kept = set(acct.transmitted_indices.tolist()) | set(range(3000 - cap, 3000))
    assert acct.dropped == 3000 - len(kept)
    assert acct.buffered == cap


def test_ring_with_fast_link_loses_only_decimated_frames():
    acct = RingBuffer(2330, SENSOR_HZ, 600.0, 3).run(6000)
    # Frame 5 997 is written at the end of the record: its transfer cannot finish in it.
    assert acct.transmitted == 1999 and acct.overrun_indices.size == 0
    np.testing.assert_array_equal(acct.transmitted_indices, np.arange(0, 5997, 3))
    # Dropped: the decimated-out frames older than the ring's last 2 330.
    assert acct.dropped == sum(1 for i in range(6000 - 2330) if i % 3)


def test_overrun_infinite_when_link_keeps_up():
    assert math.isinf(overrun_time_s(1000, 600, 2, 100))
