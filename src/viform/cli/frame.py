"""CLI commands: frame sensors — ``viform characterize SENSOR [--out DIR] [--json] [--json-file FILE]``.

Registered on :data:`viform.cli.app.cli`.
"""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np

from viform._io import check_json_file, check_output_folder
from viform.cli._common import CatalogHelp, parse_settings
from viform.cli.app import cli


def _db(x):
    return float(20 * np.log10(x))


def _seed_figures(name: str, size: int, seed: int) -> dict:
    """The seed's measured figures next to this model's, for the seed presets."""
    from viform.measure.emva1288 import measure_response, plateau_onset
    from viform.sensors import presets
    from viform.sensors.catalog import make_sensor

    if name in ("seed001-2seg", "seed001-3seg"):
        two = name == "seed001-2seg"
        unit = presets.PAPER001_FIG8_UNIT_LUX if two else presets.PAPER001_FIG9_UNIT_LUX
        units = np.geomspace(1.0, 1000.0, 360)
        sat = {}
        for key in ("seed001-normal", name):
            r = measure_response(make_sensor(key), units * unit, height=size, width=size, seed=seed)
            sat[key] = plateau_onset(units, r["signal_dn"])
        hdr = make_sensor(name, noise=False)
        knees = hdr.knee_lux()
        knee_dn = hdr.expected_charge_electrons(knees[:-1]) * hdr.parameters.system_gain_dn_per_e
        seed_vals = (
            {
                "normal_saturation": 30,
                "hdr_saturation": 105,
                "extension_db": 10.88,
                "knee_intensity": 15,
                "knee_dn": [374],
            }
            if two
            else {"normal_saturation": 35, "hdr_saturation": 440, "extension_db": 21.99, "knee_dn": [348, 669.8]}
        )
        from viform.sensors.segmented import RpdBarrier, snr_knee_dips_db, three_segment_family

        fw = hdr.parameters.full_well_electrons
        model = {
            "normal_saturation": sat["seed001-normal"],
            "hdr_saturation": sat[name],
            "extension_db": _db(sat[name] / sat["seed001-normal"]),
            "knee_intensity": (knees[:-1] / unit).tolist(),
            "knee_dn": knee_dn.tolist(),
            "snr_dip_db": snr_knee_dips_db(hdr.segment_times_s).tolist(),
            "rpd_voltage_v": RpdBarrier().voltage_for_fraction(np.asarray(hdr.clamp_levels_electrons[:-1]) / fw)
            .tolist(),
        }
        seed_vals["snr_dip_db"] = "no loss"
        fit = "fitted to fig. 8" if two else "fitted to fig. 9"
        status = {"normal_saturation": f"{fit} (sets the intensity unit)", "hdr_saturation": fit,
                  "extension_db": fit, "knee_intensity": fit, "knee_dn": fit,
                  "snr_dip_db": "refuted: SNR drops by 10 lg(T_before/T_after) at each knee",
                  "rpd_voltage_v": "predicted from an assumed linear mapping"}
        if not two:
            status["knee_intensity"] = "predicted (depends on the chosen family member)"
        if not two:
            fam = three_segment_family(np.linspace(0.0005, 0.08, 800))
            model["family_f3_range"] = [fam[0]["fractions"][2], fam[-1]["fractions"][2]]
            model["family_knee2_intensity_range"] = [fam[0]["knee2_intensity_units"],
                                                     fam[-1]["knee2_intensity_units"]]
        return {
            "source": "seed 001 fig. 8" if two else "seed 001 fig. 9",
            "intensity_unit_lux": unit,
            "seed": seed_vals,
            "model": model,
            "status": status,
        }
    if name == "seed003-overflow":
        from viform.light.radiometry import ELEMENTARY_CHARGE_C

        over = make_sensor(name, height=size, width=size)
        four_t = make_sensor("seed003-4t")
        currents = np.geomspace(1e-14, 3e-8, 260)
        lux = over.parameters.optics.lux_from_electrons_per_s(currents / ELEMENTARY_CHARGE_C)
        sat = {}
        for key, s in (("4t", four_t), ("overflow", over)):
            r = measure_response(s, lux, height=size, width=size, seed=seed)
            sat[key] = plateau_onset(currents, r["signal_dn"])
        b = over.segment_boundaries_a()
        from viform.report.response_plots import paper003_fig5

        fig5 = paper003_fig5(size=min(size, 16), seed=seed)
        return {
            "fig5": fig5,
            "source": "seed 003 §5–6, fig. 6",
            "seed": {
                "4t_saturation_a": 8e-12,
                "DE_start_a": 270e-12,
                "D_a": 270e-12,
                "max_usable_a": 10e-9,
                "dr_gain_db": 62.0,
                "row_share_time_s": 0.51e-3,
            },
            "model": {
                "4t_saturation_a": sat["4t"],
                "B_a": b["B"],
                "C_a": b["C"],
                "D_a": b["D"],
                "E_a": b["E"],
                "max_usable_a": sat["overflow"],
                "dr_gain_db": _db(sat["overflow"] / sat["4t"]),
                "dr_gain_equations_db": over.dynamic_range_gain_db(),
                "row_share_time_s": over.row_share_time_s,
                "max_rows": over.max_rows(),
                "reset_ktc_e": over.reset_ktc_electrons,
                "readout_reset_noise_e": over.readout_reset_noise_electrons(),
                "share_ktc_e": over.share_ktc_electrons,
                **{f"dr_{k}_db": v["dynamic_range_db"] for k, v in zip(("a_4t", "b_lofic", "c_overflow"),
                                                                       fig5.values(), strict=True)},
            },
            "status": {"4t_saturation_a": "fitted (C_PD is solved from the paper's 8 pA)",
                       "D_a": "predicted", "max_usable_a": "refuted (paper 10 nA; eqs. 1-6 end at E)",
                       "dr_gain_db": "refuted: at most 57.4 dB by the paper's own eqs. 1-6",
                       "dr_gain_equations_db": "predicted", "row_share_time_s": "predicted",
                       "reset_ktc_e": "predicted (the paper gives no kTC figure)"},
            "note": "not reproduced: eqs. 1-6 give E/I_4T = (T/t3)(VF - V_sat)/(V_res - V_sat)"
            "·C_F/(C_F + C_PD) = 55.5 dB, below 20 lg((T/t3)·VF/V_res) = 57.4 dB for any "
            "C_PD, C_F, V_sat; see docs/frame-sensors.md",
        }
    return {}


#: Labels of the comparison curves, by preset name.
COMPARISON_LABELS = {
    "seed001-normal": "normal CMOS, 130 µs",
    "seed001-3seg": "segmented exposure, 3 segments, 130 µs",
    "seed003-4t": "plain 4T APS, 33 ms",
    "seed003-overflow": "conditional overflow, 33 ms",
}


def _fmt(v) -> str:
    """A number (or list of numbers) to 4 significant figures; a list as "a, b"."""
    if isinstance(v, (list, tuple, np.ndarray)):
        return ", ".join(_fmt(x) for x in v)
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.4g}"
    return str(v)


#: Readable row names and units of the paper-comparison fields (keys stay in the JSON).
_ROWS = {
    "normal_saturation": ("normal mode saturates at", "intensity units"),
    "hdr_saturation": ("segmented mode saturates at", "intensity units"),
    "extension_db": ("range extension", "dB"),
    "knee_intensity": ("knee(s) at", "intensity units"),
    "knee_dn": ("knee output(s)", "DN"),
    "snr_dip_db": ("SNR dip at each knee", "dB"),
    "rpd_voltage_v": ("barrier voltage(s), assumed mapping", "V"),
    "family_f3_range": ("third-segment fraction, fits from", "of the frame"),
    "family_knee2_intensity_range": ("second knee of the fits, from", "intensity units"),
    "4t_saturation_a": ("plain 4T saturates at", "A"),
    "B_a": ("first overflow starts (B)", "A"),
    "C_a": ("second segment saturates (C)", "A"),
    "D_a": ("third segment starts (D)", "A"),
    "E_a": ("third segment saturates (E)", "A"),
    "DE_start_a": ("third segment starts (D)", "A"),
    "max_usable_a": ("largest usable photocurrent", "A"),
    "dr_gain_db": ("DR gain over the 4T, simulated", "dB"),
    "dr_gain_equations_db": ("DR gain over the 4T, equations", "dB"),
    "row_share_time_s": ("charge-sharing time per row", "s"),
    "max_rows": ("rows that fit in the frame", "rows"),
    "reset_ktc_e": ("reset (kTC) noise per reset", "e- rms"),
    "readout_reset_noise_e": ("noise of the signal before reset", "e- rms"),
    "share_ktc_e": ("kTC noise per charge sharing", "e- rms"),
    "dr_a_4t_db": ("DR, plain 4T, Fig. 5 sweep", "dB"),
    "dr_b_lofic_db": ("DR, lateral overflow, Fig. 5 sweep", "dB"),
    "dr_c_overflow_db": ("DR, cond. overflow, Fig. 5 sweep", "dB"),
}


def _comparison_curves(size: int, seed: int, skip_spike: bool = False) -> dict:
    """Normal, segmented, overflow (and spike) responses on a common illuminance axis."""
    from viform.report.response_plots import frame_response_curve, spike_response_curve
    from viform.sensors.catalog import make_sensor

    lux = np.geomspace(0.01, 1e6, 120)
    curves = {}
    for key, label in COMPARISON_LABELS.items():
        kw = {"height": size, "width": size} if key == "seed003-overflow" else {}
        curves[label] = frame_response_curve(make_sensor(key, **kw), lux, size=size, seed=seed)
    if not skip_spike:
        curves["spike camera, Q = 100 e⁻ (spikes per tick)"] = spike_response_curve(
            make_sensor("spike"), np.geomspace(0.01, 1e4, 60), seed=seed
        )
    return curves


def _jsonable(obj):
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


#: Families ``characterize`` measures: EMVA 1288 for frame cameras, the interval dynamic range for spike
#: cameras. The high-speed camera's auto-exposure changes its exposure every frame and the gated CCD
#: records laser returns: their own commands measure them.
CHARACTERIZED = ("frame", "segmented", "overflow", "spike")
ELSEWHERE = {"highspeed": "its auto-exposure changes the exposure every frame; viform highspeed-figures prints its "
                          "published figures next to the model's, and viform highspeed SCENE runs it",
             "gated": "it records laser returns; viform gated runs seed 004's field test with it"}


def characterized_entry(sensor: str):
    """The catalogue entry of a sensor ``characterize`` measures (others are refused with where to go)."""
    from viform._validate import ViformError
    from viform.sensors.catalog import SENSORS, entry, sensor_names

    family = SENSORS[sensor].family if sensor in SENSORS else None
    if family in ELSEWHERE:
        raise ViformError(f"sensor = {sensor!r} is not characterized here ({ELSEWHERE[family]}); characterize "
                          f"takes {', '.join(sensor_names(*CHARACTERIZED))}")
    return entry(sensor, choices=sensor_names(*CHARACTERIZED))


def _characterize_spike(sensor: str, dev, size: int, seed: int, result: dict, figures: dict) -> list[str]:
    """The spike camera's interval dynamic range and SNR (into ``result["spike"]`` and ``figures``);
    returns the lines ``characterize`` prints."""
    from viform.measure.dynamic_range import CLIP_LENGTHS_S, clip_limited_dynamic_range_db, clip_limited_lines
    from viform.measure.spike_characterization import characterize_spike_sensor
    from viform.report import response_plots as plots

    # 2·τ̂ of dark on 16×16 pixels: ~500 dark spikes, τ̂ to ±5 % (0.4 dB).
    dark_s = 2 * dev.parameters.longest_signal_interval_s
    ticks = dark_s * dev.parameters.clock_hz
    click.echo(f"{sensor}: simulating {dark_s:.3g} s of darkness ({ticks:.3g} ticks on "
               f"{min(size, 16)}×{min(size, 16)} pixels) to find the longest interval, then an "
               "illuminance sweep; long dark intervals take minutes", err=True)
    r = characterize_spike_sensor(dev, height=min(size, 16), width=min(size, 16), seed=seed, dark_duration_s=dark_s)
    result["spike"] = r
    c = r["snr_curve"]
    figures["snr.png"] = plots.snr_figure({"spike (interval SNR)": {"lux": c["lux"], "snr": c["snr"]}})
    lines = [
        f"interval DR  {r['dynamic_range_db']:.4g} dB (expected "
        f"{r['expected']['dynamic_range_db']:.4g} dB: longest interval = threshold / dark current = "
        f"{r['longest_interval_s']:.3g} s, shortest = one tick = {r['shortest_interval_s'] * 1e6:.3g} µs)"
    ]
    r["clip_limited_dr_db"] = {f"{t:g} s": clip_limited_dynamic_range_db(r["shortest_interval_s"],
                                                                        r["longest_interval_s"], t)
                               for t in CLIP_LENGTHS_S}
    lines += [f"  {line}" for line in clip_limited_lines(r["shortest_interval_s"], r["longest_interval_s"],
                                                         r["dynamic_range_db"])]
    return lines


@cli.command("characterize", cls=CatalogHelp)
@click.argument("sensor")
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False),
    default=None,
    help="Folder for the PNG figures (response, SNR, photon transfer).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of the table.")
@click.option(
    "--json-file",
    "json_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="Also write the results (EMVA 1288, comparison with the published figures) as JSON to this file.",
)
@click.option(
    "--size",
    default=64,
    show_default=True,
    type=int,
    help="Flat-field size in pixels (square) for the EMVA 1288 sweep.",
)
@click.option("--seed", default=0, show_default=True, type=int, help="Random seed.")
@click.option("--set", "settings", multiple=True, metavar="NAME=VALUE",
              help="Change one parameter of SENSOR by name, e.g. --set read_noise_electrons=10 "
                   "--set parasitic_light_sensitivity=0.01 --set threshold_level=7 (repeatable; viform sensors "
                   "show SENSOR lists them; the published-figure comparison keeps the preset's own values).")
def characterize(sensor, out_dir, as_json, json_path, size, seed, settings):
    """Characterize SENSOR (EMVA 1288 R4.0 for frame sensors; interval dynamic range for spike sensors).

    SENSOR is one of: {sensors:frame,segmented,overflow,spike}.
    """
    from viform._io import save_figure, write_json
    from viform._validate import ViformError, check_int
    from viform.measure import emva1288 as emva
    from viform.report import response_plots as plots
    from viform.sensors.catalog import make_sensor
    from viform.sensors.frame import FrameSensor

    size = check_int("--size", size, 4, 512)
    # Check the outputs first, so a bad path fails at once and leaves no figures behind.
    if out_dir is not None:
        check_output_folder("--out", Path(out_dir))
    check_json_file(json_path)
    kind = characterized_entry(sensor)  # clear error for an unknown name
    overrides = parse_settings(kind, settings)
    result: dict = {"sensor": sensor, "description": kind.description}
    if overrides:
        result["settings"] = overrides
    figures = {}
    if kind.family == "spike":
        dev = kind.build(height=None, width=None, **overrides)  # any test size
        lines = _characterize_spike(sensor, dev, size, seed, result, figures)
    else:
        kw = {"height": min(size, 64), "width": min(size, 64)} if kind.family == "overflow" else {}
        dev = kind.build(**kw, **overrides)
        lines = []
        if type(dev) is FrameSensor:
            r = emva.characterize_frame_sensor(dev, height=size, width=size, seed=seed)
            result["emva1288"] = r
            figures["ptc.png"] = plots.ptc_figure(r)
            e = r["expected"]
            lines += [
                f"{'quantity':<22} {'measured':>12}  {'from parameters':>15}",
                f"{'system gain K':<22} {r['system_gain_dn_per_e']:>7.4g} DN/e-  "
                f"{e['system_gain_dn_per_e']:>9.4g} DN/e-",
                f"{'quantum efficiency':<22} {r['quantum_efficiency']:>12.3g}  {e['quantum_efficiency']:>15.3g}",
                f"{'dark noise':<22} {r['temporal_dark_noise_electrons']:>9.3g} e-  "
                f"{e['temporal_dark_noise_electrons']:>12.3g} e-",
                f"{'saturation capacity':<22} {r['saturation_capacity_electrons']:>9.4g} e-  "
                f"{e['saturation_capacity_electrons']:>12.4g} e-",
                f"{'sensitivity threshold':<22} {r['absolute_sensitivity_threshold_photons']:>5.3g} photons",
                f"{'dynamic range':<22} {r['dynamic_range_db']:>9.4g} dB  {e['dynamic_range_db']:>12.4g} dB",
                f"{'DSNU':<22} {r['dsnu_electrons']:>9.3g} e-  {e['dsnu_electrons']:>12.3g} e-",
                f"{'PRNU':<22} {r['prnu_percent']:>10.3g} %  {e['prnu_percent']:>13.3g} %",
                f"{'linearity error':<22} {r['linearity_error_percent']:>10.3g} %",
            ]
            lines += [f"warning: {w}" for w in r["warnings"]]
        lux = np.geomspace(1e-5, 1e6, 200)
        own = plots.frame_response_curve(dev, lux, size=min(size, 32), seed=seed)
        dr = emva.dynamic_range_from_response(own["raw"])
        result["response_dynamic_range"] = dr
        px = min(size, 32)
        dr["sweep"] = f"{lux.size} illuminances 1e-5 to 1e6 lux on {px}x{px} pixels"
        lines.append(
            f"{'response DR':<22} {dr['dynamic_range_db']:>9.4g} dB  (SNR = 1 at "
            f"{dr['lux_min']:.3g} lux to the plateau at {dr['lux_sat']:.3g} lux; {dr['sweep']})"
        )
        figures["snr.png"] = plots.snr_figure({sensor: own})
        seed_fig = _seed_figures(sensor, min(size, 32), seed)
        fig5 = seed_fig.pop("fig5", None)
        if fig5 is not None:
            figures["fig5_dr_abc.png"] = plots.paper003_fig5_figure(fig5)
        if seed_fig:
            result["seed_comparison"] = seed_fig
            unit_lux = seed_fig.get("intensity_unit_lux")
            lines.append("the model next to the published figures"
                         + (f" (1 intensity unit = {unit_lux:.4g} lux)" if unit_lux else "") + ":")
            lines.append(f"  {'quantity':<37} {'model':>22}  {'published':>10}  {'unit':<16} status")
            status = seed_fig.get("status", {})
            for k, v in seed_fig["model"].items():
                ref = seed_fig["seed"].get(k)
                name, unit = _ROWS.get(k, (k.replace("_", " "), ""))
                val = " to ".join(_fmt(x) for x in v) if k.endswith("_range") else _fmt(v)
                st = status.get(k, "")
                lines.append(f"  {name:<37} {val:>22}  {_fmt(ref) if ref is not None else '-':>10}  {unit:<16} {st}")
            if "dr_c_overflow_db" in seed_fig["model"]:
                lines.append(f"  the response DR above and the Fig. 5 DRs use one definition (SNR = 1 to the plateau) "
                             f"on two sweeps ({dr['sweep']}; Fig. 5: 150 photocurrents 1e-16 to 3e-8 A on "
                             f"{min(size, 32, 16)}x{min(size, 32, 16)} pixels): they differ only by that sampling")
    if out_dir is not None:
        # The "spike" preset is the reference spike curve itself: draw it once.
        curves = _comparison_curves(16, seed, skip_spike=sensor == "spike")
        label = COMPARISON_LABELS.get(sensor)
        if label is None:  # this sensor is not among the comparison curves: add it, bold
            label = f"{sensor} (this sensor)"
            if kind.family == "spike":
                curves[label] = plots.spike_response_curve(dev, np.geomspace(0.01, 1e4, 40), seed=seed)
            else:
                curves[label] = own
        knees = None
        if hasattr(dev, "segment_boundaries_a"):  # the overflow pixel's knees B–E (seed 003 fig. 6)
            names = {"B": "B first overflow", "C": "C saturates in t1", "D": "D saturates in t2",
                     "E": "E end of range"}
            knees = {names[k]: float(dev.lux_from_photocurrent(v))
                     for k, v in dev.segment_boundaries_a().items() if k in names}
        figures["response.png"] = plots.response_figure(
            curves, f"Response of {sensor} (bold) against the other frame and spike sensors", highlight=label,
            knees_lux=knees,
        )
        if sensor in ("seed001-2seg", "seed001-3seg"):
            from viform.sensors.segmented import SegmentedExposureSensor, three_segment_family

            figures["fig7_rpd_voltage.png"] = plots.rpd_fig7_figure()
            figures["fig8_fractions.png"] = plots.fraction_family_figure()
            if sensor == "seed001-3seg":
                figures["fig9_three_segment_family.png"] = plots.three_segment_family_figure(
                    three_segment_family([0.0095, 0.01, 0.015, 0.02, 0.03, 0.04]))
            spread = SegmentedExposureSensor(dev.parameters, dev.segment_times_s, dev.clamp_levels_electrons,
                                             frame_rate_hz=60.0, barrier_spread_fraction=0.02)
            figures["snr_knees.png"] = plots.snr_knees_figure(dev, make_sensor("seed001-normal"), spread,
                                                              measured=own)
        out = Path(out_dir)
        for fname, fig in figures.items():
            save_figure(out / fname, fig)
        result["figures"] = sorted(str(out / f) for f in figures)
    else:
        import matplotlib.pyplot as plt

        for fig in figures.values():
            plt.close(fig)
    if json_path is not None:
        for key in ("emva1288", "spike"):
            if key in result:
                result[key] = {k: v for k, v in result[key].items() if k not in ("curves",)}
        write_json(json_path, _jsonable(result))
    if not lines:
        raise ViformError(f"nothing was measured for {sensor!r}")
    if as_json:
        for key in ("emva1288", "spike"):
            if key in result:
                result[key] = {k: v for k, v in result[key].items() if k not in ("curves",)}
        click.echo(json.dumps(_jsonable(result), indent=2))
        return
    click.echo(f"{sensor}: {result['description']}"
               + (f" (changed: {', '.join(f'{k} = {v}' for k, v in overrides.items())})" if overrides else ""))
    for line in lines:
        click.echo("  " + line)
