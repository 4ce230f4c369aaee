"""Shared fixtures: tiny source clips (32×24, 6 frames at 1 kHz = 240 ticks at 40 kHz) and dask clusters.

Cluster start-up costs seconds, so one 2-process cluster serves every test of the package.
"""

from __future__ import annotations

import logging
import os
import shutil
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

H, W, FRAMES, FRAME_RATE_HZ = 24, 32, 6, 1000.0
SHARED = Path(os.environ.get("VIFORM_SPIKE_DATA")
              or Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "spike")


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


def _local_client(n_workers: int, processes: bool):
    """A dask LocalCluster of ``n_workers`` single-thread workers and its client, closed after use."""
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=processes,
                                       dashboard_address=":0", silence_logs=logging.ERROR)
    client = distributed.Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


@pytest.fixture(scope="package")
def client1():
    """One worker, one thread, in this process (starts in well under a second)."""
    yield from _local_client(1, processes=False)


@pytest.fixture(scope="package")
def client2():
    """Two worker processes, one thread each (what `viform dataset --workers 2` starts)."""
    yield from _local_client(2, processes=True)


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


@pytest.fixture()
def source_with_broken_clip(source_clips, tmp_path) -> Path:
    """A copy of the source clips plus a folder 'broken' whose one frame is not a PNG."""
    src = tmp_path / "src"
    shutil.copytree(source_clips, src)
    (src / "broken").mkdir()
    (src / "broken" / "000.png").write_bytes(b"not a png")
    return src


@pytest.fixture()
def spike_zoo_layout(tmp_path) -> Path:
    """The Spike-Zoo 'base' layout: spike/<name>.dat, gt/<name>.png, config.yaml (links to the shared files)."""
    if not (SHARED / "reds_sim_400x250.dat").is_file():
        pytest.skip(f"shared spike data absent: {SHARED / 'reds_sim_400x250.dat'}")
    (tmp_path / "spike").mkdir()
    (tmp_path / "gt").mkdir()
    for name in ("reds_sim", "reds_sim2"):
        (tmp_path / "spike" / f"{name}.dat").symlink_to((SHARED / f"{name}_400x250.dat").resolve())
        (tmp_path / "gt" / f"{name}.png").symlink_to((SHARED / f"{name}_400x250_gt.png").resolve())
    (tmp_path / "config.yaml").write_text("filename: base\nspike_h: 250\nspike_w: 400\n")
    return tmp_path
