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
@click.option("--json", "as_json", is_flag=True, help="print JSON")
@click.option("--shortest", type=float, default=None, help="τ̌, s: compute DR for these values instead")
@click.option("--longest", type=float, default=None, help="τ̂, s")
@click.option("--sensitivity", type=float, default=None, help="τ̆, s (sub-threshold)")
@click.option("--levels", type=int, default=None, help="N sub-threshold levels")
@click.option("--measure", is_flag=True, help="also measure DR on a simulated spike sensor")
def dr_cmd(as_json, shortest, longest, sensitivity, levels, measure):
    """Dynamic range of spike continuous photography (seed 000 §4.2–§4.5)."""
    from viform.measure import dynamic_range as dr

    out = {"seed_examples": dr.seed_examples()}
    if shortest is not None:
        if longest is not None:
            out["dr_db"] = dr.dynamic_range_db(shortest, longest)
        if sensitivity is not None and levels is not None:
            out["subthreshold_dr_db"] = dr.subthreshold_dynamic_range_db(shortest, sensitivity, levels)
    if measure:
        out["measured"] = dr.measure_spike_dynamic_range()
    if as_json:
        click.echo(json.dumps(out, indent=2, ensure_ascii=False))
        return
    for ex in out["seed_examples"]:
        if "seed_db" in ex:
            click.echo(f"{ex['example']}: {ex['computed_db']:.1f} dB (seed: {ex['seed_db']:g} dB)")
        else:
            click.echo(f"{ex['example']}: {ex['computed_ns']:.2f} ns (seed: {ex['seed_ns']:g} ns)")
    if "dr_db" in out:
        click.echo(f"DR(τ̌={shortest:g} s, τ̂={longest:g} s) = {out['dr_db']:.2f} dB")
    if "subthreshold_dr_db" in out:
        click.echo(f"sub-threshold DR = {out['subthreshold_dr_db']:.2f} dB")
    if measure:
        m = out["measured"]
        click.echo(f"simulated sensor (Q={m['threshold_electrons']:g}, Id={m['dark_current_e_per_s']:g} e/s): "
                   f"measured {m['dr_measured_db']:.2f} dB, formula {m['dr_formula_db']:.2f} dB "
                   f"(±{m['tolerance_db']:.2f} dB)")
