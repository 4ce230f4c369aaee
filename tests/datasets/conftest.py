"""Shared fixtures: tiny source clips (32×24, 6 frames at 1 kHz = 240 ticks at 40 kHz) and dask clusters.

Cluster start-up costs seconds, so one 2-process cluster serves every test of the package.
"""

from __future__ import annotations

import logging
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

H, W, FRAMES, FRAME_RATE_HZ = 24, 32, 6, 1000.0
SHARED = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "spike"


def make_clips(root: Path, n_folders: int = 3, gif: bool = True) -> Path:
    """Frame folders clip0.. (a texture sliding 1 px per frame) and one GIF video."""
    rng = np.random.default_rng(1)
    root.mkdir(parents=True, exist_ok=True)
    for c in range(n_folders):
        folder = root / f"clip{c}"
        folder.mkdir()
        base = rng.integers(0, 256, (H, W)).astype(np.uint8)
        for k in range(FRAMES):
            iio.imwrite(folder / f"{k:08d}.png", np.roll(base, k, axis=1))
    if gif:
        frames = rng.integers(0, 256, (FRAMES, H, W)).astype(np.uint8)
        iio.imwrite(root / "video3.gif", frames, duration=1)
    return root


@pytest.fixture(scope="package")
def source_clips(tmp_path_factory) -> Path:
    return make_clips(tmp_path_factory.mktemp("clips") / "src")


@pytest.fixture(scope="package")
def settings():
    from viform.datasets import make_settings

    return make_settings(height=H, width=W, frame_rate_hz=FRAME_RATE_HZ, gt_every=2, seed=7)


@pytest.fixture(scope="package")
def client1():
    """One worker, one thread, in this process (starts in well under a second)."""
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                       dashboard_address=":0", silence_logs=logging.ERROR)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.fixture(scope="package")
def client2():
    """Two worker processes, one thread each (what `viform dataset --workers 2` starts)."""
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=":0", silence_logs=logging.ERROR)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.fixture(scope="package")
def reference(tmp_path_factory, source_clips, settings, client1) -> Path:
    """The 4-clip dataset converted by one worker."""
    from viform.datasets import build_dataset

    out = tmp_path_factory.mktemp("ref") / "ds"
    summary = build_dataset(source_clips, out, settings, client=client1, block_ticks=64, progress=False)
    assert summary["converted"] == 4 and not summary["failed"], summary
    return out


def _dataset_files(root: Path) -> dict[str, bytes]:
    """Every spike and ground-truth file and the manifest, by relative path (sidecars hold dates)."""
    files = sorted(p for p in root.rglob("*") if p.is_file() and not p.name.endswith(".json"))
    out = {str(p.relative_to(root)): p.read_bytes() for p in files if p.suffix in (".dat", ".png")}
    out["manifest.json"] = (root / "manifest.json").read_bytes()
    return out


@pytest.fixture(scope="package")
def dataset_files():
    return _dataset_files


@pytest.fixture(scope="package")
def clip_maker():
    return make_clips
