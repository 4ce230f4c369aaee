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
    """20 m, 1 cd: λT/Q ≈ 160 (OOK) / 80 (4-PPM, Manchester) per on slot at 5 kbit/s, so an on
    slot fires in every tick (8 / 4 ticks; the readout ceiling), while ambient 1 lux gives 0.6
    / 0.3 spikes per slot (+ ≤ 1 from the tick straddling an on slot's edge).

    0 errors in 1000 bits by itself only bounds the BER below 3.0·10⁻³ (95 %); the margin is
    what makes "error-free" a fair claim: on counts 7–8, off counts 0–2, θ ≈ 4.5 (OOK)."""
    link = lc.LightLink(distance_m=20.0, ambient_lux=1.0)
    r = lc.simulate_link(link, lc.random_bits(1000, seed=1), 5e3, modulation, seed=1)
    assert r.bit_errors == 0
    assert r.summary()["ber_upper_95"] == pytest.approx(3.0e-3, rel=0.01)
    assert r.spikes_per_on_slot_pixel > 10


def test_text_message_round_trip():
    link = lc.LightLink(distance_m=30.0, ambient_lux=0.3)
    msg = "光通信 spike link".encode()
    r = lc.simulate_link(link, lc.bytes_to_bits(msg), 4e3, "ppm", seed=2)
    assert lc.bits_to_bytes(r.bits_received) == msg


def _starved_count_tol(n_on_slots: int, nbar: float) -> float:
    """4σ of the spikes fired in ``n_on_slots`` on slots (Var = N/Q + 1/6, N = n_on·n̄; module
    docstring) plus one for the start-up charge and a stray dark spike."""
    return 4 * np.sqrt(n_on_slots * nbar / Q + 1 / 6) + 1


@pytest.mark.parametrize("nbar", [0.25, 0.5, 0.75])
def test_ook_ber_follows_photon_starved_theory(nbar):
    """Each on slot fires with probability n̄ = λT/Q and off slots never: misses = n_on·(1 − n̄)
    almost exactly (the integrator's charge carries over: misses are regular, not Bernoulli), so
    BER = ½(1 − n̄) up to the payload's share of ones (4σ = 4·½(1 − n̄)/√n). A Poisson receiver
    (½e^(−n̄)) would be off by 20–100 σ of the miss count."""
    slot_s = 4 / CLOCK
    link = link_with_spikes_per_slot(nbar, slot_s)
    n = 3000
    bits = lc.random_bits(n, seed=7)
    r = lc.simulate_link(link, bits, 1 / slot_s, "ook", seed=7, phase_ticks=0.0)
    assert r.spikes_per_on_slot_pixel == pytest.approx(nbar, rel=1e-6)
    n_on = int(bits.sum())
    misses = np.count_nonzero((bits == 1) & (r.bits_received == 0))
    assert abs(misses - n_on * (1 - nbar)) < _starved_count_tol(n_on, nbar)
    assert np.count_nonzero((bits == 0) & (r.bits_received == 1)) <= 1
    assert abs(r.ber - lc.starved_ber(nbar)) < 4 * 0.5 * (1 - nbar) / np.sqrt(n)


@pytest.mark.parametrize("nbar", [0.25, 0.6])
def test_ppm_ber_follows_photon_starved_theory(nbar):
    """Lost symbols = n_sym·(1 − n̄) (count tolerance as for OOK); each decodes as slot 0 and costs
    the Hamming weight of the sent index (mean 1, variance ½ for 4-PPM): BER = ½(1 − n̄) within
    4·√(n_lost·½)/n."""
    slot_s = 4 / CLOCK
    link = link_with_spikes_per_slot(nbar, slot_s)
    n = 3000
    bits = lc.random_bits(n, seed=8)
    r = lc.simulate_link(link, bits, 1 / (2 * slot_s), "ppm4", seed=8, phase_ticks=0.0)
    n_sym = n // 2
    fired = np.count_nonzero(r.counts.reshape(n_sym, 4).max(axis=1) > 0)
    assert abs((n_sym - fired) - n_sym * (1 - nbar)) < _starved_count_tol(n_sym, nbar)
    n_lost = n_sym * (1 - nbar)
    assert abs(r.ber - lc.starved_ber(nbar)) < 4 * np.sqrt(n_lost * 0.5) / n + _starved_count_tol(n_sym, nbar) / n


def test_ber_rises_as_light_falls_below_one_spike_per_slot():
    slot_s = 4 / CLOCK
    bers = [lc.simulate_link(link_with_spikes_per_slot(nb, slot_s), lc.random_bits(800, seed=3), 1 / slot_s,
                             "ook", seed=3).ber for nb in (8.0, 0.6, 0.15)]
    assert bers[0] == 0.0
    assert bers[0] < bers[1] < bers[2]
    assert bers[2] > lc.starved_ber(0.15) - 4 * 0.5 * 0.85 / np.sqrt(800)  # ½(1 − 0.15) = 0.425


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


def test_sub_spike_background_costs_a_starved_link_but_not_a_bright_one():
    """Far below the clock's ceiling (8-tick slots), a background of b = ½ spike per slot: with
    n̄_on = 1, θ = 1 and the off counts are 0 or 1 with probability ½ each (phase quantisation),
    so BER ≈ ½·frac(b) = ¼ (4σ binomial, + 0.02 for the spikes of ticks straddling a slot edge);
    with n̄_on = 4 the same background leaves a margin of 2 spikes and no errors."""
    slot_s = 8 / CLOCK
    n = 2000

    def run(nbar, b):
        link = link_with_spikes_per_slot(nbar, slot_s)
        lk = replace(link, ambient_lux=b * Q / (link.optics.electrons_per_lux_second * slot_s))
        return lc.simulate_link(lk, lc.random_bits(n, seed=6), 1 / slot_s, "ook", seed=6)

    assert abs(run(1.0, 0.5).ber - 0.25) < 4 * np.sqrt(0.25 * 0.75 / n) + 0.02
    assert run(4.0, 0.5).bit_errors == 0


def test_max_error_free_rate_between_photon_and_clock_bounds():
    link = lc.LightLink(distance_m=100.0, ambient_lux=0.1)
    mx = lc.max_error_free_rate(link, "ook", n_bits=300, seed=0)
    bounds = lc.theoretical_rate_limits(link, "ook", spikes_needed=1.0)
    assert mx["max_error_free_bps"] is not None
    # at least ~1 spike per on slot is needed, and no faster than one slot per tick
    assert mx["max_error_free_bps"] <= bounds["photon_limited_bps"] * 1.01
    assert mx["max_error_free_bps"] <= CLOCK
    assert mx["max_error_free_bps"] >= lc.theoretical_rate_limits(link, "ook", spikes_needed=8.0)["photon_limited_bps"]


def test_max_error_free_search_stops_at_its_tick_budget():
    """A link with errors at every rate: the search stops once its tries cost the budget of sensor ticks
    (slower rates cost more ticks per bit) and says how far down it went."""
    link = lc.LightLink(distance_m=1e5, ambient_lux=0.1)  # far too far: errors at every rate
    n_bits = 100
    mx = lc.max_error_free_rate(link, "ook", n_bits=n_bits, seed=0, max_ticks=2e5)
    assert mx["max_error_free_bps"] is None and mx["tried"]
    spent = sum(2 * n_bits * CLOCK / t["bitrate_bps"] for t in mx["tried"])
    assert spent <= 2e5 or len(mx["tried"]) == 1
    assert mx["searched_down_to_bps"] == mx["tried"][-1]["bitrate_bps"] > CLOCK / 4096


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
