"""Images at many instants of a spike stream, for every method, in bounded memory (seed 000 §3.3).

:func:`reconstruct_ticks` yields one :class:`~viform.imaging.units.LightImage` per requested
tick, in order, holding only what one image needs: accumulation and interval imaging
stream through the file once (a sliding count / a carried previous spike), multi-interval
and motion-compensated imaging read around each instant. :func:`write_light_npz_stream`
writes the images into a ``.npz`` one frame at a time (the ``.npy`` member is written
incrementally into the zip), so whole-stream output never holds the whole result.
"""

from __future__ import annotations

import zipfile
from collections.abc import Iterator

import numpy as np

from viform._validate import ViformError, check_choice, check_int
from viform.imaging.accumulation import DEFAULT_ALIGN, check_align, sliding_accumulation, spike_counts, window_bounds
from viform.imaging.interval import interval_frames, interval_ticks
from viform.imaging.units import LightImage, light_from_rate
from viform.stream.container import SpikeSource

#: Reconstruction methods, as the CLI names them.
METHODS = ("accumulation", "interval", "multi-interval", "motion")

#: Default accumulation window, ticks (the common 41-tick "TFP" window).
DEFAULT_WINDOW_TICKS = 41


def _block_ticks(source) -> int:
    """Ticks per streamed block: 256, fewer on large sensors (a block's counts stay ≈ 32 MiB)."""
    return int(np.clip(2 ** 23 // max(1, source.height * source.width), 8, 256))


def _accumulation_stream(source, ticks, window, align, sensor_parameters):
    """Centred/ended/started windows from one pass of the sliding count (ends handled directly)."""
    n_total = source.n_ticks
    wanted = {int(k): window_bounds(int(k), window, n_total, align) for k in ticks}
    # the sliding count ending at tick e covers (e − window, e]: usable when the window is whole
    by_end = {}
    direct = []
    for k, (k0, k1) in wanted.items():
        if k1 - k0 == window:
            by_end.setdefault(k1 - 1, []).append(k)
        else:
            direct.append(k)
    ready = {}
    for k in direct:
        k0, k1 = wanted[k]
        ready[k] = spike_counts(source, k0, k1)
    order = sorted(wanted)
    pos = 0
    if by_end:
        last_end = max(by_end)
        for first, counts in sliding_accumulation(source, window, block_ticks=_block_ticks(source)):
            for e in range(first, min(first + counts.shape[0], last_end + 1)):
                for k in by_end.get(e, ()):
                    ready[k] = counts[e - first].astype(np.int64)
            while pos < len(order) and order[pos] in ready:
                yield _accumulation_image(source, order[pos], ready.pop(order[pos]), wanted, sensor_parameters,
                                          align)
                pos += 1
            if first + counts.shape[0] > last_end:
                break
    while pos < len(order):
        yield _accumulation_image(source, order[pos], ready.pop(order[pos]), wanted, sensor_parameters, align)
        pos += 1


def _accumulation_image(source, k, counts, wanted, sensor_parameters, align):
    k0, k1 = wanted[k]
    image = light_from_rate(counts / ((k1 - k0) / source.clock_hz), source, sensor_parameters,
                            method="accumulation", window_ticks=k1 - k0, first_tick=k0, align=align)
    return k, image


def _interval_stream(source, ticks, sensor_parameters):
    wanted = np.asarray(sorted(set(int(k) for k in ticks)))
    if wanted.size * 64 < source.n_ticks:  # few instants: search around each
        for k in wanted:
            tau, censored = interval_ticks(source, [k])
            yield int(k), _interval_image(source, tau[0], censored[0], sensor_parameters)
        return
    pos = 0
    for first, tau, censored in interval_frames(source, block_ticks=_block_ticks(source), with_censored=True,
                                                dtype=np.int64):
        while pos < wanted.size and wanted[pos] < first + tau.shape[0]:
            k = int(wanted[pos])
            # a view of the block's int64 array (no copy per frame)
            yield k, _interval_image(source, tau[k - first], censored[k - first].copy(), sensor_parameters)
            pos += 1
        if pos == wanted.size:
            break


def _interval_image(source, tau, censored, sensor_parameters):
    image = light_from_rate(source.clock_hz / tau, source, sensor_parameters, censored=censored, method="interval",
                            spikes_per_side=1)
    image.info["tau_ticks"] = tau
    return image


def reconstruct_ticks(source: SpikeSource, method: str, ticks, *, window_ticks: int = DEFAULT_WINDOW_TICKS,
                      align: str = DEFAULT_ALIGN, spikes_per_side: int | None = None, adaptive: bool = True,
                      sensor_parameters=None, progress: bool = False,
                      **motion_options) -> Iterator[tuple[int, LightImage]]:
    """Yield ``(tick, LightImage)`` for each of ``ticks`` (sorted), by ``method``.

    Parameters
    ----------
    method : {"accumulation", "interval", "multi-interval", "motion"}
        Accumulation over ``window_ticks`` aligned by ``align``; interval (Q/τ);
        multi-interval (``spikes_per_side``, ``adaptive``); motion-compensated accumulation
        (``motion_options`` go to :func:`~viform.imaging.motion.motion_compensated_image`).
    progress : bool
        Show a progress bar (tqdm, on stderr).
    """
    check_choice("method", method, METHODS)
    window = check_int("window_ticks", window_ticks, 1)
    align = check_align(align)
    ticks = sorted(int(k) for k in np.atleast_1d(ticks))
    if not ticks:
        raise ViformError("no instants to reconstruct: give at least one")
    if ticks[0] < 0 or ticks[-1] >= source.n_ticks:
        raise ViformError(f"tick {ticks[0] if ticks[0] < 0 else ticks[-1]} is outside the stream's "
                          f"[0, {source.n_ticks})")
    if method == "accumulation":
        frames = _accumulation_stream(source, ticks, window, align, sensor_parameters)
    elif method == "interval":
        frames = _interval_stream(source, ticks, sensor_parameters)
    else:
        frames = _per_instant(source, method, ticks, spikes_per_side, adaptive, sensor_parameters, motion_options)
    if progress:
        from tqdm import tqdm

        frames = tqdm(frames, total=len(ticks), unit="frame", desc=f"{method} images")
    yield from frames


def _per_instant(source, method, ticks, spikes_per_side, adaptive, sensor_parameters, motion_options):
    from viform.imaging.motion import motion_compensated_image
    from viform.imaging.multi_interval import DEFAULT_SPIKES_PER_SIDE, multi_interval_frames, spikes_used

    if method == "multi-interval":
        k_side = spikes_per_side or DEFAULT_SPIKES_PER_SIDE
        for k, rate, used, censored in multi_interval_frames(source, ticks, k_side, adaptive=adaptive):
            image = light_from_rate(rate * source.clock_hz, source, sensor_parameters, censored=censored,
                                    method="multi-interval", spikes_per_side=spikes_used(used, k_side),
                                    adaptive=adaptive)
            image.info["spikes_per_side"] = k_side
            image.info["intervals"] = used
            yield k, image
        return
    for k in ticks:
        t = source.start_time_s + (k + 0.5) / source.clock_hz
        yield k, motion_compensated_image(source, t, sensor_parameters=sensor_parameters, **motion_options)


class NpzFrameWriter:
    """Write ``(F, H, W)`` arrays into a ``.npz`` one frame at a time (bounded memory).

    Frames are appended to temporary ``.npy`` files (beside the target) that are packed
    into the zip, member by member, on :meth:`close`; ``np.load`` reads the result as an
    ordinary ``.npz``. ``path`` should be the temporary path of an atomic write.
    """

    def __init__(self, path, n_frames: int, frame_shape: tuple[int, int], arrays: dict):
        import tempfile
        from pathlib import Path

        self.path = Path(path)
        self.n_frames = n_frames
        self._folder = tempfile.TemporaryDirectory(prefix=f".{self.path.name}-", dir=self.path.parent)
        self._files = {}
        self._counts = {}
        self._small = {}
        for name, dtype in arrays.items():
            # a plain .npy file: the header (final shape) first, then frames appended as written
            handle = open(Path(self._folder.name) / f"{name}.npy", "wb")  # noqa: SIM115 (closed in close())
            np.lib.format.write_array_header_2_0(handle, {"descr": np.lib.format.dtype_to_descr(np.dtype(dtype)),
                                                          "fortran_order": False,
                                                          "shape": (n_frames, *frame_shape)})
            self._files[name] = (handle, np.dtype(dtype), tuple(frame_shape))
            self._counts[name] = 0

    def append(self, name: str, frame) -> None:
        handle, dtype, shape = self._files[name]
        frame = np.asarray(frame)
        if frame.shape != shape:
            raise ViformError(f"light.npz: a {name} frame has shape {frame.shape}, expected {shape}")
        handle.write(np.ascontiguousarray(frame, dtype=dtype).tobytes())
        self._counts[name] += 1

    def add_array(self, name: str, array) -> None:
        """A small whole array (times, ticks)."""
        self._small[name] = np.asarray(array)

    def abort(self) -> None:
        """Give up: close and remove the temporary frame files (nothing is written to ``path``)."""
        for handle, _, _ in self._files.values():
            handle.close()
        self._files.clear()
        self._folder.cleanup()

    def close(self) -> None:
        from pathlib import Path

        try:
            for handle, _, _ in self._files.values():
                handle.close()
            with zipfile.ZipFile(self.path, "w", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as archive:
                for name, array in self._small.items():
                    with archive.open(f"{name}.npy", "w", force_zip64=True) as member:
                        np.lib.format.write_array(member, array)
                for name in self._files:
                    if self._counts[name] != self.n_frames:
                        raise ViformError(f"light.npz: {name} got {self._counts[name]} frames, "
                                          f"expected {self.n_frames}")
                    archive.write(Path(self._folder.name) / f"{name}.npy", f"{name}.npy")
        finally:
            for handle, _, _ in self._files.values():
                handle.close()
            self._files.clear()
            self._folder.cleanup()
