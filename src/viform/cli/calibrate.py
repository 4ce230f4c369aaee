"""CLI: ``viform calibrate`` — fit a spike-sensor preset to a recording of a steady scene."""

from __future__ import annotations

import json
import math
import textwrap
from pathlib import Path

import click

from viform._validate import size_text
from viform.cli._common import spike_file_options
from viform.cli.app import cli


def _fmt(value, digits: int = 4) -> str:
    return "—" if value is None else f"{value:.{digits}g}"


def _level_line(q, bound: bool = False) -> str | None:
    """The chip threshold level that matches ``q``: the nearest in ratio, or "below/above" the range."""
    if not q:
        return None
    from viform.sensors.spike_presets import threshold_levels_electrons

    levels = threshold_levels_electrons()
    lo, hi = min(levels), max(levels)
    if q < lo / 1.5 and bound:
        return f"(the chip's lowest threshold level is {lo:,.0f} e⁻, level {levels.index(lo)})"
    if q < lo / 1.5:
        return f"below the chip's lowest threshold level ({lo:,.0f} e⁻ at level {levels.index(lo)})"
    if q > hi * 1.5:
        return f"above the chip's highest threshold level ({hi:,.0f} e⁻ at level {levels.index(hi)})"
    k = min(range(len(levels)), key=lambda i: abs(math.log(levels[i] / q)))
    return f"nearest chip threshold level: {k} ({levels[k]:,.0f} e⁻)"


def _lines(file, r: dict, out) -> list[str]:
    th, gs, d, dark = r["threshold"], r["gain_spread"], r["defects"], r["dark_current"]
    st = r["static"]
    lines = [f"spike-stream calibration of {file}",
             f"  {size_text(r['height'], r['width'], 'pixels')}, {r['n_ticks']} ticks at {r['clock_hz'] / 1e3:.4g} kHz "
             f"({r['duration_s'] * 1e3:.4g} ms), mean firing rate {r['mean_firing_rate_per_tick']:.4g} per tick",
             ""]
    if r["n_ticks"] < r["recording_ticks"]:
        lines.insert(2, f"  (the first {r['n_ticks']} of {r['recording_ticks']} ticks: enough spikes for every figure)")
    frac = st.get("static_fraction_of_judged")
    lines.append(f"  {'steady tiles':<22}{_fmt(None if frac is None else 100 * frac)} % of {st['tiles_judged']} "
                 "tiles judged (successive intervals anti-correlated)")
    level = _level_line(th.get("q_eff_electrons") or th.get("q_eff_lower_bound_electrons"),
                        bound=not th.get("q_eff_electrons"))
    if th.get("q_eff_electrons"):
        lo, hi = th["q_eff_range_electrons"]
        lines.append(f"  {'effective threshold':<22}{th['q_eff_electrons']:,.0f} e⁻  "
                     f"(95 % range {lo:,.0f} – {hi:,.0f})")
    elif th.get("q_eff_lower_bound_electrons"):
        lines.append(f"  {'effective threshold':<22}≥ {th['q_eff_lower_bound_electrons']:,.0f} e⁻  (a lower bound)")
        lines += [f"  {'':<22}{part}" for part in textwrap.wrap(th["reason"], 72)]
    else:
        lines.append(f"  {'effective threshold':<22}not estimated: {th.get('reason')}")
    if level is not None:
        lines.append(f"  {'':<22}{level}")
    g = gs.get("gain_spread_fraction")
    lines.append(f"  {'flat-field spread':<22}" + (f"{100 * g:.3g} % (pixel-to-pixel gain spread; an upper bound "
                                                  "where the scene has fine texture)" if g is not None
                                                  else f"not estimated: {gs.get('reason')}"))
    levels = gs.get("spread_by_level") or []
    if levels:
        lines.append(f"  {'':<22}median tile spread by light level: " + ", ".join(
            f"{100 * v['median_spread']:.3g} % at {v['mean_interval_ticks']:.3g} ticks" for v in levels))
    if d.get("hot_pixel_dark_current_e_per_s") and d.get("hot_pixel_fraction"):
        lines.append(f"  {'hot pixels':<22}{d['hot_pixels']} found, about "
                     f"{d['hot_pixel_dark_current_e_per_s']:.3g} e⁻/s of dark current each; "
                     f"{100 * d['hot_pixel_fraction']:.3g} ± "
                     f"{100 * d['hot_pixel_fraction_standard_error']:.2g} % of the {d['hot_pixel_searchable_pixels']} "
                     "pixels dark or smooth enough to show them")
    elif d.get("hot_pixel_fraction_upper_bound") is not None:
        lines.append(f"  {'hot pixels':<22}{d['hot_pixels']} reported, fewer than "
                     f"{100 * d['hot_pixel_fraction_upper_bound']:.2g} % of pixels (95 %, a bound): "
                     f"{d.get('hot_pixel_reason', '')}")
    elif d.get("hot_pixel_bound"):
        hb = d["hot_pixel_bound"]
        lines.append(f"  {'hot pixels':<22}none with ≥ {hb['dark_current_at_least_e_per_s']:.3g} e⁻/s of dark current "
                     f"(fewer than {100 * hb['fraction_upper_bound']:.2g} % of pixels, 95 %); weaker ones hide "
                     "under the light")
    else:
        lines.append(f"  {'hot pixels':<22}{d['hot_pixels']} reported: {d.get('hot_pixel_reason', '')}")
    if d.get("hot_pixels"):
        lines.append(f"  {'':<22}{100 * d['hot_pixels_with_reported_neighbour_fraction']:.3g} % of them have another "
                     f"report within 1.5 px ({100 * d['hot_pixels_with_reported_neighbour_if_random']:.2g} % if placed "
                     "at random)")
    lines.append(f"  {'dead pixels':<22}{d['dead_pixels']} ({100 * d['dead_pixel_fraction']:.3g} %)")
    bound = dark.get("dark_current_upper_bound_e_per_s")
    lines.append(f"  {'dark current':<22}not measurable" + (f" (≤ {bound:.3g} e⁻/s)" if bound else "")
                 + f": {dark['reason']}")
    if r["interval_table"]:
        lines += ["", "  intervals of steady tiles, by mean interval:",
                  f"  {'mean interval':>14} {'pixels':>7} {'RSD':>7} {'RSD detr.':>9} {'lag-1 corr':>10} "
                  f"{'steady pixel':>12}"]
        for row in r["interval_table"]:
            exp = row.get("expected_lag1_correlation")
            lines.append(f"  {row['mean_interval_ticks']:>8.4g} ticks {row['pixels']:>7d} {row['rsd']:>7.3g} "
                         f"{row['rsd_detrended']:>9.3g} {row['lag1_correlation']:>10.2f} "
                         f"{'' if exp is None else format(exp, '.2f'):>12}")
    if out is not None:
        lines += ["", f"  preset written to {out} (use: viform simulate --preset {out} …)"]
        q_file = r.get("recorded_threshold_electrons")
        if q_file and not th.get("q_eff_electrons") and not th.get("q_eff_lower_bound_electrons"):
            lines.append(f"  its threshold, {q_file:,.0f} e⁻, is the one the recording's metadata states, "
                         "not a measurement")
    return lines


@cli.command()
@click.argument("recording", type=click.Path(exists=True))
@click.option("--out", "out_path", type=click.Path(dir_okay=False), default=None,
              help="Write the fitted spike-sensor preset here (.json).")
@click.option("--name", default=None, help="Preset name (default: the recording's file name).")
@click.option("--max-ticks", type=int, default=None, help="Use only the first N ticks of the recording.")
@spike_file_options()
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of the table.")
@click.option("--json-file", type=click.Path(dir_okay=False), default=None, help="Also write the JSON to this file.")
def calibrate(recording, out_path, name, max_ticks, height, width, no_flip, clock_hz, key, axes, as_json, json_file):
    """Fit a spike-sensor preset to RECORDING, a spike stream of a (mostly) steady scene.

    Estimates the effective threshold (from how regular each pixel's intervals are, after
    the rounding to readout ticks), the flat-field gain spread, hot and dead pixels, and
    says for each figure when the recording is too short or not steady enough to give it.
    """
    from viform._io import check_json_file, check_output_folder, write_json
    from viform._validate import ViformError, check_int
    from viform.cli._common import open_source
    from viform.measure.calibration import calibrate as run
    from viform.measure.calibration import preset_from_calibration
    from viform.sensors.spike_presets import save_spike_preset

    if out_path is not None:
        if Path(out_path).suffix.lower() != ".json":
            raise ViformError(f"--out = {out_path!r} is not allowed: give a .json file for the preset")
        check_output_folder("--out", Path(out_path).resolve().parent)
    check_json_file(json_file)
    if max_ticks is not None:
        check_int("--max-ticks", max_ticks, 20)
    source = open_source(recording, height, width, clock_hz, flip=not no_flip, key=key, axes=axes)
    result = run(source, max_ticks=max_ticks)
    result["source"] = str(recording)
    if out_path is not None:
        try:
            preset = preset_from_calibration(result, name or Path(recording).stem)
        except ViformError as exc:
            raise ViformError(f"--out {out_path}: {exc}") from None
        save_spike_preset(out_path, preset)
        result["preset"] = str(out_path)
    if json_file is not None:
        write_json(json_file, result)
    if as_json:
        click.echo(json.dumps(result, indent=2))
    else:
        click.echo("\n".join(_lines(recording, result, out_path)))
