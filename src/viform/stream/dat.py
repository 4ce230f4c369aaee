"""The spike-camera / SpikeCV ``.dat`` layout: headerless packed bits, memory-mapped.

Layout (see ``shared/data/spike/SOURCES.md``): a sequence of frames, each holding H·W bits
in H·W/8 bytes; pixel k = r·W + c is bit (k mod 8) of byte k // 8, least significant bit
first; rows are stored bottom-up (the reader flips them upright; ``flip=False`` for
simulators that write upright). Older 400×250 recordings store 416 columns per row, the
last 16 being padding (``stored_width=416``, detected automatically when only that layout
fits the file size).

Height, width, clock and threshold are not stored in the file; the reader is told them.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from viform._io import atomic_open
from viform._validate import ViformError, check_int, check_positive
from viform.stream.container import SpikeSource

#: Readout clock assumed for ``.dat`` files when none is given, Hz (seed 000 §6: 40 kHz).
DEFAULT_DAT_CLOCK_HZ = 40_000.0


def _frame_bytes(height: int, stored_width: int) -> int:
    bits = height * stored_width
    if bits % 8:
        raise ViformError(f"height × width = {height}×{stored_width} is not a multiple of 8 bits; "
                          "the .dat layout packs whole bytes per frame")
    return bits // 8


class DatFile(SpikeSource):
    """A memory-mapped ``.dat`` spike file, read through the :class:`SpikeSource` interface.

    Parameters
    ----------
    path : path-like
        The file.
    height, width : int
        Image size (upright, without padding). Required: the file does not store them.
    flip : bool
        True (default) for files stored bottom-up, as the cameras and SpikeCV write them.
    stored_width : int or None
        Columns per stored row (416 for old 400-wide recordings); None detects it.
    clock_hz : float
        Readout clock, Hz (not stored in the file).
    threshold_electrons : float or None
        Threshold Q if known.
    allow_partial : bool
        When the file size is not a whole number of frames: False (default) refuses the
        file; True keeps the whole frames and ignores the trailing bytes.
    """

    def __init__(self, path, height: int | None, width: int | None, *, flip: bool = True,
                 stored_width: int | None = None, clock_hz: float = DEFAULT_DAT_CLOCK_HZ,
                 threshold_electrons: float | None = None, allow_partial: bool = False,
                 start_time_s: float = 0.0):
        path = Path(path)
        if height is None or width is None:
            raise ViformError(f"height and width are required to read {str(path)!r}: "
                              ".dat files do not store them (e.g. --height 250 --width 400)")
        self.height = check_int("height", height, 1)
        self.width = check_int("width", width, 1)
        if not path.is_file():
            raise ViformError(f"spike file {str(path)!r} does not exist")
        size = path.stat().st_size
        if stored_width is None:
            stored_width = self._detect_stored_width(size)
        self.stored_width = check_int("stored_width", stored_width, self.width)
        self.frame_bytes = _frame_bytes(self.height, self.stored_width)
        whole, rest = divmod(size, self.frame_bytes)
        if rest and not allow_partial:
            raise ViformError(
                f"{str(path)!r} holds {size} bytes, not a whole number of {self.height}×{self.stored_width} "
                f"frames ({self.frame_bytes} bytes each; {whole} whole frames and {rest} extra bytes): "
                "check --height/--width, or keep the whole frames with --allow-partial")
        if whole == 0:
            raise ViformError(f"{str(path)!r} holds no whole frame of {self.frame_bytes} bytes")
        self.path = path
        self.flip = bool(flip)
        self.n_ticks = whole
        self.clock_hz = check_positive("clock_hz", clock_hz)
        self.threshold_electrons = threshold_electrons
        self.start_time_s = float(start_time_s)
        self.metadata = {"source": str(path), "format": "dat", "flip": self.flip,
                         "stored_width": self.stored_width}
        self._bytes = np.memmap(path, dtype=np.uint8, mode="r", shape=(whole, self.frame_bytes))

    def _detect_stored_width(self, size: int) -> int:
        fits = size % _frame_bytes(self.height, self.width) == 0
        if self.width == 400 and not fits and (self.height * 416) % 8 == 0 \
                and size % (self.height * 416 // 8) == 0:
            return 416
        return self.width

    def read_ticks(self, start: int, stop: int) -> np.ndarray:
        start, stop = max(0, start), min(stop, self.n_ticks)
        raw = np.asarray(self._bytes[start:stop])
        bits = np.unpackbits(raw, axis=1, bitorder="little").view(bool)
        frames = bits.reshape(-1, self.height, self.stored_width)[:, :, : self.width]
        if self.flip:
            frames = frames[:, ::-1, :]
        return np.ascontiguousarray(frames)


def read_dat(path, height: int | None, width: int | None, **kwargs) -> DatFile:
    """Open a ``.dat`` spike file (memory-mapped); see :class:`DatFile` for the options."""
    return DatFile(path, height, width, **kwargs)


def pack_frames(spikes: np.ndarray, flip: bool = True) -> bytes:
    """Pack bool frames (T, H, W) into the ``.dat`` byte layout."""
    spikes = np.asarray(spikes, dtype=bool)
    if flip:
        spikes = spikes[:, ::-1, :]
    t, h, w = spikes.shape
    _frame_bytes(h, w)
    return np.packbits(spikes.reshape(t, h * w), axis=1, bitorder="little").tobytes()


def write_dat(path, source: SpikeSource, *, flip: bool = True, block_ticks: int = 2048) -> Path:
    """Write ``source`` as a ``.dat`` file, block by block and atomically."""
    path = Path(path)
    _frame_bytes(source.height, source.width)
    with atomic_open(path, "wb") as f:
        for _, block in source.iter_blocks(block_ticks):
            f.write(pack_frames(block, flip))
        f.flush()
        os.fsync(f.fileno())
    return path
