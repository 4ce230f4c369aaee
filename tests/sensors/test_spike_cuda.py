"""The GPU kernels (numba-cuda) give the CPU kernels' bits and state, checked under numba's CUDA simulator.

The simulator (``NUMBA_ENABLE_CUDASIM=1``) runs the CUDA kernels' Python source thread by thread
on the CPU, so no GPU is needed; it must be enabled before numba.cuda is first imported, hence
one subprocess for all cases. It is slow (each thread a Python thread), so the images are one
or two warps (32–64 pixels) and a few dozen ticks — enough to cross block boundaries, partial
warps, every light kind, Q from 1 to 10⁵, dead time, hot pixels and saturated ticks.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

pytest.importorskip("numba.cuda", reason="numba-cuda is not installed (pip install -e '.[test]')")

CHILD = textwrap.dedent('''
    import hashlib, json, warnings
    import numpy as np
    TICKS = 32
    warnings.simplefilter("ignore")  # uint64 hash arithmetic wraps in the simulator's NumPy scalars
    from viform.light.scenes import (FlickerScene, HDRScene, RotatingScene, StepScene, StillScene,
                                     TranslatingScene, VideoScene)
    from viform.sensors.spike import SpikeSensor

    rng = np.random.default_rng(7)

    def tex(h, w, lo, hi):
        return lo * (hi / lo) ** rng.random((h, w))

    class MapSensor(SpikeSensor):
        def threshold_map_electrons(self, height, width):
            levels = np.array([1.0, 5.0, 100.0, 1e5])
            return levels[np.arange(height * width) % 4].reshape(height, width)

    cases = {
        "still-exact": (SpikeSensor(), StillScene(tex(4, 8, 0.3, 30.0))),
        "hdr-q7-saturated": (SpikeSensor(threshold_electrons=7), HDRScene(4, 16, 0.001, 8.0)),
        "threshold-map": (MapSensor(), StillScene(tex(4, 8, 0.1, 3e5))),  # Q = 1 saturated … Q = 1e5
        "noise-free": (SpikeSensor(photon_noise=False), StillScene(tex(4, 8, 0.1, 900.0))),
        "noise-free-readout": (SpikeSensor(photon_noise=False, reset="readout"), StillScene(tex(4, 8, 0.1, 300.0))),
        "dead-time-hot-pixels": (SpikeSensor(dead_time_s=3e-5, hot_pixel_fraction=0.2,
                                             hot_pixel_dark_current_e_per_s=4e5, gain_spread_fraction=0.1),
                                 StillScene(tex(4, 8, 0.1, 2e3))),
        "readout-dead-time": (SpikeSensor(reset="readout", dead_time_s=5e-5), StillScene(tex(4, 8, 0.1, 2e3))),
        "step": (SpikeSensor(), StepScene(StillScene(tex(4, 8, 0.5, 20.0)), 0.0006, 20.0)),
        "video-linear": (SpikeSensor(), VideoScene(0.2 + 8 * rng.random((4, 4, 8)), 20000.0, "linear")),
        "translating-texture": (SpikeSensor(), TranslatingScene(4, 8, (3000.0, 800.0), max_lux=40.0)),
        "moving-edge-saturated": (SpikeSensor(threshold_electrons=3),
                                  TranslatingScene(4, 8, (9000.0, 0.0), pattern="edge", max_lux=3e4)),
        "rotating-bars-readout": (SpikeSensor(reset="readout"),
                                  RotatingScene(4, 8, 300.0, pattern="bars", max_lux=50.0)),
        "flicker-square": (SpikeSensor(), FlickerScene(StillScene(tex(4, 8, 1.0, 60.0)), 2000.0, 0.8, "square")),
        "odd-size-partial-warp": (SpikeSensor(), TranslatingScene(3, 13, (2000.0, 0.0), max_lux=30.0)),
    }
    results = {}
    for name, (sensor, scene) in cases.items():
        kw = {"light_sample_ticks": 1}  # the goldens' light: one sample per tick
        h, w = scene.height, scene.width
        out = {}
        for device in ("cpu", "cuda"):
            state = sensor.initial_state(h, w, 5)
            bits = np.concatenate([b for _, b in sensor.simulate(scene, TICKS / 40e3, seed=5, block_ticks=17,
                                                                 state=state, device=device, **kw)])
            out[device] = (bits, state)
        (cb, cs), (gb, gs) = out["cpu"], out["cuda"]
        digest = hashlib.blake2b(np.packbits(gb.reshape(gb.shape[0], -1), axis=1).tobytes(), digest_size=12)
        for k in ("charge", "target", "counter"):
            digest.update(np.ascontiguousarray(getattr(gs, k), dtype=np.int64).tobytes())
        results[name] = {"bits": bool(np.array_equal(cb, gb)), "hash": digest.hexdigest(),
                         "state": all(bool(np.array_equal(getattr(cs, k), getattr(gs, k)))
                                      for k in ("charge", "target", "counter")),
                         "firing": float(cb.mean())}
    packed_cpu = b"".join(f.tobytes() for _, f in SpikeSensor().simulate_packed(
        TranslatingScene(4, 8, (2000.0, 0.0)), 24 / 40e3, seed=2, flip=True))
    packed_gpu = b"".join(f.tobytes() for _, f in SpikeSensor().simulate_packed(
        TranslatingScene(4, 8, (2000.0, 0.0)), 24 / 40e3, seed=2, flip=True, device="cuda"))
    stream = SpikeSensor().capture(StillScene(tex(4, 8, 1.0, 9.0)), 8 / 40e3, seed=1, device="auto")
    results["_packed"] = {"bits": packed_cpu == packed_gpu, "state": True, "firing": 0.5,
                          "hash": hashlib.blake2b(packed_gpu, digest_size=12).hexdigest()}
    results["_device"] = stream.metadata["device"]
    print(json.dumps(results))
''')


@pytest.fixture(scope="module")
def simulated():
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
    run = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, timeout=1800)
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout.strip().splitlines()[-1])


CASES = ["still-exact", "hdr-q7-saturated", "threshold-map", "noise-free", "noise-free-readout",
         "dead-time-hot-pixels", "readout-dead-time", "step", "video-linear", "translating-texture",
         "moving-edge-saturated", "rotating-bars-readout", "flicker-square", "odd-size-partial-warp", "_packed"]

#: Hashes of the GPU path's spikes and final state per case (simulator), recorded before the spike kernels moved
#: to ``sensors/_spike_kernels.py``: a change of either device's bits fails here even where both change alike.
GOLDEN = {
    'still-exact': '3808a8fe08e1c3d4f76009e0',
    'hdr-q7-saturated': 'b056b8b402db7fedca74abc9',
    'threshold-map': '1756341d19c218ec30f3786b',
    'noise-free': '457985ff6b7736632454631e',
    'noise-free-readout': 'b0a539957661887b2b8d1e47',
    'dead-time-hot-pixels': '2eef870d3cafdf4c92cefe5b',
    'readout-dead-time': '083e9e7fe984a62cf9971c21',
    'step': 'b2f8653ddcc5a57f6a34213c',
    'video-linear': '6860edbbe800c82871ec4690',
    'translating-texture': '89a4d568646cf9ff8f4b19c0',
    'moving-edge-saturated': '098239e3de93cc7fc3eb9ffc',
    'rotating-bars-readout': '375f800f7c45f64f2e89685b',
    'flicker-square': '9d5318763b3c012c97f0f201',
    'odd-size-partial-warp': '84ea0dd9c253d4ee6857cb16',
    '_packed': '660c50639455cef9d1c83b01',
}


@pytest.mark.parametrize("name", CASES)
def test_gpu_kernels_give_the_cpu_bits_and_state(simulated, name):
    result = simulated[name]
    assert result["bits"], f"{name}: GPU bits differ from the CPU's"
    assert result["state"], f"{name}: GPU final state differs from the CPU's"
    assert 0.0 < result["firing"] < 1.0  # the case is neither dark nor stuck


@pytest.mark.parametrize("name", CASES)
def test_gpu_bits_and_state_are_the_golden_ones(simulated, name):
    assert simulated[name]["hash"] == GOLDEN[name]


def test_auto_device_uses_the_gpu_and_says_so(simulated):
    assert simulated["_device"].startswith("cuda: numba-cuda simulator")


def test_cuda_without_a_gpu_is_one_clear_error():
    code = textwrap.dedent('''
        import numba.cuda as cuda
        cuda.is_available = lambda: False
        from viform._validate import ViformError
        from viform.sensors.spike_cuda import resolve_device
        assert resolve_device("auto") == "cpu"
        try:
            resolve_device("cuda", "--device")
        except ViformError as exc:
            print(exc)
    ''')
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=1800)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip() == "--device = 'cuda': numba-cuda finds no CUDA GPU on this machine (use cpu or auto)"


def test_cli_device_cuda_without_a_gpu_exits_2_with_one_line(tmp_path, capsys):
    from viform.cli import main
    from viform.sensors.spike_cuda import cuda_available

    if cuda_available():
        pytest.skip("this machine has a CUDA GPU")
    out = tmp_path / "x.dat"
    code = main(["simulate", "hdr", "--duration", "0.001", "--height", "8", "--width", "8", "--out", str(out),
                 "--device", "cuda"])
    assert code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "--device = 'cuda'" in lines[0] and "no CUDA GPU" in lines[0]
    assert not any(tmp_path.iterdir())
