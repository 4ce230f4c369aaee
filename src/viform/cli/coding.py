"""CLI commands: encode, decode, dr (registered on viform.cli.app.cli).

``viform encode IN OUT [--mode]`` codes a spike stream (.dat/.npz/.zarr) into a first-spike
coded ``.vfc`` file (seed 000 §5.2); ``viform decode IN OUT`` regenerates the stream;
``viform dr`` prints the dynamic-range figures of spike photography (seed 000 §4.2–§4.5).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

# one rule for every command's --json-file (missing folders are created, as for --out)
from viform._io import check_json_file
from viform._validate import ViformError, size_text
from viform.cli._common import spike_file_options
from viform.cli.app import cli


def _emit(summary: dict, as_json: bool, json_file, line: str) -> None:
    """The command's result: JSON on stdout (``--json``) or the human line, and ``--json-file``."""
    if json_file is not None:
        from viform._io import write_json

        write_json(json_file, summary)
    click.echo(json.dumps(summary, indent=2, ensure_ascii=False) if as_json else line)


def _announce_compile() -> None:
    """The compile notice, on stderr, at the moment a coding kernel really is compiled (not loaded)."""
    from viform.coding._compile_cache import COMPILING_NOTICE, announce_compiles

    announce_compiles(lambda: click.echo(COMPILING_NOTICE, err=True))


_JSON_OPTIONS = (
    click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of the text."),
    click.option("--json-file", type=click.Path(dir_okay=False), default=None,
                 help="Also write the JSON that --json prints to this file."),
)


def _json_options(f):
    for option in reversed(_JSON_OPTIONS):
        f = option(f)
    return f


def _check_tolerance(threshold, k, slack) -> None:
    """--threshold, --k and --slack before any file is opened (the tolerance is k·τ/√Q + slack)."""
    import math

    from viform.stream.sidecar import MAX_THRESHOLD_ELECTRONS

    if threshold is not None and not (math.isfinite(threshold) and 0 < threshold <= MAX_THRESHOLD_ELECTRONS):
        raise ViformError(f"--threshold = {threshold:g} is not allowed: give the threshold Q in electrons, a number "
                          f"in (0, {MAX_THRESHOLD_ELECTRONS:g}]")
    if k is not None and not (math.isfinite(k) and 0 <= k <= 1e6):
        raise ViformError(f"--k = {k:g} is not allowed: give a tolerance factor in [0, 1e6] (standard deviations)")
    if not 0 <= slack <= 1 << 20:
        raise ViformError(f"--slack = {slack} is not allowed: give a whole number of ticks in [0, {1 << 20}]")


@cli.command("encode")
@click.argument("src", type=click.Path())
@click.argument("dst", type=click.Path())
@click.option("--mode", type=click.Choice(["strict", "statistical", "intensity"]), default="strict",
              show_default=True,
              help="strict: lossless. statistical: an interval within k·τ/√Q of the previous one (τ the "
                   "interval, Q the threshold) is coded as a repeat. intensity: like statistical, and the "
                   "transitional first spikes after a light change are dropped.")
@click.option("--k", "k", type=float, default=None,
              help="Tolerance factor k of the lossy modes: intervals within k·τ/√Q count as a repeat "
                   "(k standard deviations of the photon noise).  [default: 2]")
@click.option("--threshold", type=float, default=None,
              help="Threshold Q, electrons, when the file does not record it (lossy modes).  "
                   "[allowed: > 0 to 1e12 e-]")
@click.option("--slack", type=int, default=0, show_default=True,
              help="Extra tolerance of the lossy modes, ticks.")
@spike_file_options()
@click.option("--segment-ticks", type=int, default=None,
              help="Ticks per independently decodable segment of the coded file (≥ 1).  [default: 4096, "
                   "fewer for sensors above 8,192 pixels in strict mode: a segment holds at most 2^25 "
                   "pixel-ticks by default and 2^28 if you set it]")
@click.option("--fast", is_flag=True,
              help="Strict mode: write format version 5 with its interval model on every band of rows instead of "
                   "version 6's tick model (about 2× faster to encode and 1.7× to decode; files 7 % larger on "
                   "a typical stream, up to 50 % where every pixel fires every tick).")
@_json_options
def encode_cmd(src, dst, mode, k, threshold, slack, height, width, no_flip, clock_hz, key, axes, segment_ticks, fast,
               as_json, json_file):
    """Code the spike stream SRC into the first-spike coded file DST (.vfc)."""
    from viform._validate import check_int
    from viform.cli._common import open_source
    from viform.coding.aer_file import EXTENSION, encode_source

    if Path(dst).suffix.lower() != EXTENSION:
        raise ViformError(f"output {dst!r} must end in {EXTENSION}")
    if segment_ticks is not None:
        check_int("--segment-ticks", segment_ticks, 1)
    _check_tolerance(threshold, k, slack)
    check_json_file(json_file)
    source = open_source(src, height, width, clock_hz, flip=not no_flip, key=key, axes=axes)
    if segment_ticks is not None and mode == "strict":
        from viform.coding.aer_file import MAX_SEGMENT_PIXEL_TICKS

        n_pixels = source.height * source.width
        if segment_ticks * n_pixels > MAX_SEGMENT_PIXEL_TICKS:
            raise ViformError(f"--segment-ticks = {segment_ticks} is not allowed for "
                              f"{size_text(source.height, source.width, 'pixels')}: a segment is held in memory "
                              f"while it is coded; give at most "
                              f"{MAX_SEGMENT_PIXEL_TICKS // n_pixels} ticks")
    _announce_compile()
    t0 = time.perf_counter()
    summary = encode_source(source, dst, mode, k=k, threshold_electrons=threshold, slack_ticks=slack,
                            segment_ticks=segment_ticks, progress=True, fast=fast)
    summary["seconds"] = time.perf_counter() - t0
    _emit(summary, as_json, json_file,
          f"{dst}: {summary['bytes']:,} bytes, {summary['ratio_vs_raw']:.3g}× smaller than the raw bits "
          f"({mode} mode, {summary['spikes']:,} spikes, {summary['seconds']:.3g} s)")


@cli.command("decode")
@click.argument("src", type=click.Path())
@click.argument("dst", type=click.Path())
@_json_options
def decode_cmd(src, dst, as_json, json_file):
    """Regenerate the spike stream of the coded file SRC into DST (.dat/.npz/.zarr)."""
    from viform.coding.aer_file import CodedFile
    from viform.stream.io import save_spikes

    check_json_file(json_file)
    coded = CodedFile(src)
    _announce_compile()
    t0 = time.perf_counter()
    save_spikes(dst, coded)
    summary = {"path": str(dst), "source": str(src), "mode": coded.mode, "n_ticks": int(coded.n_ticks),
               "height": int(coded.height), "width": int(coded.width), "clock_hz": float(coded.clock_hz),
               "seconds": time.perf_counter() - t0}
    _emit(summary, as_json, json_file,
          f"{dst}: {coded.n_ticks:,} ticks × {size_text(coded.height, coded.width, 'pixels')} ({coded.mode} coding)")


#: Plain-language labels of the worked examples, in the order of ``seed_examples()``.
_EXAMPLE_LABELS = (
    "shortest interval 10 ns, longest interval 1 s",
    "shortest interval 10 ns, longest interval 10 s",
    "sub-threshold readout: shortest 10 ns, 100 levels every 10 ms",
    "shortest interval at 100 000 lux (Q 100 e-, 100 µm², QE 0.7)",
)


@cli.command("dr")
@_json_options
@click.option("--threshold-electrons", type=float, default=None,
              help="Your sensor's threshold Q, electrons (with --dark-current-e-per-s gives the longest interval).")
@click.option("--clock-hz", type=float, default=None,
              help="Your sensor's readout clock, Hz (gives the shortest interval, 1/clock).")
@click.option("--dark-current-e-per-s", type=float, default=None, help="Your sensor's dark current, e-/s.")
@click.option("--shortest", type=float, default=None,
              help="Shortest interval the readout resolves, s (default: 1/--clock-hz).")
@click.option("--longest", type=float, default=None,
              help="Longest interval still set by light, s (default: Q / dark current).")
@click.option("--sensitivity", type=float, default=None,
              help="Sub-threshold readout: how often the partial charge is read, s (with --levels).")
@click.option("--levels", type=int, default=None,
              help="Sub-threshold readout: number of charge levels it resolves, ≥ 1 (with --sensitivity).")
@click.option("--measure", is_flag=True, help="Also measure the DR of a simulated spike sensor.")
def dr_cmd(as_json, json_file, threshold_electrons, clock_hz, dark_current_e_per_s, shortest, longest, sensitivity,
           levels, measure):
    """Dynamic range of spike continuous photography: the worked examples, and your sensor's.

    The DR is the ratio of the longest interval still set by light (Q over the dark current)
    to the shortest one the readout resolves (one clock period); sub-threshold readout of the
    partial charge extends it at the dark end.
    """
    from viform._validate import ViformError, check_positive
    from viform.measure import dynamic_range as dr

    check_json_file(json_file)
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
        out["clip_limited_dr_db"] = {f"{t:g} s": dr.clip_limited_dynamic_range_db(shortest, longest, t)
                                     for t in dr.CLIP_LENGTHS_S}
        if sensitivity is not None:
            out["subthreshold_dr_db"] = dr.subthreshold_dynamic_range_db(shortest, sensitivity, levels)
    elif sensitivity is not None:
        raise ViformError("--sensitivity/--levels need the shortest interval: give --shortest or --clock-hz")
    if measure:
        out["measured"] = dr.measure_spike_dynamic_range()
    if json_file is not None:
        from viform._io import write_json

        write_json(json_file, out)
    if as_json:
        click.echo(json.dumps(out, indent=2, ensure_ascii=False))
        return
    click.echo(f"{'worked example':<62}{'computed':>12}{'published':>12}")
    for i, ex in enumerate(out["seed_examples"]):
        label = _EXAMPLE_LABELS[i] if i < len(_EXAMPLE_LABELS) else ex["example"]
        if "seed_db" in ex:
            click.echo(f"{label[:61]:<62}{ex['computed_db']:>9.1f} dB{ex['seed_db']:>9g} dB")
        else:
            click.echo(f"{label[:61]:<62}{ex['computed_ns']:>9.2f} ns{ex['seed_ns']:>9g} ns")
    if "dr_db" in out:
        click.echo(f"your sensor: shortest interval {shortest:.4g} s, longest {longest:.4g} s → "
                   f"dynamic range {out['dr_db']:.1f} dB")
        for line in dr.clip_limited_lines(shortest, longest, out["dr_db"]):
            click.echo(f"  {line}")
    if "subthreshold_dr_db" in out:
        click.echo(f"with sub-threshold readout ({levels} levels every {sensitivity:.4g} s): "
                   f"{out['subthreshold_dr_db']:.1f} dB")
    if measure:
        m = out["measured"]
        click.echo(f"simulated sensor (Q = {m['threshold_electrons']:g} e-, dark current "
                   f"{m['dark_current_e_per_s']:g} e-/s): measured {m['dr_measured_db']:.2f} dB, formula "
                   f"{m['dr_formula_db']:.2f} dB (±{m['tolerance_db']:.2f} dB)")
