"""Spike streams in ``.npz`` archives, read and written in bounded memory.

Layout written by viform (readable by plain ``numpy.load`` and by Spike-Zoo loaders):

- ``spk``: uint8 array of 0/1, shape (T, H, W) — the key and axis order Spike-Zoo uses;
- ``viform_header``: a 0-d string array holding the JSON header (:mod:`viform.stream.sidecar`:
  resolution, clock, Q, optics, dark current, scene, seed, provenance, ``axes``);
- ``clock_hz``, ``threshold_electrons`` (NaN when unknown), ``start_time_s``: scalars, for
  readers that do not parse the header.

The spike member is streamed: its ``.npy`` header is read from the zip member, then ticks are
read block by block as the member decompresses, so neither the file length nor a forged shape
costs memory (a shape that disagrees with the member's size is refused at open).

Integrity: viform's header (written after ``spk``) holds ``format``, ``version``, the member's
size, the CRC-32 of each block of it and the header's own BLAKE2b; every read checks the
blocks it uses before decoding them, so a partial read (``reconstruct --at``) never returns
damaged bits and costs only those blocks. A header holding any field only viform writes (its
integrity fields, or the provenance ``viform_version``, ``command_line``, ``utc_date``) must
hold them all; fields viform does not write are refused. The archive must account for every
byte of the file: bytes before the first member or after the zip's end record are refused.

Files of other tools have no viform checksums: their data is read *unverified* (an
:class:`~viform._validate.UnverifiedDataWarning` says so at the first read). The zip CRC-32 of a
spike member of at most :data:`WHOLE_CHECK_BYTES` is checked by one streamed pass before the
first read; a bigger member is read only as far as a read needs (the work of a partial read is
bounded by what it reads; its zip CRC-32 is checked when a read reaches the member's end, as
``verify`` does).

Axis order: viform's own files declare it; the arrays named ``spk`` and ``spikes`` are
(T, H, W) by the Spike-Zoo and viform conventions; any other array must be given an explicit
``axes`` (e.g. ``"hwt"``), never guessed. Arrays that are not (T, H, W) in C order are
transposed in memory, up to :data:`MAX_WHOLE_BYTES` (beyond that, convert to ``.zarr``).
"""

from __future__ import annotations

import io
import json
import math
import tokenize
import zipfile
import zlib
from pathlib import Path

import numpy as np

from viform._io import atomic_path
from viform._validate import ViformError
from viform.stream.checksums import BlockCrcs, BlockReader, block_bytes_for, check_manifest, header_digest
from viform.stream.container import SpikeSource, block_ticks_for
from viform.stream.sidecar import (
    HEADER_FIELDS,
    MAX_DIMENSION,
    MAX_TICKS,
    check_consistent,
    source_metadata,
    stream_header,
    validate_header,
)

#: Keys read by default, in this order (Spike-Zoo's, then viform's older one); both are (T, H, W).
DEFAULT_KEYS = ("spk", "spikes")
HEADER_KEY = "viform_header"
#: ``format`` and ``version`` of the header viform writes (inside its checksummed part).
NPZ_FORMAT = "viform-spikes-npz"
NPZ_VERSION = 2
#: Header fields of viform's integrity scheme: a header holding one must hold all.
_INTEGRITY_FIELDS = ("format", "version", "member_bytes", "block_bytes", "block_crc32", "header_blake2b")
#: Fields only viform writes in the header (its integrity fields and provenance): a header holding
#: any of them is viform's and must be whole.
_MARKS = _INTEGRITY_FIELDS + ("viform_version", "command_line", "utc_date")
#: Every field of the header viform writes.
_HEADER_FIELDS = HEADER_FIELDS + ("axes",) + _INTEGRITY_FIELDS
#: Largest spike member of another tool's file whose zip CRC-32 is checked by a pass over it before
#: the first read (bytes; about 0.3 s of inflating). A bigger one is read as far as each read needs.
WHOLE_CHECK_BYTES = 256 << 20
#: Largest array loaded whole (one not stored as (T, H, W) in C order), bytes.
MAX_WHOLE_BYTES = 256 << 20
#: Largest small member (header, scalars) read, bytes.
MAX_SMALL_MEMBER_BYTES = 4 << 20
_ERRORS = (zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError, KeyError, NotImplementedError,
           RuntimeError, OverflowError, UnicodeDecodeError, tokenize.TokenError, SyntaxError, TypeError,
           RecursionError)  # (numpy parses a damaged .npy header with tokenize and ast)
#: Members whose value viform uses: one that cannot be read is refused, never skipped.
_SCALARS = ("clock_hz", "threshold_electrons", "start_time_s")


def _check_axes(axes) -> str | None:
    if axes is None:
        return None
    if not isinstance(axes, str) or sorted(axes.lower()) != ["h", "t", "w"]:
        raise ViformError(f"axes = {axes!r} is not allowed: give the order of the array's axes as a "
                          "permutation of 't', 'h', 'w', e.g. 'thw' or 'hwt'")
    return axes.lower()


class NpzSpikes(SpikeSource):
    """A spike stream in a ``.npz`` archive, read block by block from the zip member.

    Parameters
    ----------
    path : path-like
    clock_hz : float or None
        Readout clock; None takes the file's (or 40 kHz when it has none).
    key : str or None
        The array's name; None takes ``spk`` or ``spikes``.
    axes : str or None
        Axis order of the array (a permutation of ``"thw"``); None takes the declared one or,
        for ``spk``/``spikes``, ``"thw"``. Required for other arrays.
    """

    def __init__(self, path, clock_hz: float | None = None, key: str | None = None, axes: str | None = None):
        from viform.stream.dat import DEFAULT_DAT_CLOCK_HZ

        path = Path(path)
        self.path = path
        axes = _check_axes(axes)
        if not path.is_file():
            raise ViformError(f"spike file {str(path)!r} does not exist")
        try:
            if not zipfile.is_zipfile(path):
                raise ViformError(f"{str(path)!r} is not a .npz file (not a zip archive)")
            self._zip = zipfile.ZipFile(path)
            _check_layout(path, self._zip)
            infos = {i.filename: i for i in self._zip.infolist()}
            if len(infos) != len(self._zip.infolist()):  # readers disagree on which one counts
                twice = sorted({i.filename for i in self._zip.infolist()
                                if sum(j.filename == i.filename for j in self._zip.infolist()) > 1})
                raise ViformError(f"{str(path)!r} is damaged or was tampered with: it holds several members "
                                  f"named {twice[0]!r}")
        except ViformError:
            raise
        except _ERRORS as exc:
            raise ViformError(f"{str(path)!r} could not be read as .npz: {_short(exc)}") from None
        names = [n[:-4] for n in infos if n.endswith(".npy")]
        if key is None:
            key = next((k for k in DEFAULT_KEYS if k in names), None)
            if key is None:
                raise ViformError(f"{str(path)!r} has no 'spk' or 'spikes' array (it has {names[:20]}); "
                                  "choose one with key = NAME")
        elif key not in names:
            raise ViformError(f"{str(path)!r} has no array {key!r} (it has {names[:20]})")
        self.key = key
        small = {}
        for name in names:
            if name == key:
                continue
            info = infos[name + ".npy"]
            if info.file_size > MAX_SMALL_MEMBER_BYTES:
                if name in (HEADER_KEY, *_SCALARS):
                    raise ViformError(f"{str(path)!r}: member {name!r} holds {info.file_size} bytes, more than the "
                                      f"{MAX_SMALL_MEMBER_BYTES} a header or a number may")
                continue  # not a scalar: not metadata
            value = self._read_small(name + ".npy")
            if value is not None:
                small[name] = value
        header = {}
        if HEADER_KEY in small:
            try:
                header = json.loads(str(small.pop(HEADER_KEY)))
            except (ValueError, RecursionError) as exc:
                raise ViformError(f"{str(path)!r}: member {HEADER_KEY!r} is not valid JSON: {_short(exc)}") from None
            if not isinstance(header, dict):
                raise ViformError(f"{str(path)!r}: member {HEADER_KEY!r} must hold a JSON object")
            marked = _check_integrity_fields(header, path)
            validate_header(header, path, required=("height", "width", "clock_hz", "start_time_s"))
            if "threshold_electrons" not in header:
                raise ViformError(f"{str(path)!r}: required field 'threshold_electrons' is missing from "
                                  f"member {HEADER_KEY!r}")
        else:
            marked = False
        declared_axes = header.get("axes")
        if declared_axes is not None:
            declared_axes = _check_axes(declared_axes)
            if axes is not None and axes != declared_axes:
                raise ViformError(f"axes = {axes!r} contradicts {str(path)!r}, which declares axes "
                                  f"{declared_axes!r}")
        if axes is None:
            axes = declared_axes or ("thw" if key in DEFAULT_KEYS else None)
        # scalars of older viform files and other tools (clock, Q, start; labels go to the metadata)
        legacy = {k: small.pop(k) for k in ("clock_hz", "threshold_electrons", "start_time_s") if k in small}
        self._open_member(key + ".npy", infos[key + ".npy"])
        if marked:  # viform's own file: per-block CRC-32s of the member (its .npy header included)
            if key != "spk" or header.get("member_bytes") != self._member_bytes:
                raise ViformError(f"{str(path)!r}: array {key!r} holds {self._member_bytes} bytes but member "
                                  f"{HEADER_KEY!r} declares member_bytes = {header.get('member_bytes')!r} for 'spk': "
                                  "the file is damaged or was edited")
            crcs = check_manifest(header.get("block_crc32"), header.get("block_bytes"), self._member_bytes,
                                  f"{str(path)!r}: member {HEADER_KEY!r}")
            self._blocks = BlockReader(crcs, header["block_bytes"], self._member_bytes, self._member_read,
                                       f"{str(path)!r} (array {key!r})")
            self._blocks.read(0, self._header_bytes)  # shape, order and dtype are checked too
        if axes is None:
            raise ViformError(f"{str(path)!r}: the axis order of array {key!r} (shape {self._shape}) is not "
                              "declared: give it with axes = 'thw' (ticks, rows, columns) or 'hwt' (rows, columns, "
                              "ticks)")
        self.axes = axes
        dims = dict(zip(axes, self._shape, strict=True))
        self.n_ticks, self.height, self.width = dims["t"], dims["h"], dims["w"]
        if not (1 <= self.height <= MAX_DIMENSION and 1 <= self.width <= MAX_DIMENSION
                and 0 <= self.n_ticks <= MAX_TICKS):
            raise ViformError(f"{str(path)!r}: array {key!r} has shape {self._shape} (axes {axes!r}): height and "
                              f"width must lie in [1, {MAX_DIMENSION}]")
        for name, dim in (("height", self.height), ("width", self.width), ("n_ticks", self.n_ticks)):
            if header.get(name) is not None and int(header[name]) != dim:
                raise ViformError(f"{str(path)!r}: the header declares {name} = {header[name]} but array {key!r} "
                                  f"has {dim}")
        self._whole = None
        if axes != "thw" or self._fortran:
            if self._data_bytes > MAX_WHOLE_BYTES:
                raise ViformError(f"{str(path)!r}: array {key!r} is not stored as (ticks, rows, columns) in C order "
                                  f"and holds {self._data_bytes / 1e6:.0f} MB, more than the "
                                  f"{MAX_WHOLE_BYTES / 1e6:.0f} MB viform transposes in memory: convert it to .zarr")
        clock = clock_hz if clock_hz is not None else header.get("clock_hz", _scalar(legacy, "clock_hz", path))
        clock = DEFAULT_DAT_CLOCK_HZ if clock is None else clock
        q = header["threshold_electrons"] if "threshold_electrons" in header \
            else _scalar(legacy, "threshold_electrons", path)
        start = header.get("start_time_s", _scalar(legacy, "start_time_s", path))
        # the same bounds as viform's own header, before anything is sized by them
        check = {"clock_hz": clock,
                 "threshold_electrons": None if q is None or (isinstance(q, float) and math.isnan(q)) else q,
                 "start_time_s": 0.0 if start is None else start, "n_ticks": self.n_ticks}
        validate_header(check, path, required=())
        self.clock_hz = float(check["clock_hz"])
        check["threshold_electrons"] = None if check["threshold_electrons"] is None \
            else float(check["threshold_electrons"])
        check["start_time_s"] = float(check["start_time_s"])
        self.threshold_electrons = check["threshold_electrons"]
        self.start_time_s = check["start_time_s"]
        self.header = header
        self.metadata = source_metadata(header) if header else {}
        for name, value in small.items():
            if np.ndim(value) == 0 and name not in self.metadata:
                item = np.asarray(value).item()
                self.metadata[name] = item.decode() if isinstance(item, bytes) else item
        self.metadata.update({"source": str(path), "format": "npz"})
        #: True when every read is checked against viform's block CRC-32s (False: another tool's file,
        #: read unverified; the zip CRC-32 of its member is still checked, see the module docstring).
        self.checked = self._blocks is not None

    # ---- zip member access
    def _read_small(self, member: str):
        damage = (zipfile.BadZipFile, zlib.error, EOFError, OSError)
        try:
            with self._zip.open(member) as fp:
                try:
                    value = np.lib.format.read_array(fp, allow_pickle=False)
                except damage:
                    raise
                except _ERRORS:
                    value = None  # an object (pickled) or exotic array from another tool: not our metadata
                while fp.read(1 << 20):  # to the end, unparsable or not: the zip CRC is checked
                    pass
        except damage as exc:  # damage: never ignored
            raise ViformError(f"{str(self.path)!r}: member {member!r} is damaged: {_short(exc)}") from None
        if value is None and member[:-4] in (HEADER_KEY, *_SCALARS):
            raise ViformError(f"{str(self.path)!r}: member {member!r} cannot be read as a .npy array of numbers "
                              "or text")
        return value

    def _open_member(self, member: str, info: zipfile.ZipInfo) -> None:
        self._member = member
        self._fp, self._pos = None, 0
        self._blocks = None
        self._zip_checked = False
        self._member_bytes = info.file_size
        self._parse_npy_header()
        self._data_bytes = info.file_size - self._header_bytes
        expected = math.prod(self._shape) * self._dtype.itemsize
        if self._data_bytes != expected:
            raise ViformError(f"{str(self.path)!r}: array {self.key!r} declares shape {self._shape} of "
                              f"{self._dtype} ({expected} bytes) but the archive holds {self._data_bytes} bytes")

    def _parse_npy_header(self) -> None:
        """Read the member's .npy header (shape, order, dtype) from a fresh stream of the member."""
        path = self.path
        try:
            with self._zip.open(self._member) as fp:
                version = np.lib.format.read_magic(fp)
                if version == (1, 0):
                    shape, fortran, dtype = np.lib.format.read_array_header_1_0(fp)
                elif version == (2, 0):
                    shape, fortran, dtype = np.lib.format.read_array_header_2_0(fp)
                else:
                    raise ViformError(f"{str(path)!r}: array {self.key!r} uses .npy format {version}, "
                                      "which viform does not stream (1.0 and 2.0 are read)")
                header_bytes = fp.tell()
        except ViformError:
            raise
        except _ERRORS as exc:
            raise ViformError(f"{str(path)!r}: array {self.key!r} has a damaged .npy header: {_short(exc)}") from None
        if dtype.kind not in "biu" or dtype.itemsize > 8 or dtype.hasobject:
            raise ViformError(f"{str(path)!r}: array {self.key!r} has dtype {dtype}; spikes must be bool or "
                              "whole numbers 0/1")
        if len(shape) != 3:
            raise ViformError(f"{str(path)!r}: array {self.key!r} must have 3 axes (ticks, rows, columns); "
                              f"got shape {shape}")
        self._shape, self._fortran, self._dtype = tuple(int(n) for n in shape), bool(fortran), dtype
        self._header_bytes = header_bytes

    def _member_read(self, offset: int, count: int) -> bytes:
        """Up to ``count`` bytes of the spike member from ``offset`` (member coordinates, .npy header
        included); sequential reads are cheap, a read behind the position decompresses from the start.
        Reading to the member's end checks its zip CRC-32."""
        try:
            if self._fp is None or offset < self._pos:
                if self._fp is not None:
                    self._fp.close()
                self._fp, self._pos = self._zip.open(self._member), 0
            if offset > self._pos:
                self._skip(offset - self._pos)
            data = self._fp.read(count)
            self._pos += len(data)
            if self._pos == self._member_bytes and not self._zip_checked:
                if self._fp.read(1):
                    raise ViformError(f"{str(self.path)!r}: array {self.key!r} holds more data than its shape")
                self._zip_checked = True  # zipfile compared the CRC-32 at the end of the member
        except ViformError:
            raise
        except _ERRORS as exc:
            raise ViformError(f"{str(self.path)!r}: array {self.key!r} is damaged: {_short(exc)}") from None
        return data

    def _check_member(self, keep: tuple[int, int] = (0, 0)) -> bytes:
        """A streamed pass over the whole member: its zip CRC-32 is checked before any of it is used.

        Returns the ``keep = (offset, count)`` bytes it passed (member coordinates), so the read
        that asked for the check does not decompress the member a second time.
        """
        offset, count = keep
        kept = bytearray()
        pos, step = 0, 8 << 20
        while pos < self._member_bytes:
            n = min(step, self._member_bytes - pos)
            chunk = self._member_read(pos, n)
            if len(chunk) != n:
                raise ViformError(f"{str(self.path)!r}: array {self.key!r} is truncated")
            if pos < offset + count and offset < pos + n:
                kept += chunk[max(0, offset - pos): offset + count - pos]
            pos += n
        return kept

    def _read_bytes(self, offset: int, count: int) -> bytes:
        """``count`` bytes of the array's data from ``offset``, checked before they are returned.

        viform's files: the CRC-32 of each block holding them (:mod:`viform.stream.checksums`).
        Other files: the member's zip CRC-32, by one streamed pass before the first read (a read
        of the whole array is that pass).
        """
        if self._blocks is not None:
            data = self._blocks.read(self._header_bytes + offset, count)
        elif not self._zip_checked and self._member_bytes <= WHOLE_CHECK_BYTES:
            self._say_unverified(f"{str(self.path)!r} holds no viform checksums (another tool's .npz, or viform's "
                                 "header removed; the zip CRC-32 of its spikes is checked)")
            data = self._check_member((self._header_bytes + offset, count))  # one pass, CRC-32 at the end
        else:
            if not self._zip_checked:
                self._say_unverified(
                    f"{str(self.path)!r} holds no viform checksums (another tool's .npz, or viform's header "
                    f"removed), and the zip CRC-32 of its {self._member_bytes / 1e9:.3g} GB spike member is "
                    "checked only by a read to its end (viform verify)")
            data = self._member_read(self._header_bytes + offset, count)
        if len(data) != count:
            raise ViformError(f"{str(self.path)!r}: array {self.key!r} is truncated (data ends "
                              f"{count - len(data)} bytes early)")
        return data

    def _skip(self, count: int) -> None:
        step = 8 << 20
        while count > 0:
            got = len(self._fp.read(min(step, count)))
            if got == 0:
                raise ViformError(f"{str(self.path)!r}: array {self.key!r} is truncated")
            count -= got
            self._pos += got

    def _to_bool(self, raw: np.ndarray) -> np.ndarray:
        if raw.dtype != bool:
            if raw.size and (raw.max() > 1 or raw.min() < 0):
                raise ViformError(f"{str(self.path)!r}: array {self.key!r} holds values other than 0 and 1 "
                                  f"(e.g. {int(raw.max()) if raw.max() > 1 else int(raw.min())})")
            raw = raw.astype(bool)
        return raw

    def _whole_array(self) -> np.ndarray:
        if self._whole is None:
            raw = np.frombuffer(self._read_bytes(0, self._data_bytes), dtype=self._dtype)
            raw = raw.reshape(self._shape, order="F" if self._fortran else "C")
            order = [self.axes.index(c) for c in "thw"]
            self._whole = np.ascontiguousarray(self._to_bool(np.transpose(raw, order)))
        return self._whole

    def read_ticks(self, start: int, stop: int) -> np.ndarray:
        start, stop = max(0, start), min(stop, self.n_ticks)
        if stop <= start:
            return np.zeros((0, self.height, self.width), bool)
        if self.axes != "thw" or self._fortran:
            return self._whole_array()[start:stop]
        frame = self.height * self.width * self._dtype.itemsize
        raw = np.frombuffer(self._read_bytes(start * frame, (stop - start) * frame), dtype=self._dtype)
        return self._to_bool(raw.reshape(stop - start, self.height, self.width))

    def iter_blocks(self, block_ticks: int = 1024, start: int = 0, stop: int | None = None):
        # a byte budget per block, counted in the stored dtype (int64 arrays are 8 bytes a pixel)
        block_ticks = block_ticks_for(self.height, self.width * self._dtype.itemsize, block_ticks)
        yield from super().iter_blocks(block_ticks, start, stop)

    def verify(self) -> dict:
        """Read every member to its end (zip CRC-32 checked) and the spikes (values 0/1).

        ``verified`` is True only for viform's files (every block against its CRC-32); another
        tool's file is read whole, but nothing it carries can tell an edit from the original.
        """
        self._unverified_said = True  # the result says so
        for info in self._zip.infolist():
            if info.filename == self._member:
                continue
            try:
                with self._zip.open(info) as fp:
                    while fp.read(8 << 20):
                        pass
            except _ERRORS as exc:
                raise ViformError(f"{str(self.path)!r}: member {info.filename!r} is damaged: {_short(exc)}") from None
        for _ in self.iter_blocks(1 << 20):
            pass
        if not self._zip_checked:
            self._check_member()
        checks = ["zip CRC-32 of every member matches; spikes are 0/1; shape matches the data size"]
        if self._blocks is None:
            checks.append("but the file holds no viform checksums (another tool's .npz, or viform's header "
                          "removed): an edit cannot be told from the original")
            return {"verified": False, "checks": checks}
        checks.append(f"{len(self._blocks.crcs)} block CRC-32s and the header checksum match")
        return {"verified": True, "checks": checks}

    def close(self) -> None:
        if self._fp is not None:
            self._fp.close()
        self._zip.close()


def _check_integrity_fields(header: dict, path) -> bool:
    """True for a header viform wrote (any of its integrity fields), after checking it is whole.

    Removing fields does not turn the checks off: a header with some of them and not the others,
    or whose own BLAKE2b differs, is damaged. Headers of older viform files (no such field) are
    read like other tools' files (the member's zip CRC-32 checked before use).
    """
    marks = [k for k in _MARKS if k in header]
    if not marks:
        return False
    where = f"{str(path)!r}: member {HEADER_KEY!r}"
    if header.get("format") != NPZ_FORMAT:
        raise ViformError(f"{where}: field 'format' = {header.get('format')!r} is not {NPZ_FORMAT!r}, though it "
                          f"holds viform's field {marks[0]!r}: the file is damaged or was edited (or written by "
                          "an older viform: write it again)")
    version = header.get("version")
    if isinstance(version, bool) or version != NPZ_VERSION:
        raise ViformError(f"{where}: field 'version' = {version!r} is not supported (this viform reads version "
                          f"{NPZ_VERSION})")
    missing = [k for k in _INTEGRITY_FIELDS if k not in header]
    if missing:
        raise ViformError(f"{where}: field {missing[0]!r} is missing: the file is damaged or was edited")
    if header["header_blake2b"] != header_digest(header):
        raise ViformError(f"{where}: the header is damaged or was edited (its BLAKE2b checksum differs)")
    check_consistent(header, where, known=_HEADER_FIELDS)
    if header.get("rows", "upright") != "upright" or header.get("axes", "thw") != "thw":
        raise ViformError(f"{where}: fields rows = {header.get('rows')!r}, axes = {header.get('axes')!r}, but "
                          "viform stores .npz spikes upright as (ticks, rows, columns): the header was edited")
    return True


def _check_layout(path: Path, archive: zipfile.ZipFile) -> None:
    """The archive accounts for the whole file: its end record (and comment) ends the file, and its
    first member starts it (zip readers tolerate bytes around an archive; viform does not)."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        tail_len = min(size, 22 + 0xFFFF)
        f.seek(size - tail_len)
        tail = f.read(tail_len)
    pos = tail.rfind(b"PK\x05\x06")
    while pos >= 0:  # the end record whose comment ends exactly at the end of the file
        if pos + 22 <= len(tail) and pos + 22 + int.from_bytes(tail[pos + 20:pos + 22], "little") == len(tail):
            break
        pos = tail.rfind(b"PK\x05\x06", 0, pos)
    if pos < 0:
        raise ViformError(f"{str(path)!r} is damaged or was edited: it holds bytes after the zip's end record")
    first = min((info.header_offset for info in archive.infolist()), default=0)
    if first != 0:
        raise ViformError(f"{str(path)!r} is damaged or was edited: it holds {first} bytes before the first zip "
                          "member (e.g. another file joined in front)")


def _scalar(values: dict, name: str, path=None):
    """The number in member ``name`` (None when absent); anything but a number is refused."""
    if name not in values:
        return None
    v = np.asarray(values[name])
    if v.ndim != 0 or v.dtype.kind not in "iuf":  # a bool is not a clock (True is not 1 Hz)
        raise ViformError(f"{str(path)!r}: member {name!r} holds {v.dtype} of shape {v.shape}; it must be one "
                          "number")
    return v.item()


def _short(exc) -> str:
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return text[:200]


def read_npz(path, clock_hz: float | None = None, key: str | None = None, axes: str | None = None) -> NpzSpikes:
    """Open a ``.npz`` spike stream (streamed; see :class:`NpzSpikes`).

    Parameters
    ----------
    path : str or Path
        The ``.npz`` file.
    clock_hz : float, optional
        Tick rate, Hz, overriding the file's.
    key : str, optional
        Name of the spike array.
    axes : str, optional
        Its axis order (``"thw"``, ``"hwt"`` ...).

    Returns
    -------
    NpzSpikes
        The stream.
    """
    return NpzSpikes(path, clock_hz, key, axes)


def write_npz(path, source: SpikeSource, *, block_ticks: int = 1024) -> Path:
    """Write ``source`` as a ``.npz`` (layout in the module docstring), block by block, atomically.

    The spike member is written first; the header that follows holds the CRC-32 of each block
    of it (:mod:`viform.stream.checksums`), its size, ``format``/``version`` and its own BLAKE2b.

    Parameters
    ----------
    path : str or Path
        The ``.npz`` file to write.
    source : SpikeSource
        The spikes.
    block_ticks : int
        Ticks written per block (memory bound).

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    shape = (int(source.n_ticks), int(source.height), int(source.width))
    block_ticks = block_ticks_for(source.height, source.width, block_ticks)
    npy_header = io.BytesIO()
    write_header = np.lib.format.write_array_header_2_0 if len(str(shape)) > 60000 \
        else np.lib.format.write_array_header_1_0
    write_header(npy_header, {"descr": "|u1", "fortran_order": False, "shape": shape})
    member_bytes = len(npy_header.getvalue()) + math.prod(shape)
    crcs = BlockCrcs(block_bytes_for(member_bytes))
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED,
                                                   allowZip64=True) as zf:
        def small(name, value):
            with zf.open(name + ".npy", "w") as fp:
                np.lib.format.write_array(fp, np.asarray(value), allow_pickle=False)

        written = 0
        with zf.open("spk.npy", "w", force_zip64=True) as fp:
            fp.write(npy_header.getvalue())
            crcs.update(npy_header.getvalue())
            for _, block in source.iter_blocks(block_ticks):
                raw = np.ascontiguousarray(block, dtype=np.uint8).tobytes()
                fp.write(raw)
                crcs.update(raw)
                written += block.shape[0]
        if written != shape[0]:
            raise RuntimeError(f"the stream gave {written} ticks, not the {shape[0]} it declared")
        header = stream_header(source, rows="upright",
                               extra={"axes": "thw", "format": NPZ_FORMAT, "version": NPZ_VERSION,
                                      "member_bytes": member_bytes, "block_bytes": crcs.block_bytes,
                                      "block_crc32": crcs.finish()})
        header = json.loads(json.dumps(header))
        header["header_blake2b"] = header_digest(header)
        small(HEADER_KEY, np.array(json.dumps(header)))
        small("clock_hz", np.float64(source.clock_hz))
        small("threshold_electrons", np.float64(np.nan if source.threshold_electrons is None
                                                else source.threshold_electrons))
        small("start_time_s", np.float64(source.start_time_s))
    return path
