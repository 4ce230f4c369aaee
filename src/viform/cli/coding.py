"""CLI commands: encode, decode, dr (registered on viform.cli.app.cli).

``viform encode IN OUT [--mode]`` codes a viform (.dat/.npz/.zarr) into a first-spike coded
``.vfc`` file (seed 000 §5.2); ``viform decode IN OUT`` regenerates the stream;
``viform dr`` prints the seed's dynamic-range figures (§4.2–§4.5).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from viform._validate import ViformError
from viform.cli.app import cli


@cli.command("encode")
@click.argument("src", type=click.Path())
@click.argument("dst", type=click.Path())
@click.option("--mode", type=click.Choice(["strict", "statistical", "intensity"]), default="strict",
              show_default=True, help="strict: lossless; statistical: |Δτ| ≤ k·τ/√Q are repeats; "
                                      "intensity: transitional first spikes dropped")
@click.option("--k", "k", type=float, default=None, help="tolerance factor k (default 2)")
@click.option("--threshold", type=float, default=None, help="threshold Q, e⁻ (if the file does not say)")
@click.option("--slack", type=int, default=0, show_default=True, help="extra tolerance, ticks (lossy modes)")
@click.option("--height", type=int, default=None, help=".dat height")
@click.option("--width", type=int, default=None, help=".dat width")
@click.option("--segment-ticks", type=int, default=None, help="segment length of the coded file")
@click.option("--json", "as_json", is_flag=True, help="print the summary as JSON")
def encode_cmd(src, dst, mode, k, threshold, slack, height, width, segment_ticks, as_json):
    """Code the viform SRC into the first-spike coded file DST (.vfc)."""
    from viform.coding.aer_file import EXTENSION, encode_source
    from viform.stream.io import open_spikes

    if Path(dst).suffix.lower() != EXTENSION:
        raise ViformError(f"output {dst!r} must end in {EXTENSION}")
    source = open_spikes(src, height, width)
    t0 = time.perf_counter()
    summary = encode_source(source, dst, mode, k=k, threshold_electrons=threshold, slack_ticks=slack,
                            segment_ticks=segment_ticks, progress=True)
    summary["seconds"] = time.perf_counter() - t0
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    else:
        click.echo(f"{dst}: {summary['bytes']} bytes, {summary['ratio_vs_raw']:.2f}× smaller than the raw bits "
                   f"({mode} mode, {summary['spikes']} spikes, {summary['seconds']:.2f} s)")


@cli.command("decode")
@click.argument("src", type=click.Path())
@click.argument("dst", type=click.Path())
def decode_cmd(src, dst):
    """Regenerate the spike stream of the coded file SRC into DST (.dat/.npz/.zarr)."""
    from viform.coding.aer_file import CodedFile
    from viform.stream.io import save_spikes

    coded = CodedFile(src)
    save_spikes(dst, coded)
    click.echo(f"{dst}: {coded.n_ticks} ticks × {coded.height}×{coded.width} ({coded.mode} coding)")


@cli.command("dr")
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of the table.")
@click.option("--threshold-electrons", type=float, default=None,
              help="Your sensor's threshold Q, electrons (with --dark-current-e-per-s gives the longest interval).")
@click.option("--clock-hz", type=float, default=None,
              help="Your sensor's readout clock, Hz (gives the shortest interval, 1/clock).")
@click.option("--dark-current-e-per-s", type=float, default=None, help="Your sensor's dark current, e-/s.")
@click.option("--shortest", type=float, default=None,
              help="Shortest interval the readout resolves, s (default: 1/--clock-hz).")
@click.option("--longest", type=float, default=None,
              help="Longest interval still set by light, s (default: Q / dark current).")
@click.option("--sensitivity", type=float, default=None, help="Sub-threshold read period, s.")
@click.option("--levels", type=int, default=None, help="Number of sub-threshold levels.")
@click.option("--measure", is_flag=True, help="Also measure the DR of a simulated spike sensor.")
def dr_cmd(as_json, threshold_electrons, clock_hz, dark_current_e_per_s, shortest, longest, sensitivity, levels,
           measure):
    """Dynamic range of spike continuous photography: the worked examples, and your sensor's.

    The DR is the ratio of the longest interval still set by light (Q over the dark current)
    to the shortest one the readout resolves (one clock period); sub-threshold readout of the
    partial charge extends it at the dark end.
    """
    from viform._validate import ViformError, check_positive
    from viform.measure import dynamic_range as dr

    if clock_hz is not None:
        check_positive("--clock-hz", clock_hz)
        shortest = 1.0 / clock_hz if shortest is None else shortest
    if threshold_electrons is not None or dark_current_e_per_s is not None:
        if threshold_electrons is None or dark_current_e_per_s is None:
            raise ViformError("--threshold-electrons and --dark-current-e-per-s go together: the longest "
                              "interval is Q / dark current; give both")
        check_positive("--threshold-electrons", threshold_electrons)
        check_positive("--dark-current-e-per-s", dark_current_e_per_s)
        longest = threshold_electrons / dark_current_e_per_s if longest is None else longest
    if (shortest is None) != (longest is None):
        given, missing = ("--shortest", "--longest (or --threshold-electrons with --dark-current-e-per-s)") \
            if shortest is not None else ("--longest", "--shortest (or --clock-hz)")
        raise ViformError(f"{given} alone gives no dynamic range: also give {missing}")
    if (sensitivity is None) != (levels is None):
        raise ViformError("--sensitivity and --levels go together (the sub-threshold read period and its levels)")
    out = {"seed_examples": dr.seed_examples()}
    if shortest is not None:
        check_positive("--shortest", shortest)
        check_positive("--longest", longest)
        if longest <= shortest:
            raise ViformError(f"--longest = {longest:g} s is not allowed: it must exceed --shortest = {shortest:g} s")
        out["shortest_interval_s"], out["longest_interval_s"] = shortest, longest
        out["dr_db"] = dr.dynamic_range_db(shortest, longest)
        if sensitivity is not None:
            out["subthreshold_dr_db"] = dr.subthreshold_dynamic_range_db(shortest, sensitivity, levels)
    elif sensitivity is not None:
        raise ViformError("--sensitivity/--levels need the shortest interval: give --shortest or --clock-hz")
    if measure:
        out["measured"] = dr.measure_spike_dynamic_range()
    if as_json:
        click.echo(json.dumps(out, indent=2, ensure_ascii=False))
        return
    click.echo(f"{'worked example':<58}{'computed':>12}{'paper':>10}")
    for ex in out["seed_examples"]:
        if "seed_db" in ex:
            click.echo(f"{ex['example'][:57]:<58}{ex['computed_db']:>9.1f} dB{ex['seed_db']:>7g} dB")
        else:
            click.echo(f"{ex['example'][:57]:<58}{ex['computed_ns']:>9.2f} ns{ex['seed_ns']:>7g} ns")
    if "dr_db" in out:
        click.echo(f"your sensor: shortest interval {shortest:.4g} s, longest {longest:.4g} s → "
                   f"dynamic range {out['dr_db']:.1f} dB")
    if "subthreshold_dr_db" in out:
        click.echo(f"with sub-threshold readout ({levels} levels every {sensitivity:.4g} s): "
                   f"{out['subthreshold_dr_db']:.1f} dB")
    if measure:
        m = out["measured"]
        click.echo(f"simulated sensor (Q = {m['threshold_electrons']:g} e-, dark current "
                   f"{m['dark_current_e_per_s']:g} e-/s): measured {m['dr_measured_db']:.2f} dB, formula "
                   f"{m['dr_formula_db']:.2f} dB (±{m['tolerance_db']:.2f} dB)")
