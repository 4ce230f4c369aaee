"""The spike-camera / SpikeCV ``.dat`` layout: headerless packed bits, read block by block.

Layout (see ``shared/data/spike/SOURCES.md``): a sequence of frames, each holding H·W bits
in H·W/8 bytes; pixel k = r·W + c is bit (k mod 8) of byte k // 8, least significant bit
first; rows are stored bottom-up (the reader flips them upright; ``flip=False`` for
simulators that write upright). Older 400×250 recordings store 416 columns per row, the
last 16 being padding (``stored_width=416``, detected automatically when only that layout
fits the file size).

Height, width, clock and threshold are not stored in the file: viform writes them, with the
sensor description and provenance, to a JSON sidecar beside it (``clip.dat.json``, see
:mod:`viform.stream.sidecar`), which the reader uses when present; otherwise it is told them.

Integrity: the sidecar records the data's size, BLAKE2b and the CRC-32 of each block
(:mod:`viform.stream.checksums`). Every read checks the blocks holding the ticks it returns
before decoding them (a partial read costs a block or two); sidecars of version 1 (whole-file
BLAKE2b only) get the whole file checked before the first read. A ``.dat`` without a viform
sidecar is read unchecked (``verified`` is then False).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from viform._io import atomic_open
from viform._validate import ViformError, check_int, check_positive
from viform.stream.checksums import BlockCrcs, BlockReader, block_bytes_for, check_manifest
from viform.stream.container import SpikeSource, block_ticks_for
from viform.stream.sidecar import read_sidecar, sidecar_body, sidecar_path, source_metadata, stream_header

#: Readout clock assumed for ``.dat`` files when none is given, Hz (seed 000 §6: 40 kHz).
DEFAULT_DAT_CLOCK_HZ = 40_000.0
#: Largest height or width accepted (pixels).
MAX_SIDE = 1 << 16
#: Bytes read or written per block (bounded memory whatever the file length).
BLOCK_BYTES = 16 << 20


def _agree(path, name, given, declared):
    """The sidecar's value, or the caller's when it agrees; a contradiction is refused."""
    if declared is None:
        return given
    if given is not None and int(given) != int(declared):
        raise ViformError(f"{name} = {given} contradicts the sidecar of {str(path)!r}, which gives "
                          f"{int(declared)}: leave it out")
    return int(declared)


def check_dat_space(path, n_ticks: int, height: int, width: int) -> None:
    """Refuse a ``.dat`` that cannot fit on its disk, before anything is simulated or written.

    The file's size is exact (``n_ticks`` frames of ``height × width / 8`` bytes); the new file is
    written beside any old one and renamed over it, so the whole size must be free.

    Raises
    ------
    ViformError
        When the disk holding ``path`` has less free space than the file needs, or when
        ``height × width`` is not a multiple of 8 (whole bytes per frame).
    """
    import shutil

    path = Path(path)
    if (height * width) % 8:
        raise ViformError(f"height = {height} and width = {width} make {height * width} pixels, not a multiple of 8: "
                          "a .dat file packs whole bytes per frame; choose a size whose pixel count is a multiple "
                          "of 8, or save as .npz or .zarr")
    frame_bytes = _frame_bytes(height, width)
    needed = int(n_ticks) * frame_bytes
    folder = path.resolve().parent
    try:
        free = shutil.disk_usage(folder).free
    except OSError:  # the folder's own errors are reported where it is opened
        return
    if needed > free:
        raise ViformError(f"not enough disk space: {path.name} needs {_bytes_text(needed)} ({int(n_ticks):,} ticks × "
                          f"{frame_bytes:,} bytes) and {str(folder)!r} has {_bytes_text(free)} free; record "
                          "fewer ticks (a shorter duration) or write to another disk")


def _bytes_text(n: int) -> str:
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n} bytes"


def _frame_bytes(height: int, stored_width: int) -> int:
    bits = height * stored_width
    if bits % 8:
        raise ViformError(f"height = {height} rows × width = {stored_width} stored columns = {bits} bits is not a "
                          "multiple of 8: the .dat layout packs whole bytes per frame")
    return bits // 8


class DatFile(SpikeSource):
    """A ``.dat`` spike file, read block by block through the :class:`SpikeSource` interface.

    Parameters
    ----------
    path : path-like
        The file.
    height, width : int or None
        Image size (upright, without padding). Required unless the file has a sidecar
        (``clip.dat.json``, :mod:`viform.stream.sidecar`), which gives them, the clock, Q and
        the row order; a value contradicting the sidecar is refused.
    flip : bool or None
        True for files stored bottom-up, as the cameras and SpikeCV write them; None (default)
        takes the sidecar's row order, else True.
    stored_width : int or None
        Columns per stored row (416 for old 400-wide recordings); None detects it.
    clock_hz : float
        Readout clock, Hz (not stored in the file).
    threshold_electrons : float or None
        Threshold Q if known.
    allow_partial : bool
        When the file size is not a whole number of frames: False (default) refuses the
        file; True keeps the whole frames and ignores the trailing bytes.
    verify : bool or None
        True: check the whole file against its sidecar's size and BLAKE2b at open. None
        (default): check each block as it is read (version 1 sidecars: the whole file before
        the first read). Reads are never left unchecked when the sidecar has checksums.
    """

    def __init__(self, path, height: int | None = None, width: int | None = None, *, flip: bool | None = None,
                 stored_width: int | None = None, clock_hz: float | None = None,
                 threshold_electrons: float | None = None, allow_partial: bool = False,
                 start_time_s: float | None = None, use_sidecar: bool = True, verify: bool | None = None):
        path = Path(path)
        if not path.is_file():
            raise ViformError(f"spike file {str(path)!r} does not exist")
        side = read_sidecar(path) if use_sidecar else None
        self.sidecar = side
        if side is not None:
            height = _agree(path, "height", height, side.get("height"))
            width = _agree(path, "width", width, side.get("width"))
            if stored_width is None and side.get("stored_width") is not None:
                stored_width = int(side["stored_width"])
            if flip is None and side.get("rows") is not None:
                flip = side["rows"] == "bottom-up"
            if clock_hz is None:
                clock_hz = side.get("clock_hz")
            if threshold_electrons is None:
                threshold_electrons = side.get("threshold_electrons")
            if start_time_s is None:
                start_time_s = side.get("start_time_s")
        if height is None or width is None:
            where = (f"its sidecar {sidecar_path(path).name!r} does not give "
                     f"{' and '.join(k for k in ('height', 'width') if side.get(k) is None)}") if side is not None \
                else f"{sidecar_path(path).name!r} (the sidecar viform writes) is absent"
            raise ViformError(f"height and width are required to read {str(path)!r}: .dat files do not store "
                              f"them and {where}; give them, e.g. height=250 width=400")
        self.height = check_int("height", height, 1, MAX_SIDE)
        self.width = check_int("width", width, 1, MAX_SIDE)
        size = path.stat().st_size
        if stored_width is None:
            stored_width = self._detect_stored_width(size)
        self.stored_width = check_int("stored_width", stored_width, self.width, MAX_SIDE + 64)
        self.frame_bytes = _frame_bytes(self.height, self.stored_width)
        whole, rest = divmod(size, self.frame_bytes)
        if rest and not allow_partial:
            raise ViformError(
                f"{str(path)!r} holds {size} bytes, not a whole number of {self.stored_width}×{self.height} "
                f"frames ({self.frame_bytes} bytes each; {whole} whole frames and {rest} extra bytes)",
                remedies={**({} if side is not None and side.get("height") is not None else
                             {"height": f"check height={self.height} and width={self.width}"}),
                          "allow_partial": "keep the whole frames with allow_partial=True"})
        if whole == 0:
            raise ViformError(f"{str(path)!r} holds no whole frame of {self.frame_bytes} bytes")
        if side is not None and side.get("n_ticks") is not None and int(side["n_ticks"]) != whole \
                and not allow_partial:
            raise ViformError(f"{str(path)!r} holds {whole} frames but its sidecar declares "
                              f"n_ticks = {int(side['n_ticks'])}: the file was cut or replaced",
                              remedies={"allow_partial": "keep the whole frames with allow_partial=True"})
        self.path = path
        self._reader = None
        self._check_whole = False
        if side is not None and side.get("data_bytes") is not None:
            declared = int(side["data_bytes"])
            if declared != size and not allow_partial:
                raise ViformError(f"{str(path)!r} holds {size} bytes but its sidecar declares data_bytes = "
                                  f"{declared}: the file was cut or replaced")
            if declared % self.frame_bytes or (side.get("n_ticks") is not None
                                               and int(side["n_ticks"]) * self.frame_bytes != declared):
                raise ViformError(f"{str(sidecar_path(path))!r}: field 'data_bytes' = {declared} is not the "
                                  f"declared n_ticks × {self.frame_bytes} bytes a frame: the sidecar is damaged")
            whole = min(whole, declared // self.frame_bytes)  # only ticks the checksums cover
            if side.get("block_crc32") is not None:
                crcs = check_manifest(side["block_crc32"], side.get("block_bytes"), declared,
                                      repr(str(sidecar_path(path))))
                self._reader = BlockReader(crcs, side["block_bytes"], declared, self._pread, repr(str(path)))
            else:
                self._check_whole = True  # version 1: the whole file's BLAKE2b, before the first read
        if whole == 0:
            raise ViformError(f"{str(path)!r} holds no whole frame covered by its sidecar's checksums")
        self.flip = True if flip is None else bool(flip)
        self.n_ticks = whole
        self.clock_hz = check_positive("clock_hz", DEFAULT_DAT_CLOCK_HZ if clock_hz is None else clock_hz)
        self.threshold_electrons = (None if threshold_electrons is None
                                    else check_positive("threshold_electrons", threshold_electrons))
        self.start_time_s = 0.0 if start_time_s is None else float(start_time_s)
        self.metadata = source_metadata(side) if side is not None else {}
        self.metadata.update({"source": str(path), "format": "dat", "flip": self.flip,
                              "stored_width": self.stored_width})
        #: True when every read is checked against the sidecar's checksums (False: nothing to check against)
        self.checked = self._reader is not None or self._check_whole
        self._size = size
        if verify:
            self.verify()

    def verify(self) -> dict:
        """Check the file against its sidecar: size, and the BLAKE2b checksum when recorded.

        Returns ``{"verified": bool, "checks": [...]}``; raises :class:`ViformError` on a mismatch.
        """
        checks = []
        if self.sidecar is None:
            return {"verified": False, "checks": [f"no sidecar {sidecar_path(self.path).name!r}: nothing to "
                                                  "verify the data against"]}
        if self.sidecar.get("blake2b") is None:
            return {"verified": False, "checks": ["the sidecar holds no viform checksums (another tool's, or "
                                                  "viform's with its fields removed): nothing to verify the "
                                                  "data against"]}
        size = self.path.stat().st_size
        declared = self.sidecar.get("data_bytes")
        if declared is not None:
            if int(declared) != size:
                raise ViformError(f"{str(self.path)!r} holds {size} bytes but its sidecar declares {int(declared)}")
            checks.append(f"size {size} bytes matches the sidecar")
        digest = self.sidecar.get("blake2b")
        if digest:  # one pass: the BLAKE2b and, for version 2 sidecars, every block's CRC-32
            h = hashlib.blake2b(digest_size=16)
            blocks = BlockCrcs(self._reader.block_bytes) if self._reader is not None else None
            with open(self.path, "rb") as f:
                for chunk in iter(lambda: f.read(BLOCK_BYTES), b""):
                    h.update(chunk)
                    if blocks is not None:
                        blocks.update(chunk)
            if h.hexdigest() != digest:
                raise ViformError(f"{str(self.path)!r} is damaged: its BLAKE2b checksum differs from the one "
                                  "in its sidecar")
            checks.append("BLAKE2b checksum matches the sidecar")
            if blocks is not None:
                bad = [i for i, (a, b) in enumerate(zip(blocks.finish(), self._reader.crcs, strict=False)) if a != b]
                if bad or len(blocks.crcs) != len(self._reader.crcs):
                    raise ViformError(f"{str(self.path)!r}: its sidecar's block CRC-32s disagree with the data "
                                      f"(block {bad[0] if bad else len(blocks.crcs)}): the sidecar is damaged")
                checks.append(f"{len(self._reader.crcs)} block CRC-32s match the sidecar")
            self._check_whole = False
        return {"verified": bool(checks), "checks": checks or ["sidecar records no size or checksum"]}

    def _unverified_reason(self) -> str:
        name = sidecar_path(self.path).name
        if self.sidecar is None:
            return f"{str(self.path)!r} has no sidecar {name!r} (where viform records the data's checksums)"
        return (f"{str(self.path)!r}: its sidecar {name!r} holds no viform checksums (another tool's sidecar, or "
                "viform's with its fields removed)")

    def _pread(self, offset: int, count: int) -> bytes:
        with open(self.path, "rb") as f:
            return os.pread(f.fileno(), count, offset)

    def _detect_stored_width(self, size: int) -> int:
        fits = size % _frame_bytes(self.height, self.width) == 0
        if self.width == 400 and not fits and (self.height * 416) % 8 == 0 \
                and size % (self.height * 416 // 8) == 0:
            return 416
        return self.width

    def _before_reading(self, n_bytes: int) -> None:
        """What every read of ``n_bytes`` > 0 stored bytes does first: warn when the file has no
        checksums, and check a version-1 sidecar's whole-file checksum (it has no block checksums)."""
        if not n_bytes:
            return
        if not self.checked:
            self._say_unverified(self._unverified_reason())
        if self._check_whole:
            self.verify()

    def read_packed(self, start: int, stop: int) -> np.ndarray:
        """The stored bytes of ticks [start, stop) as they are in the file: (T, frame bytes) uint8.

        Each row holds ``height × stored_width`` bits, pixel k of the stored frame being bit
        k mod 8 of byte k // 8 (least significant first); rows are bottom-up when ``flip``.
        Checked against the sidecar's checksums exactly as :meth:`read_ticks`.
        """
        start, stop = max(0, start), min(stop, self.n_ticks)
        # positioned reads rather than a memory map: the resident memory stays one block whatever
        # the file size (mapped pages of a long file count against the process)
        want = (stop - start) * self.frame_bytes if stop > start else 0
        self._before_reading(want)
        if self._reader is not None:  # the blocks holding these ticks, each checked before use
            data = self._reader.read(start * self.frame_bytes, want)
        else:
            data = self._pread(start * self.frame_bytes, want) if want else b""
        if len(data) != want:
            raise ViformError(f"{str(self.path)!r} was cut while being read (ticks {start}–{stop - 1})")
        return np.frombuffer(data, np.uint8).reshape(-1, self.frame_bytes)

    def read_packed_words(self, start: int, stop: int, out: np.ndarray | None = None) -> np.ndarray:
        """The stored bits of ticks [start, stop) as little-endian words: (T, ⌈frame bytes / 8⌉) uint64.

        Row t holds :meth:`read_packed`'s row t, zero-padded to whole words. The checked
        blocks are copied into the rows once (no intermediate copy of the stored bytes).
        ``out``: a C-contiguous uint64 array of at least T rows of that width to fill and return
        (its first T rows), so that a reader of many blocks reuses its memory: fresh pages can cost
        more than the copy into them.
        """
        start, stop = max(0, start), min(stop, self.n_ticks)
        t = max(stop - start, 0)
        n_words = -(-self.frame_bytes // 8)
        if out is None:
            out = np.empty((t, n_words * 8), np.uint8)
        else:
            if (not isinstance(out, np.ndarray) or out.dtype != np.uint64 or out.ndim != 2 or out.shape[0] < t
                    or out.shape[1] != n_words or not out.flags.c_contiguous or not out.flags.writeable):
                raise ViformError(f"out must be a writable C-contiguous uint64 array of at least ({t}, {n_words}); "
                                  f"got {getattr(out, 'dtype', type(out).__name__)} {getattr(out, 'shape', '')}")
            out = out[:t].view(np.uint8)
        out[:, self.frame_bytes:] = 0
        want = t * self.frame_bytes
        self._before_reading(want)
        if self._reader is not None:  # the blocks holding these ticks, each checked before use
            pieces = self._reader.pieces(start * self.frame_bytes, want)
        else:
            pieces = [memoryview(self._pread(start * self.frame_bytes, want))] if want else []
        rows, fb, at = out[:, : self.frame_bytes], self.frame_bytes, 0
        for piece in pieces:
            data = np.frombuffer(piece, np.uint8)
            i = 0
            while i < data.size:  # a partial row, whole rows, a partial row
                r, c = divmod(at + i, fb)
                k = (data.size - i) // fb if c == 0 else 0
                if k:
                    rows[r:r + k] = data[i:i + k * fb].reshape(k, fb)
                    i += k * fb
                else:
                    m = min(fb - c, data.size - i)
                    rows[r, c:c + m] = data[i:i + m]
                    i += m
            at += data.size
        if at != want:
            raise ViformError(f"{str(self.path)!r} was cut while being read (ticks {start}–{stop - 1})")
        return out.view("<u8").astype(np.uint64, copy=False)

    def read_ticks(self, start: int, stop: int) -> np.ndarray:
        raw = self.read_packed(start, stop)
        bits = np.unpackbits(raw, axis=1, bitorder="little").view(bool)
        frames = bits.reshape(-1, self.height, self.stored_width)[:, :, : self.width]
        if self.flip:
            frames = frames[:, ::-1, :]
        return np.ascontiguousarray(frames)


def read_dat(path, height: int | None = None, width: int | None = None, **kwargs) -> DatFile:
    """Open a ``.dat`` spike file; see :class:`DatFile` for the options.

    Parameters
    ----------
    path : str or Path
        The ``.dat`` file.
    height, width : int, optional
        Size, pixels (needed without a sidecar).
    **kwargs
        :class:`DatFile`'s options (``clock_hz``, ``flip``, ``threshold_electrons``, ``allow_partial``).

    Returns
    -------
    DatFile
        The memory-mapped stream.
    """
    return DatFile(path, height, width, **kwargs)


def pack_frames(spikes: np.ndarray, flip: bool = True) -> bytes:
    """Pack bool frames (T, H, W) into the ``.dat`` byte layout.

    Parameters
    ----------
    spikes : ndarray of bool (T, H, W)
        One frame of spikes per tick.
    flip : bool
        Store rows bottom-up, as the cameras do.

    Returns
    -------
    bytes
        The ``.dat`` bytes of those ticks.
    """
    spikes = np.asarray(spikes, dtype=bool)
    if flip:
        spikes = spikes[:, ::-1, :]
    t, h, w = spikes.shape
    _frame_bytes(h, w)
    return np.packbits(spikes.reshape(t, h * w), axis=1, bitorder="little").tobytes()


def write_dat(path, source: SpikeSource, *, flip: bool = True, block_ticks: int = 2048,
              sidecar: bool = True) -> Path:
    """Write ``source`` as a ``.dat`` file, block by block and atomically, with its JSON sidecar.

    The sidecar (:func:`viform.stream.sidecar.stream_header` fields plus the data size and
    BLAKE2b checksum) is written beside the sidecar in place, as a pending sidecar
    (:func:`~viform.stream.sidecar.pending_sidecar_path`), before the data is renamed in, and
    renamed onto the sidecar right after. Whenever the writer is killed, one of the two
    sidecars matches the data under ``path``, and the next reader or writer keeps that one
    (:func:`~viform.stream.sidecar.settle_sidecar`). With ``sidecar=False`` an old sidecar is
    removed just before the data is renamed in (it would describe other bits): a kill between
    the two leaves the old data without a sidecar, never with a wrong one.

    Parameters
    ----------
    path : str or Path
        The ``.dat`` file to write.
    source : SpikeSource
        The spikes.
    flip : bool
        Store rows bottom-up, as the cameras do.
    block_ticks : int
        Ticks written per block (memory bound).
    sidecar : bool
        Write the JSON sidecar.

    Returns
    -------
    Path
        The file written.
    """
    from viform._io import clean_stale
    from viform.stream.sidecar import pending_sidecar_path, settle_sidecar

    path = Path(path)
    check_dat_space(path, source.n_ticks, source.height, source.width)
    # a simulator hands its packed bits as they are produced (bounded by its own budget)
    packed_blocks = getattr(source, "iter_packed_blocks", None)
    blocks = packed_blocks(block_ticks, flip) if packed_blocks is not None else None
    block_ticks = block_ticks_for(source.height, source.width, block_ticks)
    digest = hashlib.blake2b(digest_size=16)
    crcs = BlockCrcs(block_bytes_for(source.n_ticks * (source.height * source.width // 8)))
    size = 0
    side = sidecar_path(path)
    settle_sidecar(path)  # a pair left by a killed writer is made whole before anything is replaced
    clean_stale(side)  # temporaries of sidecars written by write_json (write_sidecar)
    pending = pending_sidecar_path(path)
    pending.unlink(missing_ok=True)  # a killed writer's whose data never arrived
    renamed = False
    body = old_side = written = None
    try:
        with atomic_open(path, "wb") as f:
            written = os.fstat(f.fileno())  # the new data's identity: is it under ``path`` after an interrupt?
            if blocks is None:
                blocks = ((first, pack_frames(block, flip)) for first, block in source.iter_blocks(block_ticks))
            for _, raw in blocks:
                raw = memoryview(raw).cast("B") if not isinstance(raw, bytes) else raw
                digest.update(raw)
                crcs.update(raw)
                size += len(raw)
                f.write(raw)
            f.flush()
            os.fsync(f.fileno())
            if sidecar:
                body = sidecar_body(stream_header(source, rows="bottom-up" if flip else "upright",
                                                  extra={"data_bytes": size, "blake2b": digest.hexdigest(),
                                                         "block_bytes": crcs.block_bytes,
                                                         "block_crc32": crcs.finish()}))
                with open(pending, "w", encoding="utf-8") as p:
                    p.write(json.dumps(body, indent=2) + "\n")
                    p.flush()
                    os.fsync(p.fileno())
            elif side.is_file():  # an old sidecar would describe other bits once the data is in
                old_side = side.read_bytes()
                side.unlink()
        renamed = True
        if body is not None:
            _finish_pair(pending, side, body)
    except BaseException:
        renamed = renamed or _holds(path, written)  # an interrupt held during the data's rename comes after it
        if renamed and body is not None:  # interrupted between the renames: finish the pair
            _finish_pair(pending, side, body)
        else:
            pending.unlink(missing_ok=True)
            if not renamed and old_side is not None:  # the old data stays: so does its sidecar
                with atomic_open(side, "wb") as f:
                    f.write(old_side)
        raise
    return path


def _holds(path: Path, written) -> bool:
    """Whether the file at ``path`` is the one whose ``os.fstat`` is ``written``."""
    if written is None:
        return False
    try:
        now = os.stat(path)
    except OSError:
        return False
    return (now.st_dev, now.st_ino) == (written.st_dev, written.st_ino)


def _finish_pair(pending: Path, side: Path, body: dict) -> None:
    """Second rename of :func:`write_dat`: the pending sidecar (holding ``body``) goes in."""
    from viform._io import write_json
    from viform.stream.sidecar import DIGEST_KEY, _intact

    try:
        os.replace(pending, side)
    except FileNotFoundError:  # a reader found the new data first and renamed it in (settle_sidecar)
        if (_intact(side) or {}).get(DIGEST_KEY) != body[DIGEST_KEY]:
            write_json(side, body)  # whatever removed it, the data needs its sidecar
