"""CLI commands: gated (registered on viform.cli.app.cli).

``viform gated`` reproduces seed 004's field test with the gated interline-CCD model and
prints what the model predicts next to the seed's figures.
"""

from __future__ import annotations

import math
from pathlib import Path

import click

from viform._validate import check_non_negative, check_positive
from viform.cli.app import cli

SEED_PULSES = {300.0: "15–20", 800.0: "70–90"}


def run_gated(
    gate_m: float = 150.0,
    pulses: int = 20,
    visibility_m: float = 20e3,
    ambient_lux: float = 1e5,
    fog_visibility_m: float = 150.0,
    threshold: float = 5.0,
    seed: int = 0,
    out=None,
) -> dict:
    """Compute everything ``viform gated`` reports; write figures to ``out`` if given."""
    from viform.light.active import Medium, field_test_scene, fog_scene
    from viform.measure.gated_metrics import expected_cnr, measured_cnr, pulses_needed_vs_ambient
    from viform.sensors.gated_ccd import MODES, GatedInterlineCCD

    check_non_negative("gate_m", gate_m)
    check_positive("visibility_m", visibility_m, allow_inf=True)
    check_non_negative("ambient_lux", ambient_lux)
    check_positive("fog_visibility_m", fog_visibility_m)
    scene = field_test_scene(ambient_lux=ambient_lux, visibility_m=visibility_m)
    ccd = GatedInterlineCCD(pulses=pulses, gate_range_m=gate_m, frame_rate_hz=25.0)
    result = {
        "gate": ccd.timing.to_dict(),
        "pulses": pulses,
        "ambient_lux": ambient_lux,
        "visibility_m": visibility_m,
        "cnr_threshold": threshold,
        "sensor": ccd.describe(),
    }

    # 1. field test and the three modes on the same scene
    modes = {}
    pp = ccd.per_pulse_electrons(scene)
    frames = {}
    for mode in MODES:
        sensor = GatedInterlineCCD(
            pulses=pulses,
            gate_range_m=gate_m,
            mode=mode,
            frame_rate_hz=1.0
            / GatedInterlineCCD(pulses=1, gate_range_m=gate_m, mode=mode, frame_rate_hz=1e-3).frame_time_s(
                pulses, mode
            ),
        )
        frame = sensor.capture_frame(scene, seed=seed)
        frames[mode] = frame.electrons
        rows = []
        for r in scene.retroreflectors:
            exp = expected_cnr(sensor, scene, r.row, r.col, per_pulse=pp)
            rows.append(
                {
                    "label": r.label,
                    "range_m": r.range_m,
                    "cnr": exp.cnr,
                    "cnr_simulated": measured_cnr(frame.electrons, r.row, r.col),
                    "visible": bool(exp.cnr >= threshold),
                    "signal_electrons": exp.signal_electrons,
                    "background_electrons": exp.background_electrons,
                }
            )
        modes[mode] = {"frame_rate_hz": 1.0 / sensor.frame_time_s(), "readouts": frame.readouts, "targets": rows}
    result["modes"] = modes

    # 2. pulses needed vs ambient at 300 m and 800 m (accumulate mode)
    ambients = sorted({1e5, 1e4, 1e3, 1.0, 1e-3, float(ambient_lux)}, reverse=True)
    result["pulses_needed"] = pulses_needed_vs_ambient((300.0, 800.0), ambients, threshold)
    for row in result["pulses_needed"]:
        row["seed_figure"] = SEED_PULSES.get(row["range_m"]) if row["ambient_lux"] == 1e5 else None

    # 3. fog: gated vs un-gated
    fog = fog_scene(visibility_m=fog_visibility_m, ambient_lux=min(ambient_lux, 1.0))
    first = min(float(fog.range_m.min()), 1e9)
    fog_gate = max(0.0, first - 10.0)
    fog_x = min(pulses, 200)
    fog_rows, fog_imgs = {}, {}
    for mode in ("ungated", "accumulate"):
        sensor = GatedInterlineCCD(pulses=fog_x, gate_range_m=fog_gate, mode=mode, frame_rate_hz=25.0)
        fimg = sensor.capture_frame(fog, seed=seed).electrons
        fog_imgs[f"{mode}, X={fog_x}"] = fimg
        budget = sensor.electron_budget(fog)
        signs = fog.retro_coefficient_per_sr > 0
        bg = ~signs
        fog_rows[mode] = {
            "sign_mean_electrons": float(budget["photo"][signs].mean()),
            "background_mean_electrons": float(budget["photo"][bg].mean()),
            "backscatter_electrons": float(
                (budget["photo"] - sensor.electron_budget(fog.with_(medium=Medium(0.0)))["photo"])[bg].mean()
            ),
            "sign_contrast": float((fimg[signs].mean() - fimg[bg].mean()) / max(fimg[bg].std(ddof=1), 1e-9)),
        }
    result["fog"] = {"visibility_m": fog_visibility_m, "gate_range_m": fog_gate, "pulses": fog_x, "modes": fog_rows}

    if out is not None:
        from viform.report import gated_plots as gp

        out = Path(out)
        prof = gp.range_intensity_profile(ccd, Medium.from_visibility(fog_visibility_m))
        gp.plot_range_intensity(
            out / "range_intensity.png",
            prof,
            f"gate {gate_m:g} m: window {prof['gate_window_m'][0]:.0f}–"
            f"{prof['gate_window_m'][1]:.0f} m (fog V = {fog_visibility_m:g} m)",
        )
        gp.plot_images(
            out / "fog_gated_vs_ungated.png",
            fog_imgs,
            f"signs at {', '.join(f'{r:g}' for r in (60, 90, 120))} m in fog V = {fog_visibility_m:g} m"
            " (one grey scale for both)",
            shared_scale=True,
        )
        gp.plot_images(
            out / "modes.png",
            {f"{m}, X={pulses}": im for m, im in frames.items()},
            f"reflectors 50/100/200/300 m, gate {gate_m:g} m, {ambient_lux:g} lx",
        )
        gp.plot_cnr(
            out / "cnr.png",
            [dict(r, label=f"{m[:5]} {r['label']}") for m in MODES for r in modes[m]["targets"]],
            threshold,
            f"CNR per target, X = {pulses}",
        )
        result["figures"] = sorted(str(p) for p in out.glob("*.png"))
    return result


def format_report(res: dict) -> str:
    g = res["gate"]
    lines = [
        f"gate {g['gate_range_m']:g} m: opens {g['open_s'] * 1e9:.0f} ns after the pulse, "
        f"width {g['width_s'] * 1e9:.0f} ns, sees {g['range_window_m'][0]:.0f}–{g['range_window_m'][1]:.0f} m",
        f"field test, X = {res['pulses']}, {res['ambient_lux']:g} lx, CNR ≥ {res['cnr_threshold']:g} = visible"
        " (seed: 200 and 300 m visible, 50 and 100 m not)",
    ]
    for mode, m in res["modes"].items():
        cells = ", ".join(f"{t['label']}: {t['cnr']:.1f}{'*' if t['visible'] else ''}" for t in m["targets"])
        lines.append(f"  {mode:<10} {m['frame_rate_hz']:6.1f} Hz  CNR {cells}")
    lines.append(
        "pulses needed (accumulate mode, gate 50 m before the reflector, CNR ≥ "
        f"{res['cnr_threshold']:g}) — model vs seed:"
    )
    for row in res["pulses_needed"]:
        x = row["pulses_needed"]
        xs = "not reached" if x is None else f"{x}"
        fr = (
            ""
            if x is None
            else f" ({row['frame_rate_hz_at_x']:.0f} Hz{'' if row['fits_frame_rate'] else ', > 25 Hz limit'})"
        )
        seed = f"   seed: {row['seed_figure']}" if row.get("seed_figure") else ""
        lines.append(f"  {row['range_m']:5.0f} m  {row['ambient_lux']:>8g} lx  X = {xs}{fr}{seed}")
    f = res["fog"]
    lines.append(f"fog V = {f['visibility_m']:g} m, X = {f['pulses']}, gate {f['gate_range_m']:g} m:")
    for mode, m in f["modes"].items():
        lines.append(
            f"  {mode:<10} backscatter {m['backscatter_electrons']:.3g} e-, signs "
            f"{m['sign_mean_electrons']:.3g} e-, sign contrast/noise {m['sign_contrast']:.1f}"
        )
    return "\n".join(lines)


@cli.command("gated")
@click.option("--gate-m", type=float, default=150.0, show_default=True, help="Gate near range, m (delay 2R/c).")
@click.option("--pulses", type=int, default=20, show_default=True, help="Laser pulses X per frame.")
@click.option(
    "--visibility-m",
    type=float,
    default=20e3,
    show_default=True,
    help="Meteorological visibility of the field-test air, m (σ = 3.912/V).",
)
@click.option(
    "--ambient-lux",
    type=float,
    default=1e5,
    show_default=True,
    help="Ambient scene illuminance, lux (sunny day ≈ 1e5, night ≈ 1e-3).",
)
@click.option(
    "--fog-visibility-m",
    type=float,
    default=150.0,
    show_default=True,
    help="Visibility of the fog scene (gated vs un-gated images), m.",
)
@click.option("--threshold", type=float, default=5.0, show_default=True, help="CNR needed to 'stand out'.")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--out", type=click.Path(file_okay=False), default=None, help="Folder for the figures.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None, help="Write all numbers as JSON.")
def gated(gate_m, pulses, visibility_m, ambient_lux, fog_visibility_m, threshold, seed, out, json_path):
    """Range-gated imaging with an interline CCD (seed 004): field test, pulses needed, fog."""
    from viform._io import write_json

    if not math.isfinite(threshold) or threshold <= 0:
        check_positive("threshold", threshold)
    res = run_gated(gate_m, pulses, visibility_m, ambient_lux, fog_visibility_m, threshold, seed, out)
    click.echo(format_report(res))
    if json_path:
        write_json(json_path, res)
