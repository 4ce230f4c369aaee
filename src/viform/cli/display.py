"""CLI commands: lightcomm, display (registered on viform.cli.app.cli).

``viform lightcomm`` simulates a visible-light link received by the spike camera (seed 000
§7) and prints its budget, BER and maximum error-free rate; ``viform display`` compares the
spike continuous display with 60/120 Hz sample-and-hold displays and runs the pass-through
(capture → display) experiment.
"""

from __future__ import annotations

from pathlib import Path

import click

from viform._io import check_json_file, check_output_folder
from viform._validate import ViformError, check_int, check_non_negative, check_positive
from viform.cli.app import cli


def _check_outputs(json_path, out) -> None:
    """Refuse unusable --json-file/--out before any work, so a bad path leaves no figures behind."""
    if out is not None:
        check_output_folder("--out", Path(out))
    check_json_file(json_path)


def _emit(result: dict, print_table, as_json: bool, json_path) -> None:
    """The project's one convention: a table by default, ``--json`` to stdout, ``--json-file`` to a file."""
    import json

    from viform._io import _jsonable, write_json

    if as_json:
        click.echo(json.dumps(result, indent=2, default=_jsonable))
    else:
        print_table(result)
    if json_path:
        write_json(json_path, result)
        if not as_json:
            click.echo(f"wrote {json_path}")


def run_lightcomm(bitrate_bps: float = 10e3, modulation: str = "ook", distance_m: float = 100.0,
                  ambient_lux: float = 1.0, led_cd: float = 1.0, n_bits: int = 400, message: str | None = None,
                  seed: int = 0, clock_hz: float = 40e3, threshold_electrons: float = 100.0,
                  find_max: bool = True, sweeps: bool = False, out=None) -> dict:
    """Everything ``viform lightcomm`` reports; figures written to ``out`` when given."""
    from viform.display import lightcomm as lc
    from viform.sensors.spike import SpikeSensorParameters

    lc.get_modulation(modulation)
    check_positive("bitrate_bps", bitrate_bps)
    check_positive("led_cd", led_cd)
    check_non_negative("ambient_lux", ambient_lux)
    n_bits = check_int("n_bits", n_bits, 1)
    link = lc.LightLink(transmitter=lc.LEDTransmitter(luminous_intensity_cd=led_cd), distance_m=distance_m,
                        ambient_lux=ambient_lux,
                        sensor=SpikeSensorParameters(clock_hz=clock_hz, threshold_electrons=threshold_electrons))
    lc.check_rate(lc.get_modulation(modulation), bitrate_bps, clock_hz)
    if message is not None:
        bits = lc.bytes_to_bits(message.encode("utf-8"))
    else:
        bits = lc.random_bits(n_bits, seed)
    res, spikes = lc.simulate_link(link, bits, bitrate_bps, modulation, seed=seed, return_spikes=True)
    result = {"link": link.to_dict(), "transmission": res.summary(),
              "theory": {"rate_limits": lc.theoretical_rate_limits(link, modulation),
                         "starved_ber": lc.starved_ber(res.spikes_per_on_slot_pixel)}}
    if message is not None:
        received = lc.bits_to_bytes(res.bits_received)
        result["transmission"]["message_sent"] = message
        result["transmission"]["message_received"] = received.decode("utf-8", errors="replace")
    if find_max:
        mx = lc.max_error_free_rate(link, modulation, n_bits=min(n_bits, 400), seed=seed)
        result["max_error_free"] = mx
    if sweeps or out is not None:
        limit = clock_hz / lc.get_modulation(modulation).slots_per_bit
        rates = [limit / 2 ** (k / 2) for k in range(0, 13)]
        result["sweeps"] = {
            "bitrate_bps": lc.sweep(link, "bitrate_bps", rates, bitrate_bps, modulation, 300, seed),
            "distance_m": lc.sweep(link, "distance_m", [distance_m * 2 ** (k / 2) for k in range(-4, 9)],
                                   bitrate_bps, modulation, 300, seed),
            "ambient_lux": lc.sweep(link, "ambient_lux", [0.0] + [0.01 * 10 ** (k / 2) for k in range(0, 9)],
                                    bitrate_bps, modulation, 300, seed),
        }
    if out is not None:
        from viform.report import display_plots as dp

        out = Path(out)
        dp.plot_ber_sweeps(out / "lightcomm_ber.png", result["sweeps"], modulation)
        dp.plot_link_raster(out / "lightcomm_raster.png", res, spikes, clock_hz)
        result["figures"] = [str(out / "lightcomm_ber.png"), str(out / "lightcomm_raster.png")]
    return result


def _fmt(v, unit=""):
    if v is None:
        return "—"
    if isinstance(v, float):
        return f"{v:.4g}{unit}"
    return f"{v}{unit}"


def print_lightcomm(r: dict) -> None:
    lk, tx, th = r["link"], r["transmission"], r["theory"]["rate_limits"]
    click.echo(f"link: LED {lk['transmitter']['luminous_intensity_cd']:g} cd at {lk['distance_m']:g} m, "
               f"lens f={lk['lens']['focal_length_m'] * 1e3:g} mm f/{lk['lens']['f_number']:g}, "
               f"ambient {lk['ambient_lux']:g} lux on the sensor (a 50 % grey background lit by "
               f"{lk['ambient_scene_lux_grey50']:.3g} lux)")
    click.echo(f"  LED image {lk['image_diameter_m'] * 1e6:.3g} µm over {lk['led_pixels']} pixel(s); "
               f"brightest pixel {lk['led_on_peak_pixel_e_per_s']:.4g} e-/s "
               f"({lk['led_on_peak_pixel_e_per_s'] / lk['sensor']['threshold_electrons']:.4g} spikes/s), "
               f"ambient {lk['ambient_e_per_s']:.4g} e-/s, dark {lk['dark_e_per_s']:g} e-/s")
    click.echo(f"transmission: {tx['modulation']} at {tx['bitrate_bps']:g} bit/s ({tx['slot_ticks']:.3g} ticks/slot), "
               f"{tx['n_bits']} bits: {tx['bit_errors']} errors, BER {tx['ber']:.3g} "
               f"(95% upper bound {tx['ber_upper_95']:.3g})")
    click.echo(f"  spikes per slot: on {tx['mu_on_spikes']:.3g}, off {tx['mu_off_spikes']:.3g} "
               f"(theory, brightest pixel: {tx['expected_spikes_per_on_slot_pixel']:.3g}); "
               f"{tx['pixels_used']} pixel(s) used")
    if "message_sent" in tx:
        click.echo(f"  message sent {tx['message_sent']!r}, received {tx['message_received']!r}")
    click.echo(f"theory: photon limit (3 spikes per on slot) {th['photon_limited_bps']:.4g} bit/s, "
               f"clock limit (2 ticks per slot) {th['clock_limited_bps']:.4g} bit/s, "
               f"absolute clock limit {th['absolute_clock_limit_bps']:.4g} bit/s")
    if "max_error_free" in r:
        mx = r["max_error_free"]
        if mx["max_error_free_bps"] is None:
            click.echo("maximum error-free rate: none found down to "
                       f"{_fmt(mx.get('searched_down_to_bps'), ' bit/s')} (every rate tried had bit errors)")
        else:
            click.echo(f"maximum error-free rate: {_fmt(mx['max_error_free_bps'], ' bit/s')} "
                       f"(0 errors in {mx['n_bits_checked']} bits, BER < {_fmt(mx['ber_upper_95'])} at 95%)")
    if "sweeps" in r:
        for name, rows in r["sweeps"].items():
            label = {"bitrate_bps": "bit rate (bit/s)", "distance_m": "distance (m)",
                     "ambient_lux": "ambient light on the sensor (lux)"}.get(name, name)
            click.echo(f"bit-error rate against {label}: "
                       + ", ".join(f"{row[name]:.3g} → {row['ber']:.3g}" for row in rows))
    for f in r.get("figures", []):
        click.echo(f"wrote {f}")


@cli.command("lightcomm")
@click.option("--bitrate", "bitrate_bps", type=float, default=10e3, show_default=True, help="Bit rate, bit/s.")
@click.option("--modulation", default="ook", show_default=True,
              help="ook, manchester, ppm (= ppm4), ppm2, ppm4, ppm8, ppm16.")
@click.option("--distance-m", type=float, default=100.0, show_default=True, help="LED–camera distance, m.")
@click.option("--ambient-lux", type=float, default=1.0, show_default=True,
              help="Ambient illuminance on the sensor plane, lux.")
@click.option("--led-cd", type=float, default=1.0, show_default=True, help="LED luminous intensity when on, cd.")
@click.option("--bits", "n_bits", type=int, default=400, show_default=True, help="Random payload length, bits.")
@click.option("--message", default=None, help="Send this text (UTF-8) instead of random bits.")
@click.option("--clock-hz", type=float, default=40e3, show_default=True, help="Spike camera readout clock, Hz.")
@click.option("--threshold-electrons", type=float, default=100.0, show_default=True, help="Spike threshold Q, e-.")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--no-max", is_flag=True, help="Skip the search for the maximum error-free rate.")
@click.option("--sweeps", is_flag=True, help="Run the BER sweeps (always done with --out).")
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of the table.")
@click.option("--json-file", "json_path", type=click.Path(dir_okay=False), default=None,
              help="Also write the results as JSON to this file.")
@click.option("--out", type=click.Path(file_okay=False), default=None, help="Folder for figures.")
def lightcomm_command(bitrate_bps, modulation, distance_m, ambient_lux, led_cd, n_bits, message, clock_hz,
                      threshold_electrons, seed, no_max, sweeps, as_json, json_path, out):
    """Light communication: an LED sends bits (on-off keying, Manchester or pulse-position) to a spike camera.

    Prints the link budget, the bit-error rate, and the highest bit rate received without errors.
    """

    if message is not None and message == "":
        raise ViformError("--message is empty: give at least one character to transmit")
    _check_outputs(json_path, out)
    r = run_lightcomm(bitrate_bps, modulation, distance_m, ambient_lux, led_cd, n_bits, message, seed, clock_hz,
                      threshold_electrons, not no_max, sweeps, out)
    _emit(r, print_lightcomm, as_json, json_path)


def run_display(velocity_px_per_s: float = 600.0, eye_ms: float = 1000 / 60, link_latency_ticks: int = 0,
                seed: int = 0, out=None) -> dict:
    """Everything ``viform display`` reports; figures written to ``out`` when given."""
    from viform.display.passthrough import run_passthrough
    from viform.display.spike_display import compare_displays, moving_bars_scene

    check_positive("eye_ms", eye_ms)
    scene = moving_bars_scene(velocity_px_per_s=velocity_px_per_s)
    duration = max(0.06, 1.6 * eye_ms / 1e3)
    comp = compare_displays(scene, duration_s=duration, eye_integration_s=eye_ms / 1e3, seed=seed,
                            keep_arrays=out is not None)
    passthrough = run_passthrough(link_latency_ticks=link_latency_ticks, seed=seed, keep_arrays=out is not None)
    figures = []
    if out is not None:
        from viform.report import display_plots as dp

        out = Path(out)
        dp.plot_display_light_vs_time(out / "display_light_vs_time.png", comp)
        dp.plot_tracked_edges(out / "display_tracking_eye.png", comp)
        dp.plot_passthrough_step(out / "passthrough_step.png", passthrough)
        figures = [str(out / n) for n in ("display_light_vs_time.png", "display_tracking_eye.png",
                                          "passthrough_step.png")]
    comp.pop("arrays", None)
    passthrough.pop("arrays", None)
    for row in comp["displays"].values():
        row.pop("profile", None)
    return {"comparison": comp, "passthrough": passthrough, "figures": figures}


def print_display(r: dict) -> None:
    c, p = r["comparison"], r["passthrough"]
    sc = c["scene"]
    click.echo(f"scene: {sc['pattern']} (period {sc['period_px']:g} px, {sc['min_lux']:g}–{sc['max_lux']:g} lux) "
               f"moving at {sc['velocity_px_per_s']:g} px/s, {c['duration_s'] * 1e3:.3g} ms, "
               f"spike clock {c['clock_hz']:g} Hz, Q={c['threshold_electrons']:g} e-")
    windows = list(next(iter(v for k, v in c["displays"].items() if k != "truth"))["error_rel_rms"])
    click.echo(f"{'display':<14}" + "".join(f"{'err ' + w:>12}" for w in windows)
               + f"{'mean lux':>10}{'eye edge px':>13}{'theory px':>11}")
    click.echo(f"{'scene':<14}" + " " * 12 * len(windows) + f"{c['true_time_mean_lux']:>10.4f}"
               f"{c['displays']['truth']['tracked_edge_width_px']:>13.2f}{'':>11}")
    for name, row in c["displays"].items():
        if name == "truth":
            continue
        th = row.get("tracked_edge_width_theory_px")
        click.echo(f"{name:<14}" + "".join(f"{row['error_rel_rms'][w]:>12.4f}" for w in windows)
                   + f"{row['time_mean_lux']:>10.4f}{row['tracked_edge_width_px']:>13.2f}"
                   + (f"{th:>11.2f}" if th is not None else f"{'':>11}"))
    click.echo(f"{'  theory':<14}" + "".join(f"{c['displays']['spike']['error_rel_rms_theory'][w]:>12.4f}"
                                             for w in windows) + "  (spike display: √(N/Q + 1/6)/N)")
    click.echo(f"  (err = relative RMS of the light averaged over the window; eye = tracking eye integrating "
               f"{c['eye_integration_s'] * 1e3:.3g} ms; spike display dark bias "
               f"{c['spike_display_dark_bias_lux']:.2g} lux)")
    s, v = p["spike"], p["conventional"]
    click.echo(f"pass-through (spike camera → spike display, link {p['link_latency_ticks']} ticks): latency "
               f"{s['latency_s'] * 1e6:.3g} µs (theory {s['latency_theory_s'] * 1e6:.3g} µs); "
               + ", ".join(f"err {w} {e:.4f}" for w, e in s["error_rel_rms"].items()))
    click.echo(f"conventional ({p['frame_rate_hz']:g} Hz camera → hold display): latency "
               f"{v['latency_s'] * 1e3:.3g} ms (theory {v['latency_theory_s'] * 1e3:.3g} ms); "
               + ", ".join(f"err {w} {e:.4f}" for w, e in v["error_rel_rms"].items()))
    for f in r["figures"]:
        click.echo(f"wrote {f}")


@cli.command("display")
@click.option("--velocity", "velocity_px_per_s", type=float, default=600.0, show_default=True,
              help="Speed of the moving bars, px/s.")
@click.option("--eye-ms", type=float, default=round(1000 / 60, 2), show_default=True,
              help="Integration time of the tracking eye (or tracking camera exposure), ms.")
@click.option("--link-latency-ticks", type=int, default=0, show_default=True,
              help="Extra ticks of the camera → display link in the pass-through.")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of the table.")
@click.option("--json-file", "json_path", type=click.Path(dir_okay=False), default=None,
              help="Also write the results as JSON to this file.")
@click.option("--out", type=click.Path(file_okay=False), default=None, help="Folder for figures.")
def display_command(velocity_px_per_s, eye_ms, link_latency_ticks, seed, as_json, json_path, out):
    """A display that shows each spike as it comes, against 60 and 120 Hz frame displays.

    Moving bars are shown on each display; prints the light error over short windows and the
    edge blur a tracking eye sees, then the camera-to-display latency of a spike pass-through.
    """

    check_int("link_latency_ticks", link_latency_ticks, 0, 600)
    _check_outputs(json_path, out)
    r = run_display(velocity_px_per_s, eye_ms, link_latency_ticks, seed, out)
    _emit(r, print_display, as_json, json_path)
