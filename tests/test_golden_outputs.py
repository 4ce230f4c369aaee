"""Every sensor's output stays bit-identical: SHA-256 of the spike bits and frame DNs of every
sensor × a few scenes × fixed seeds, through the CLI (``viform capture``) and
the library (the sensors as ``compare``, ``sweep`` and ``dataset`` build and shoot them).

The hashes in ``golden_outputs.json`` were recorded with this script on the code before the
sensor catalogue (commit 70d19ee) and checked against it; a refactoring of how sensors are
named, built or shot must leave them unchanged. Run ``python tests/test_golden_outputs.py``
to print the current hashes (``--write`` stores them: only for a deliberate change of a model,
said in the commit).

What is hashed is what the sensor produced: spike bits (as packed bits), frame DNs, the
exposure windows, and the high-speed camera's link output; metadata (text, provenance, time
stamps) is not.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest

GOLDEN = Path(__file__).with_name("golden_outputs.json")

FRAME_SENSORS = ("cmos", "cmos-short", "seed001-normal", "seed001-2seg", "seed001-3seg", "seed003-4t",
                 "seed003-overflow", "seed003-overflow-ktc", "seed003-lofic")
SPIKE_SENSORS = ("spike", "spikeone", "spiketwo", "spiketwo-40k")
#: (scene, height, width): small, so the whole file runs in seconds.
SCENES = (("translating", 24, 32), ("dilemma", 32, 48), ("hdr", 16, 24))
SEEDS = (0, 7)


def digest(arrays: dict) -> str:
    """SHA-256 over the named arrays (name, dtype, shape and bytes, in name order)."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        if a.dtype == bool:
            a = np.packbits(a.reshape(-1))
        h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _stream_arrays(stream) -> dict:
    return {"spikes": np.asarray(stream.to_memory().spikes if hasattr(stream, "to_memory") else stream.spikes,
                                 dtype=bool)}


def _stack_arrays(stack) -> dict:
    return {"frames_dn": stack.frames_dn, "start_times_s": stack.start_times_s, "exposure_s": stack.exposure_s}


# ---------------------------------------------------------------------- CLI
def _cli_capture(tmp, name, scene, height, width, seed, duration_s, sets=()):
    from viform.cli import main

    spike = name.startswith("spike")
    out = Path(tmp) / f"{name}-{scene}-{seed}.npz"
    args = ["capture", name, scene, "--duration", str(duration_s), "--height", str(height), "--width", str(width),
            "--seed", str(seed), "--out", str(out), "--json"]
    for s in sets:
        args += ["--set", s]
    code = main(args)
    assert code == 0, (name, scene, code)
    if spike:
        from viform.stream.io import open_spikes

        return _stream_arrays(open_spikes(out))
    with np.load(out) as z:
        return {k: z[k] for k in z.files if k not in ("metadata_json", "units")}


def cli_cases() -> dict:
    cases = {}
    for name in FRAME_SENSORS + SPIKE_SENSORS + ("highspeed",):
        duration = 0.004 if name.startswith("spike") or name == "highspeed" else 0.04
        for scene, h, w in SCENES[:2]:
            for seed in SEEDS if scene == "translating" else SEEDS[:1]:
                cases[f"cli/capture/{name}/{scene}/seed{seed}"] = (
                    lambda tmp, n=name, s=scene, hh=h, ww=w, sd=seed, d=duration: _cli_capture(tmp, n, s, hh, ww, sd,
                                                                                               d))
    for seed in SEEDS:
        cases[f"cli/capture/gated/night-road-fog/seed{seed}"] = (
            lambda tmp, sd=seed: _cli_capture(tmp, "gated", "night-road-fog", 32, 48, sd, 0.08))
    # --set on the frame presets that took it before the catalogue
    for name, sets in (("cmos", ("read_noise_electrons=10", "parasitic_light_sensitivity=0.01")),
                       ("seed001-2seg", ("clamp_noise_electrons=20",)),
                       ("seed003-overflow", ("comparator_noise_v=0.005", "overflow_capacitance_f=2e-13"))):
        cases[f"cli/capture/{name}/dilemma/set:{','.join(sets)}"] = (
            lambda tmp, n=name, ss=sets: _cli_capture(tmp, n, "dilemma", 32, 48, 3, 0.04, ss))
    return cases


def _dataset(tmp, preset):
    """A scene-clip dataset as ``viform dataset --scenes`` makes it (in this process, no dask)."""
    from viform.datasets.build import convert_serially, make_settings, scene_clips
    from viform.stream.io import open_spikes

    out = Path(tmp) / f"ds-{preset}"
    settings = make_settings(preset, height=16, width=24, truth_every_ticks=20)
    convert_serially(scene_clips("translating", 1, 0.002, settings), out, settings)
    files = sorted((out / "spike").glob("*.dat"))
    assert files
    return {f.stem: np.asarray(open_spikes(f).to_memory().spikes, dtype=bool) for f in files}


# ---------------------------------------------------------------------- library
def _scene(name, h, w):
    from viform.light.catalog import load_scene

    return load_scene(name, h, w)


def _api_capture(build, scene, h, w, seed, duration_s):
    sensor = build()
    out = sensor.capture(_scene(scene, h, w), duration_s, seed=seed)
    return _stack_arrays(out) if hasattr(out, "frames_dn") else _stream_arrays(out)


def _shoot(key, scene, h, w, seed, duration_s, settings=None):
    """The raw output of ``compare``'s shot of ``key`` (a sweep point with ``settings``)."""
    from viform.measure import comparison as cmp
    from viform.measure import sweep as sw

    sc = _scene(scene, h, w)
    sensor = sw.make_point_sensor(key, settings) if settings is not None else None
    instants = [duration_s * f for f in (0.3, 0.5, 0.7)]
    shot = cmp.shoot(key, sc, duration_s, instants, seed=seed, sensor=sensor, spike_methods=["interval"])[0]
    raw = shot.raw
    if shot.family == "highspeed":  # the camera's 8-bit frames, and what its link sends of them
        from viform.isp.highspeed_pipeline import process_frames

        return {"gray8": raw.frames_dn, "exposure_cycles": raw.metadata["exposure_cycles"],
                "output_frames": process_frames(raw, shot.sensor).output_frames}
    if shot.family == "gated":  # the first frame: the one compare scores
        return {"dn": raw.frames_dn[0]}
    if hasattr(raw, "frames_dn"):
        return _stack_arrays(raw)
    return _stream_arrays(raw)


COMPARE_KEYS = ("spikeone", "cmos-short", "cmos", "seed001-2seg", "seed001-3seg", "seed003-4t", "seed003-overflow",
                "highspeed", "gated")
#: Sweep points: settings a sweep builds, one or two per sensor, shot as compare shoots them.
SWEEP_POINTS = {
    "spikeone": {"threshold_level": 3, "clock_hz": 20000.0},
    "cmos": {"exposure_s": 0.002, "read_noise_electrons": 12.0},
    "seed001-2seg": {"exposure_s": 1e-4, "barrier_fraction": 0.3},
    "seed001-3seg": {"exposure_s": 5e-4},
    "seed003-4t": {"quantum_efficiency": 0.3},
    "seed003-overflow": {"overflow_capacitance_f": 1e-13, "long_integration_s": 0.02},
    "highspeed": {"target_gray": 100.0, "read_noise_electrons": 20.0},
    "gated": {"gate_range_m": 60.0, "pulses": 100},
}


def api_cases() -> dict:
    from viform.sensors.catalog import make_sensor

    cases = {}
    for name in ("cmos", "seed001-normal", "seed001-2seg", "seed001-3seg", "seed003-4t", "seed003-overflow",
                 "seed003-overflow-ktc", "seed003-lofic", "spike"):
        duration = 0.004 if name == "spike" else 0.04
        for scene, h, w in SCENES:
            for seed in SEEDS:
                cases[f"api/make_sensor/{name}/{scene}/seed{seed}"] = (
                    lambda tmp, n=name, s=scene, hh=h, ww=w, sd=seed, d=duration: _api_capture(
                        lambda: make_sensor(n), s, hh, ww, sd, d))
    for name in ("spikeone", "spiketwo", "spiketwo-40k"):
        cases[f"api/spike_preset/{name}/translating/seed0"] = (
            lambda tmp, n=name: _api_capture(lambda: make_sensor(n, height=None, width=None), "translating", 24,
                                             32, 0, 0.004))
    for key in COMPARE_KEYS:
        scene, h, w = ("night-road-fog", 32, 48) if key == "gated" else ("dilemma", 32, 48)
        duration = 0.004 if key in ("spikeone", "highspeed") else 0.04
        cases[f"api/compare/{key}/{scene}/seed5"] = (
            lambda tmp, k=key, s=scene, hh=h, ww=w, d=duration: _shoot(k, s, hh, ww, 5, d))
        if key in SWEEP_POINTS:
            cases[f"api/sweep/{key}/{scene}/seed5"] = (
                lambda tmp, k=key, s=scene, hh=h, ww=w, d=duration: _shoot(k, s, hh, ww, 5, d, SWEEP_POINTS[k]))
    cases["api/highspeed/translating/seed2"] = _api_highspeed
    for preset in (None, "spiketwo"):
        cases[f"api/dataset/{preset}/translating"] = lambda tmp, p=preset: _dataset(tmp, p)
    cases["api/subthreshold/translating/seed4"] = _api_subthreshold
    cases["api/gated-ccd/settings/field-test/seed1"] = _api_gated_settings
    return cases


def _api_highspeed(tmp):
    from viform.isp.highspeed_pipeline import HighSpeedConfig, run_highspeed

    r = run_highspeed(_scene("translating", 18, 32), HighSpeedConfig(n_frames=12, seed=2))
    return {"gray8": r.gray8, "exposure_cycles": r.exposure_cycles, "output_frames": r.output_frames,
            "sent": r.transmitted_indices}


def _api_subthreshold(tmp):
    from viform.sensors.spike import SpikeSensor
    from viform.sensors.subthreshold import SubthresholdSpikeSensor

    cap = SubthresholdSpikeSensor(SpikeSensor(), sensitivity_ticks=20, levels=10).capture(
        _scene("translating", 12, 16), 0.003, seed=4)
    return {"spikes": np.asarray(cap.spikes.spikes, dtype=bool), "levels": cap.levels}


def _api_gated_settings(tmp):
    """The CCD ``viform gated --set`` builds, on the field-test scene (one frame per mode)."""
    from viform.cli.gated import gated_sensor_kw
    from viform.light.active import field_test_scene
    from viform.sensors.gated_ccd import GatedInterlineCCD

    kw, _ = gated_sensor_kw(["gate_jitter_s=5e-9", "read_noise_electrons=20", "transfer_smear=true"])
    scene = field_test_scene(ambient_lux=1e5, visibility_m=20e3)
    out = {}
    for mode in ("accumulate", "ungated"):
        ccd = GatedInterlineCCD(pulses=20, gate_range_m=150.0, mode=mode, frame_rate_hz=25.0, **kw)
        out[mode] = ccd.capture_frame(scene, seed=1).dn
    return out


def all_cases() -> dict:
    return {**cli_cases(), **api_cases()}


def compute(names=None) -> dict:
    import tempfile

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, case in all_cases().items():
            if names is None or name in names:
                out[name] = digest(case(tmp))
    return out


def _recorded() -> dict:
    return json.loads(GOLDEN.read_text())


@pytest.mark.parametrize("name", sorted(all_cases()))
def test_output_is_bit_identical(name, tmp_path, capsys):
    recorded = _recorded()
    assert name in recorded, f"no recorded hash for {name}: run python {Path(__file__).name} --write"
    got = digest(all_cases()[name](tmp_path))
    capsys.readouterr()
    assert got == recorded[name]


def test_every_recorded_case_still_runs():
    """A case dropped from this file would silently stop being checked."""
    assert set(_recorded()) == set(all_cases())


if __name__ == "__main__":
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        hashes = compute()
    if "--write" in sys.argv:
        GOLDEN.write_text(json.dumps(hashes, indent=1, sort_keys=True) + "\n")
    print(json.dumps(hashes, indent=1, sort_keys=True))
