"""Light communication through the spike camera (seed 000 §7; capture model §3.2, §5.1)."""

from dataclasses import replace

import numpy as np
import pytest

from viform._validate import ViformError
from viform.display import lightcomm as lc
from viform.light.radiometry import PixelOptics
from viform.sensors.spike import SpikeSensorParameters

Q = 100
CLOCK = 40e3
PEAK_AT_100M = lc.LightLink(distance_m=100.0).electron_rates()["led_on_peak_pixel_e_per_s"]


def link_with_spikes_per_slot(nbar: float, slot_s: float, ambient_lux: float = 0.0) -> lc.LightLink:
    """A link whose LED pixel fires ``nbar`` times per on slot of ``slot_s`` (1/d² law from 100 m)."""
    lam = nbar * Q / slot_s
    return lc.LightLink(distance_m=100.0 * np.sqrt(PEAK_AT_100M / lam), ambient_lux=ambient_lux)


def binomial_tol(p: float, n: int, k: float = 4.0) -> float:
    return k * np.sqrt(max(p, 0.01) * (1 - min(p, 0.99)) / n)


# ------------------------------------------------------------------ physics of the link

def test_unresolved_led_falls_as_inverse_square_and_resolved_led_is_distance_free():
    near, far = lc.LightLink(distance_m=100.0), lc.LightLink(distance_m=200.0)
    # unresolved (image ≤ Airy disc, inside one pixel): all flux on one pixel → 1/d²
    assert far.electron_rates()["led_on_total_e_per_s"] == pytest.approx(
        near.electron_rates()["led_on_total_e_per_s"] / 4, rel=1e-9)
    # resolved: image illuminance = π L T / (4 N²), independent of d
    big = lc.LightLink(transmitter=lc.LEDTransmitter(diameter_m=0.2), distance_m=20.0, height=32, width=32)
    lens = big.lens
    expected = np.pi * big.transmitter.luminance_cd_per_m2 * lens.transmission / (4 * lens.f_number ** 2)
    # (d − f)/d ≈ 1 correction of the geometric image size
    assert big.image_lux == pytest.approx(expected * ((20.0 - 8e-3) / 20.0) ** 2, rel=1e-9)
    # flux is conserved by the per-pixel map when the image lies inside the region
    pix_area = big.optics.pixel_area_m2
    assert big.led_lux_map().sum() * pix_area == pytest.approx(big.flux_lm, rel=1e-9)


def test_modulated_scene_tick_means_are_exact():
    scene = lc.ModulatedSourceScene(np.ones((2, 2)), 0.5, [1, 0, 1, 1], slot_s=1e-4, start_s=3e-5,
                                    sample_window_s=2.5e-5)
    # window [1.25e-4 - 1.25e-5, 1.25e-4 + 1.25e-5] straddles the slot edge at 1.3e-4
    t = 1.25e-4
    got = scene.illuminance_lux_many([t])[0, 0, 0]
    frac_slot0 = (1.3e-4 - (t - 1.25e-5)) / 2.5e-5
    assert got == pytest.approx(0.5 + frac_slot0 * 1.0 + (1 - frac_slot0) * 0.0)
    assert scene.mean_illuminance_lux(0.0, 1e-3)[0, 0] == pytest.approx(0.5 + 3e-4 / 1e-3)


@pytest.mark.parametrize("modulation", ["ook", "manchester", "ppm4", "ppm16"])
def test_encode_decode_round_trip(modulation):
    mod = lc.get_modulation(modulation)
    bits = lc.random_bits(37, seed=5)
    slots = mod.encode(bits)
    counts = slots * 5.0
    assert np.array_equal(mod.decode(counts, bits.size, 2.5), bits)


# ------------------------------------------------------------------ decoding

@pytest.mark.parametrize("modulation", ["ook", "ppm4", "manchester"])
def test_error_free_well_inside_the_link_budget(modulation):
    """20 m, 1 cd: ~80 spikes per on slot at 5 kbit/s, ambient 1 lux gives ≪ 1 spike per slot."""
    link = lc.LightLink(distance_m=20.0, ambient_lux=1.0)
    r = lc.simulate_link(link, lc.random_bits(1000, seed=1), 5e3, modulation, seed=1)
    assert r.bit_errors == 0
    assert r.spikes_per_on_slot_pixel > 10


def test_text_message_round_trip():
    link = lc.LightLink(distance_m=30.0, ambient_lux=0.3)
    msg = "光通信 spike link".encode()
    r = lc.simulate_link(link, lc.bytes_to_bits(msg), 4e3, "ppm", seed=2)
    assert lc.bits_to_bytes(r.bits_received) == msg


@pytest.mark.parametrize("nbar", [0.25, 0.5, 0.75])
def test_ook_ber_follows_photon_starved_theory(nbar):
    """BER ≈ ½(1 − λT/Q) when an on slot gets fewer than one spike (slot edges on tick edges)."""
    slot_s = 4 / CLOCK
    link = link_with_spikes_per_slot(nbar, slot_s)
    n = 3000
    r = lc.simulate_link(link, lc.random_bits(n, seed=7), 1 / slot_s, "ook", seed=7, phase_ticks=0.0)
    theory = lc.ook_ber_starved(r.spikes_per_on_slot_pixel)
    assert r.spikes_per_on_slot_pixel == pytest.approx(nbar, rel=1e-6)
    # binomial scatter plus the Poisson spread of the charge per slot around λT (√(λT)/Q ≈ 0.07)
    assert abs(r.ber - theory) < binomial_tol(theory, n) + 0.5 * 0.07 * 0.5


@pytest.mark.parametrize("nbar", [0.25, 0.6])
def test_ppm_ber_follows_photon_starved_theory(nbar):
    slot_s = 4 / CLOCK
    link = link_with_spikes_per_slot(nbar, slot_s)
    n = 3000
    r = lc.simulate_link(link, lc.random_bits(n, seed=8), 1 / (2 * slot_s), "ppm4", seed=8, phase_ticks=0.0)
    theory = lc.ppm_ber_starved(r.spikes_per_on_slot_pixel, 4)
    assert abs(r.ber - theory) < binomial_tol(theory, n) + 0.02


def test_ber_rises_as_light_falls_below_one_spike_per_slot():
    slot_s = 4 / CLOCK
    bers = [lc.simulate_link(link_with_spikes_per_slot(nb, slot_s), lc.random_bits(800, seed=3), 1 / slot_s,
                             "ook", seed=3).ber for nb in (8.0, 0.6, 0.15)]
    assert bers[0] == 0.0
    assert bers[0] < bers[1] < bers[2]
    assert bers[2] > 0.3  # theory ½(1 − 0.15) = 0.425


def test_ber_rises_near_the_readout_clock():
    """Bright link: error-free at 2 ticks per slot; at 1.1 ticks per slot the unlocked clocks put
    slot edges inside ticks, a tick holds light of two slots and the BER rises."""
    link = lc.LightLink(distance_m=10.0, ambient_lux=0.0)
    slow = lc.simulate_link(link, lc.random_bits(1000, seed=4), CLOCK / 2, "ook", seed=4)
    fast = lc.simulate_link(link, lc.random_bits(1000, seed=4), CLOCK / 1.1, "ook", seed=4)
    assert slow.bit_errors == 0
    # a tick holding an edge fires (saturated pixel) and goes to whichever slot holds its
    # midpoint: about a quarter of the edges (half the ticks straddle, half of those land wrong)
    assert fast.ber > 0.05


def test_ber_rises_with_ambient_light_once_the_clock_saturates():
    """Counts are sub-Poisson, so a background of b spikes per slot only shifts μ₀ — until
    b + n̄_on reaches the slot's ticks: then on slots are clipped by the one-spike-per-tick
    readout and the BER rises towards ½ (slot 8 ticks, signal 3 spikes per on slot)."""
    slot_s = 8 / CLOCK
    link = link_with_spikes_per_slot(3.0, slot_s)
    e_lux = link.optics.electrons_per_lux_second

    def run(b):
        lk = replace(link, ambient_lux=b * Q / (e_lux * slot_s))
        return lc.simulate_link(lk, lc.random_bits(800, seed=6), 1 / slot_s, "ook", seed=6)

    assert run(0.01).bit_errors == 0
    assert run(3.0).bit_errors <= 2  # 6 of 8 ticks: below the ceiling
    clipped = run(6.0)  # 9 > 8: on slots clipped at 8
    assert clipped.ber > 0.02
    assert run(12.0).ber > 0.3  # both levels saturated: no contrast left


def test_max_error_free_rate_between_photon_and_clock_bounds():
    link = lc.LightLink(distance_m=100.0, ambient_lux=0.1)
    mx = lc.max_error_free_rate(link, "ook", n_bits=300, seed=0)
    bounds = lc.theoretical_rate_limits(link, "ook", spikes_needed=1.0)
    assert mx["max_error_free_bps"] is not None
    # at least ~1 spike per on slot is needed, and no faster than one slot per tick
    assert mx["max_error_free_bps"] <= bounds["photon_limited_bps"] * 1.01
    assert mx["max_error_free_bps"] <= CLOCK
    assert mx["max_error_free_bps"] >= lc.theoretical_rate_limits(link, "ook", spikes_needed=8.0)["photon_limited_bps"]


# ------------------------------------------------------------------ bad input

def test_bitrate_above_clock_is_refused():
    link = lc.LightLink()
    with pytest.raises(ViformError, match="above what the readout clock"):
        lc.simulate_link(link, [1, 0, 1], 50e3, "ook")
    with pytest.raises(ViformError, match="at most 20000 bit/s"):
        lc.simulate_link(link, [1, 0, 1], 30e3, "ppm4")


def test_empty_payload_is_refused():
    with pytest.raises(ViformError, match="payload is empty"):
        lc.simulate_link(lc.LightLink(), [], 1e3, "ook")
    with pytest.raises(ViformError, match="payload is empty"):
        lc.bytes_to_bits(b"")


def test_unknown_modulation_is_refused():
    with pytest.raises(ViformError, match="not known to the receiver"):
        lc.simulate_link(lc.LightLink(), [1, 0], 1e3, "qam16")
    with pytest.raises(ViformError, match="not known to the receiver"):
        lc.get_modulation("ppm3")


def test_bad_link_parameters_are_refused():
    with pytest.raises(ViformError, match="distance_m"):
        lc.LightLink(distance_m=-1.0)
    with pytest.raises(ViformError, match="ambient_lux"):
        lc.LightLink(ambient_lux=-1.0)
    with pytest.raises(ViformError, match="extinction_ratio"):
        lc.LEDTransmitter(extinction_ratio=1.0)
    with pytest.raises(ViformError, match="bits must be 0 or 1"):
        lc.simulate_link(lc.LightLink(), [0, 2], 1e3)


def test_other_sensor_settings_pass_through():
    sensor = SpikeSensorParameters(optics=PixelOptics(pixel_pitch_m=20e-6), clock_hz=20e3)
    link = lc.LightLink(distance_m=20.0, sensor=sensor)
    r = lc.simulate_link(link, lc.random_bits(200, seed=9), 5e3, "ook", seed=9)
    assert r.slot_ticks == pytest.approx(4.0)
    assert r.bit_errors == 0
