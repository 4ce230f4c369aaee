"""CLI command: chip-figures — the spike chip's experiment figures from the model.

``viform chip-figures --out DIR`` films a person waving a hand with the SpikeTwo preset at
20 kHz and writes the spike-train, accumulation, interval and width-sequence figures
(seed 000 §6, Figs. 1, 3–5; see docs/chip-figures.md).
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from viform.cli.app import cli


def format_table(res: dict) -> str:
    lines = [f"{res['preset']}: {res['size_px']}x{res['size_px']} crop, {res['clock_hz'] / 1e3:g} kHz, "
             f"Q = {res['threshold_electrons']:,.0f} e-, {res['ticks']} ticks ({res['duration_s'] * 1e3:.3g} ms)",
             f"{'ticks':>6} {'window':>9} {'spikes/pixel':>13} {'pixels lit':>11} {'hand moves':>11}"]
    for n, a in res["accumulation"].items():
        lines.append(f"{n:>6} {a['window_s'] * 1e3:>6.3g} ms {a['mean_spikes_per_pixel']:>13.3g} "
                     f"{100 * a['pixels_with_spikes']:>10.3g}% {a['hand_travel_px']:>8.3g} px")
    iv = res["interval_at_last_tick"]
    lines.append(f"interval image at tick {res['ticks']}: τ {iv['tau_min_ticks']}–{iv['tau_max_ticks']} ticks → "
                 f"255 − τ ({iv['stretch']}); {100 * iv['censored_fraction']:.3g} % of intervals cut by the record")
    lines.append(f"spike-train example: 14 pulses, first spikes {', '.join(map(str, res['fig1']['first_spikes']))}")
    lines.append(f"wrote {', '.join(res['files'])} in {res['out']}")
    return "\n".join(lines)


@cli.command("chip-figures")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default="chip_figures", show_default=True,
              help="Folder for the figures.")
@click.option("--size", type=int, default=192, show_default=True,
              help="Side of the square crop of the 1000x1000 SpikeTwo array, pixels (smaller is faster).")
@click.option("--ticks", type=int, default=800, show_default=True, help="Ticks to record (800 = 40 ms at 20 kHz).")
@click.option("--stretch", type=click.Choice(["minmax", "percentile"]), default="minmax", show_default=True,
              help="Normalisation of τ before the 255 − τ display: min–max, or the 1st–99th percentiles.")
@click.option("--preset", default="spiketwo", show_default=True, help="Spike sensor preset (name or .json).")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--json", "as_json", is_flag=True, help="Print the numbers as JSON instead of the table.")
@click.option("--json-file", type=click.Path(dir_okay=False), default=None, help="Also write the JSON to this file.")
def chip_figures(out_dir, size, ticks, stretch, preset, seed, as_json, json_file):
    """Spike-camera experiment figures: a waving hand filmed at 20 kHz — spike train with first
    spikes, accumulation images of 1 to 800 ticks, the interval image (255 − τ), and the
    pulse-width sequences of ten pixels."""
    from viform._io import write_json
    from viform._validate import check_int
    from viform.report.chip_figures import chip_figures as make
    from viform.sensors.spike_presets import load_spike_preset

    check_int("size", size, 16, 1000)
    check_int("ticks", ticks, 50, 100_000)
    load_spike_preset(preset)  # validate before any work
    res = make(out_dir, size, ticks, stretch, seed, preset)
    res["out"] = str(Path(out_dir))
    if json_file:
        write_json(json_file, res)
    click.echo(json.dumps(res, indent=2) if as_json else format_table(res))
