"""The ``.vfc`` file: a first-spike coded viform as an asynchronous (i, j, t, τ) stream (seed 000 §5.2).

Seed 000 §5.2 ends with pixels sharing one asynchronous output channel, each first spike
sent as a quadruple (i, j, t, τ). A ``.vfc`` file stores exactly those spikes, losslessly in
``strict`` mode (see :mod:`viform.coding.first_spike` for the modes).

This module is the container every format version shares; how a version codes a segment is in
its own module: :mod:`~viform.coding.vfc_v1` (columns + zstd), :mod:`~viform.coding.vfc_v2`
(range-coded records), :mod:`~viform.coding.vfc_v3` (interval prediction, whole image),
:mod:`~viform.coding.vfc_v4` (bands of rows on parallel threads) and
:mod:`~viform.coding.vfc_v5` (bands, each coded by the smallest of three models) and
:mod:`~viform.coding.vfc_v6` (bands, each coded once by the tick model; written now).

Layout (little-endian)::

    magic   8 bytes  b"VIFC\\x89\\r\\n\\x1a"
    u16 version, u32 header length, u32 CRC-32 of the header, header (UTF-8 JSON — version 6:
        zlib-compressed JSON —: format, version — the same as the u16, inside the checksum —,
        height, width, clock_hz, threshold_electrons, start_time_s, mode, k, slack_ticks,
        segment_ticks, metadata; band_rows in strict files of versions 4 to 6)
    segments, each: b"SG", u32 payload length, u32 CRC-32 of the payload, payload
    end record: b"EN", u64 n_ticks, u64 n_segments, u64 spikes, u32 CRC-32 of the segment CRCs,
        then (version ≥ 3) u32 CRC-32 of those four counts

Every header field is bounded when a file is opened (the same bounds as a ``.dat`` sidecar's,
see :func:`viform.stream.sidecar.validate_header`), before anything sized by it is allocated.
Corrupt or truncated files raise :class:`~viform._validate.ViformError` naming the file, the
byte offset and what was wrong; every length, count, value and spike position is checked before
use, so no input can crash, hang or silently decode to garbage (the CRCs catch the rest).
"""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path

import numpy as np

from viform._io import atomic_open
from viform._validate import ViformError, check_int, size_text
from viform.coding import interval_model, vfc_v1, vfc_v2, vfc_v3, vfc_v4, vfc_v5, vfc_v6
from viform.coding.first_spike import (
    MAX_K,
    CodingParameters,
    FirstSpikeDecoder,
    FirstSpikeEncoder,
    Segment,
)
from viform.coding.vfc_common import (  # noqa: F401 -- re-exported: the coding room's public names
    _PAYLOAD_HEAD,
    DEFAULT_SEGMENT_PIXEL_TICKS,
    MAX_SEGMENT_PIXEL_TICKS,
    ZSTD_LEVEL,
    TickSegment,
    _segment_from_ticks,
    _Zstd,
    coding_threads,
    default_band_rows,
    default_segment_ticks,
    new_band_probabilities,
)
from viform.stream.container import SpikeSource, block_ticks_for

#: File magic (PNG-style: catches text-mode and truncation damage).
MAGIC = b"VIFC\x89\r\n\x1a"
#: Format version written (6: strict bands coded once by the tick model).
VERSION = 6
#: Versions this reader decodes (each one's segments are read by its own module).
SUPPORTED_VERSIONS = (1, 2, 3, 4, 5, 6)
#: File extension of first-spike coded viforms.
EXTENSION = ".vfc"
#: ``format`` field of the header of every ``.vfc`` viform writes (inside the header checksum).
FORMAT_NAME = "viform first-spike coded stream"

_SEG_HEAD = struct.Struct("<2sII")
_TRAILER = struct.Struct("<2sQQQI")
#: version 3 end record: the version-2 fields, then a CRC-32 of them (ticks, segments, spikes, CRC list)
_TRAILER3 = struct.Struct("<2sQQQII")
_MAX_HEADER = 1 << 20
#: Most pixels a coded file may have (2²², e.g. 2048 × 2048; the largest spike camera has 1000 × 1000): the
#: decoder keeps ~150 bytes of state per pixel (≤ 0.6 GB), and a header is cheap to forge.
MAX_PIXELS = 1 << 22
#: Pixels per byte of segment data a range-coded file (versions 2 to 5) can hold at most, per segment:
#: every pixel codes at least one binary decision per segment, and the most confident probability of
#: the coders costs ≥ 0.0007 bit (the interval coder: 1 − 32/65536; the record coder: 2043/2048, 0.0035
#: bit, so even a 5× zstd stage stays inside); checked at open, before anything per pixel is allocated,
#: so a forged header cannot make the reader allocate for pixels the data cannot hold.
PIXELS_PER_BYTE = 11_000
#: Most segment ticks a header may state (a segment is decoded whole).
MAX_SEGMENT_TICKS = 1 << 30
#: Every field a header may hold (what the writers of all versions write): any other is refused, as
#: a field this reader does not know could change what the data means.
HEADER_FIELDS = ("format", "version", "height", "width", "clock_hz", "threshold_electrons", "start_time_s", "mode",
                 "k", "slack_ticks", "segment_ticks", "metadata", "band_rows")


# ---------------------------------------------------------------------------- writer

class CodedWriter:
    """Streaming writer of a ``.vfc`` file: ``push`` blocks of ticks, then ``close``.

    The file appears under its name only when ``close`` succeeds (atomic).
    """

    def __init__(self, path, height: int, width: int, clock_hz: float, params: CodingParameters,
                 threshold_electrons: float | None = None, start_time_s: float = 0.0,
                 metadata: dict | None = None, level: int = ZSTD_LEVEL, version: int = VERSION,
                 fast: bool = False):
        self.path = Path(path)
        if version not in SUPPORTED_VERSIONS:
            raise ViformError(f"version must be one of {SUPPORTED_VERSIONS}; got {version!r}")
        self.version = version
        self.height = check_int("height", height, 1, 1 << 16)
        self.width = check_int("width", width, 1, 1 << 16)
        if self.height * self.width > MAX_PIXELS:
            raise ViformError(f"{size_text(height, width, 'pixels')}: a coded file holds at most {MAX_PIXELS} pixels")
        self.params = params
        self.strict = params.mode == "strict"
        self.encoder = FirstSpikeEncoder(self.height * self.width, params)
        self.state = FirstSpikeDecoder(self.height * self.width)  # mirrors the decoder's state
        self.ivstate = np.zeros((self.height * self.width, interval_model.STATE_ROWS), np.int64)
        self.ivprobs = interval_model.new_probabilities()
        self.zc = _Zstd(level)
        self.bands5 = None
        self.bands6 = None
        self.header = {
            "format": FORMAT_NAME, "version": version,
            "height": self.height, "width": self.width, "clock_hz": float(clock_hz),
            "threshold_electrons": threshold_electrons, "start_time_s": float(start_time_s),
            "mode": params.mode, "k": params.k, "slack_ticks": params.slack_ticks,
            "segment_ticks": params.segment_ticks, "metadata": _json_safe(metadata or {}),
        }
        # version 4, strict: the segment is held as bools and coded in bands of rows, in parallel
        self.banded = version >= 4 and self.strict
        if self.banded:
            pixel_ticks = params.segment_ticks * self.height * self.width
            if pixel_ticks > MAX_SEGMENT_PIXEL_TICKS:
                raise ViformError(f"segment_ticks = {params.segment_ticks} is not allowed for "
                                  f"{size_text(self.height, self.width, 'pixels')}: a segment would hold "
                                  f"{pixel_ticks:,} pixel-ticks in memory "
                                  f"(at most {MAX_SEGMENT_PIXEL_TICKS:,}); give at most "
                                  f"{MAX_SEGMENT_PIXEL_TICKS // (self.height * self.width)} ticks")
            coding_threads()  # refuse a bad VIFORM_THREADS before the file is opened
            self.band_rows = default_band_rows(self.height)
            self.header["band_rows"] = self.band_rows
            self.ivprobs = new_band_probabilities(self.height, self.band_rows)
            if version >= 6:
                self.bands6 = vfc_v6.BandState(self.height, self.width, self.band_rows)
            elif version == 5:
                self.bands5 = vfc_v5.BandState(self.height, self.width, self.band_rows,
                                               vfc_v5.FAST_MODELS if fast else vfc_v5.ALL_MODELS)
            self._dense = None
            self._fill = 0
            self._next_tick = 0
            self._last = np.full(self.height * self.width, -1, np.int64)  # each pixel's last spike tick
        # never write what the reader refuses: the header's values pass the reader's bounds first
        from viform.stream.sidecar import validate_header

        validate_header({key: self.header[key] for key in ("height", "width", "clock_hz", "threshold_electrons",
                                                           "start_time_s")}, self.path)
        self._cm = atomic_open(self.path, "wb")
        self.f = self._cm.__enter__()
        # version 5 writes no spaces in its header (its files are never larger than version 3's)
        head = json.dumps(self.header, sort_keys=True, separators=(",", ":") if version >= 5 else None).encode()
        if version >= 6:
            head = vfc_v6.pack_header(head)
        self.f.write(MAGIC + struct.pack("<HII", version, len(head), zlib.crc32(head)) + head)
        self.n_segments = 0
        self.spikes = 0
        self.bytes_written = len(MAGIC) + 10 + len(head)
        self._crcs = 0

    def push(self, block, final: bool = False) -> None:
        """Code a block of ticks (bool-like (T, H, W) or (T, H·W)).

        ``final``: no block follows (``close`` comes next), so a last partial segment that this block
        holds whole is coded straight from it. A strict banded writer codes every segment that a
        block holds whole straight from the block (no copy); only a segment spread over blocks is
        gathered into the writer's buffer.
        """
        if not self.banded:
            for seg in self.encoder.push(block):
                self._write(seg)
            return
        block = np.asarray(block)
        if block.ndim not in (2, 3) or block.size != block.shape[0] * self.height * self.width:
            raise ViformError(f"block of shape {block.shape} does not hold "
                              f"{size_text(self.height, self.width, 'pixels')} per tick")
        block = block.reshape(block.shape[0], self.height, self.width)
        seg_ticks = self.params.segment_ticks
        direct = block.dtype == np.bool_ and block.flags.c_contiguous  # segments coded from the block itself
        pos = 0
        while pos < block.shape[0]:
            take = min(block.shape[0] - pos, seg_ticks - self._fill)
            if direct and self._fill == 0 and (take == seg_ticks or final):
                self._next_tick += take
                self._write_banded(block[pos:pos + take])
                pos += take
                continue
            if self._dense is None:
                self._dense = np.zeros((seg_ticks, self.height, self.width), np.bool_)
            self._dense[self._fill:self._fill + take] = block[pos:pos + take]
            self._fill += take
            self._next_tick += take
            pos += take
            if self._fill == seg_ticks:
                self._write_banded()

    def _write_banded(self, dense=None) -> None:
        """Code the segment ``dense`` (its last tick is the last one pushed; default: the gathered ticks)."""
        if dense is None:
            dense = self._dense[:self._fill]
        start = self._next_tick - dense.shape[0]
        if self.bands6 is not None:
            payload, n_spikes = vfc_v6.encode_payload(dense, start, self.bands6)
        elif self.bands5 is not None:
            payload, n_spikes = vfc_v5.encode_payload(dense, start, self.bands5)
        else:
            payload, n_spikes = vfc_v4._encode_payload_v4(dense, start, self._last, self.ivstate, self.ivprobs,
                                                          self.band_rows)
        self._fill = 0
        self._append(payload, n_spikes)

    def _write(self, seg: Segment) -> None:
        if self.version == 1:
            payload = vfc_v1._encode_payload(seg, self.state.anchor, self.state.tau_ref, self.strict, self.zc)
        elif self.version == 3 and self.strict:
            payload = vfc_v3._encode_payload_v3(seg, self.state.anchor, self.state.tau_ref, self.width, self.ivstate,
                                                self.ivprobs)
        else:  # version 2, and the lossy modes of versions 3 to 5
            payload = vfc_v2._encode_payload_v2(seg, self.state.anchor, self.state.tau_ref, self.width, self.strict,
                                                self.zc)
        self.state.check(seg, advance=True)  # mirror the reader's state (anchors, widths)
        self._append(payload, seg.n_spikes)

    def _append(self, payload: bytes, n_spikes: int) -> None:
        crc = zlib.crc32(payload)
        self.f.write(_SEG_HEAD.pack(b"SG", len(payload), crc) + payload)
        self._crcs = zlib.crc32(struct.pack("<I", crc), self._crcs)
        self.n_segments += 1
        self.spikes += n_spikes
        self.bytes_written += _SEG_HEAD.size + len(payload)

    def close(self) -> Path:
        if self.banded:
            if self._fill:
                self._write_banded()
            self._dense = None
            n_ticks = self._next_tick
        else:
            for seg in self.encoder.finish():
                self._write(seg)
            n_ticks = self.encoder.next_tick
        if n_ticks == 0:
            self.abort()
            raise ViformError("the stream has no ticks to code")
        if self.version >= 3:
            fields = _TRAILER.pack(b"EN", n_ticks, self.n_segments, self.spikes, self._crcs)
            self.f.write(fields + struct.pack("<I", zlib.crc32(fields[2:])))
            self.bytes_written += _TRAILER3.size
        else:
            self.f.write(_TRAILER.pack(b"EN", self.encoder.next_tick, self.n_segments, self.spikes, self._crcs))
            self.bytes_written += _TRAILER.size
        self._cm.__exit__(None, None, None)
        return self.path

    def abort(self) -> None:
        try:
            raise RuntimeError("aborted")
        except RuntimeError as exc:
            self._cm.__exit__(type(exc), exc, exc.__traceback__)


def _json_safe(d: dict) -> dict:
    return json.loads(json.dumps(d, default=lambda v: v.item() if hasattr(v, "item") else str(v)))


def encode_source(source: SpikeSource, path, mode: str = "strict", *, k: float | None = None,
                  threshold_electrons: float | None = None, slack_ticks: int = 0,
                  segment_ticks: int | None = None, block_ticks: int = 1024, level: int = ZSTD_LEVEL,
                  progress: bool = False, version: int = VERSION, fast: bool = False) -> dict:
    """Code a viform into a ``.vfc`` file (streaming, bounded memory). Returns a summary.

    ``fast`` (strict): write version 5 with its interval model on every band (version 4's sizes) instead
    of version 6's tick model — about 2× quicker to encode and 1.7× to decode, files 7 % larger on a
    typical stream, up to 50 % where every pixel fires every tick (``benchmarks/bench_coding.py --corpus``).

    ``version`` 1 writes the older column layout (kept so that old readers can be served).

    Parameters
    ----------
    source : SpikeSource
        The stream to code.
    path : str or Path
        The ``.vfc`` file to write (atomically).
    mode : {"strict", "statistical", "intensity"}
        The repeat rule (:class:`~viform.coding.first_spike.CodingParameters`); strict is lossless.
    k : float, optional
        Tolerance factor of the statistical and intensity modes.
    threshold_electrons : float, optional
        Q, e⁻, for the tolerance (default: the source's).
    slack_ticks : int
        Extra tolerance, ticks.
    segment_ticks : int, optional
        Segment length, ticks (default: by the stream's size, :func:`~viform.coding.vfc_common.default_segment_ticks`).
    block_ticks : int
        Ticks read from ``source`` at a time.
    level : int
        zstd compression level of the versions that use zstd.
    progress : bool
        Show a progress bar.
    version : int
        File format version to write (1 to 5).
    fast : bool
        Version 5, strict: code every band with the interval model only.

    Returns
    -------
    dict
        ``path``, ``mode``, ``bytes``, ``raw_bytes``, ``ratio_vs_raw``, ``spikes``, ``segments``.
    """
    from viform.coding.first_spike import DEFAULT_K, DEFAULT_SEGMENT_TICKS

    if fast and version >= 5:
        version = 5
    q = threshold_electrons if threshold_electrons is not None else source.threshold_electrons
    if segment_ticks is None:
        segment_ticks = (default_segment_ticks(source.height * source.width) if mode == "strict" and version >= 4
                         else DEFAULT_SEGMENT_TICKS)
    params = CodingParameters(mode, DEFAULT_K if k is None else k, q, slack_ticks, segment_ticks)
    writer = CodedWriter(path, source.height, source.width, source.clock_hz, params, q, source.start_time_s,
                         {k2: v for k2, v in source.metadata.items() if k2 != "sensor"}, level, version, fast)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=source.n_ticks, unit="tick", desc="encode", leave=False, unit_scale=True)
    try:
        for first, block in source.iter_blocks(block_ticks):
            writer.push(block, final=first + block.shape[0] >= source.n_ticks)
            if bar is not None:
                bar.update(block.shape[0])
        writer.close()
    except BaseException:
        if not writer.f.closed:
            writer.abort()
        raise
    finally:
        if bar is not None:
            bar.close()
    raw = source.n_ticks * source.height * source.width / 8
    return {"path": str(path), "mode": mode, "bytes": writer.bytes_written, "raw_bytes": raw,
            "ratio_vs_raw": raw / writer.bytes_written, "spikes": writer.spikes,
            "first_spikes": None, "segments": writer.n_segments}


# ---------------------------------------------------------------------------- reader

class CodedFile(SpikeSource):
    """A ``.vfc`` file read as a :class:`SpikeSource` (decoded on the fly, segment by segment).

    Opening reads the header and trailer and walks the segment index (lengths only);
    ``iter_blocks`` decodes sequentially in bounded memory. ``verify()`` decodes everything
    and checks the CRCs and spike counts.
    """

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.is_file():
            raise ViformError(f"coded file {str(self.path)!r} does not exist")
        self.size = self.path.stat().st_size
        with open(self.path, "rb") as f:
            self.header = self._read_header(f)
            self._index = self._read_index(f)
        h = self.header
        self.height, self.width = h["height"], h["width"]
        self.clock_hz = h["clock_hz"]
        self.threshold_electrons = h["threshold_electrons"]
        self.start_time_s = h["start_time_s"]
        self.metadata = dict(h.get("metadata") or {}, coded_mode=h["mode"], source_coded=str(self.path))
        self.mode = h["mode"]
        self.segment_ticks = h["segment_ticks"]
        self._cache = None

    # -- structure
    def _fail(self, what: str, offset: int):
        raise ViformError(f"{str(self.path)!r} is not a valid {EXTENSION} file: {what} (at byte {offset})")

    def _read_header(self, f) -> dict:
        fixed = f.read(len(MAGIC) + 10)
        if len(fixed) < len(MAGIC) or fixed[:len(MAGIC)] != MAGIC:
            self._fail("wrong magic number (not a first-spike coded viform)", 0)
        if len(fixed) < len(MAGIC) + 10:
            self._fail("file is truncated inside the header", len(fixed))
        version, hlen, hcrc = struct.unpack_from("<HII", fixed, len(MAGIC))
        if version not in SUPPORTED_VERSIONS:
            self._fail(f"format version {version} is not supported (this viform reads versions "
                       f"{', '.join(map(str, SUPPORTED_VERSIONS))})", len(MAGIC))
        self.version = version
        if hlen > _MAX_HEADER:
            self._fail(f"header length {hlen} is implausible", len(MAGIC) + 2)
        head = f.read(hlen)
        if len(head) < hlen:
            self._fail("file is truncated inside the header", len(fixed) + len(head))
        if zlib.crc32(head) != hcrc:
            self._fail("header checksum mismatch", len(fixed))
        if version >= 6:
            try:
                head = vfc_v6.unpack_header(head)
            except ViformError as exc:
                self._fail(str(exc), len(fixed))
        try:
            h = json.loads(head.decode())
        except Exception as exc:
            self._fail(f"header is invalid ({exc})", len(fixed))
        if not isinstance(h, dict):
            self._fail("header is invalid (not a JSON object)", len(fixed))
        for key in ("height", "width", "clock_hz", "threshold_electrons", "start_time_s", "mode", "k",
                    "segment_ticks"):
            if key not in h:
                self._fail(f"header field {key!r} is missing", len(fixed))
        self._check_header(h, version, len(fixed))
        return h

    def _check_header(self, h: dict, version: int, offset: int) -> None:
        """Every field the reader relies on, bounded before anything is sized by it (named in the message)."""
        from viform.stream.sidecar import validate_header

        if h.get("format") != FORMAT_NAME or h.get("version") != version or isinstance(h.get("version"), bool):
            self._fail(f"header is invalid: fields format = {h.get('format')!r}, version = {h.get('version')!r} "
                       f"do not say {FORMAT_NAME!r} version {version} (the version outside the checksum was edited, "
                       "or the file is not viform's)", offset)
        try:  # height, width, clock_hz, threshold_electrons, start_time_s: the bounds of a .dat sidecar
            validate_header({key: h[key] for key in ("height", "width", "clock_hz", "threshold_electrons",
                                                     "start_time_s")}, self.path,
                            required=("height", "width", "clock_hz", "start_time_s"))
        except ViformError as exc:
            self._fail(f"header is invalid: {str(exc).split(': ', 1)[-1]}", offset)

        def bad(key, allowed):
            self._fail(f"header is invalid: field {key!r} = {h.get(key)!r} is not allowed: {allowed}", offset)

        unknown = sorted(key for key in h if key not in HEADER_FIELDS)
        if unknown:
            self._fail(f"header is invalid: field {unknown[0]!r} is not one this viform writes or reads (the header "
                       "was edited, or written by a newer viform)", offset)

        def whole(key, low, high):
            v = h.get(key)
            if isinstance(v, bool) or not isinstance(v, int) or not low <= v <= high:
                bad(key, f"it must be a whole number in [{low}, {high}]")

        whole("height", 1, 1 << 16)
        whole("width", 1, 1 << 16)
        if h["height"] * h["width"] > MAX_PIXELS:
            self._fail(f"header is invalid: fields width × height = {h['width']}×{h['height']} are not allowed: "
                       f"a coded file holds at most {MAX_PIXELS:,} pixels", offset)
        whole("segment_ticks", 1, MAX_SEGMENT_TICKS)
        if h["mode"] not in ("strict", "statistical", "intensity"):
            bad("mode", "it must be 'strict', 'statistical' or 'intensity'")
        k = h["k"]
        if isinstance(k, bool) or not isinstance(k, (int, float)) or not 0 <= k <= MAX_K:
            bad("k", f"it must be a number in [0, {MAX_K:g}]")
        if "slack_ticks" in h:
            whole("slack_ticks", 0, MAX_SEGMENT_TICKS)
        if h["mode"] == "statistical" and k > 0 and h["threshold_electrons"] is None:
            bad("threshold_electrons", "the statistical mode's tolerance k·τ/√Q needs Q (a number)")
        if not isinstance(h.get("metadata") or {}, dict):
            bad("metadata", "it must be an object")
        if version >= 4 and h["mode"] == "strict":
            whole("band_rows", 1, h["height"])
            # a segment is held whole while it is decoded: the bound its writer keeps
            if h["segment_ticks"] * h["height"] * h["width"] > MAX_SEGMENT_PIXEL_TICKS:
                self._fail(f"header is invalid: field 'segment_ticks' = {h['segment_ticks']} is not allowed for "
                           f"{size_text(h['height'], h['width'], 'pixels')}: a segment may hold at most "
                           f"{MAX_SEGMENT_PIXEL_TICKS:,} pixel-ticks", offset)

    def _read_index(self, f) -> list[tuple[int, int, int]]:
        index = []
        pos = f.tell()
        while True:
            head = f.read(_SEG_HEAD.size)
            if len(head) < 2:
                self._fail("file is truncated: the end record is missing", pos)
            if head[:2] == b"EN":
                tr = _TRAILER3 if self.version >= 3 else _TRAILER
                rest = head + f.read(tr.size - len(head))
                if len(rest) < tr.size:
                    self._fail("file is truncated inside the end record", pos)
                _, n_ticks, n_seg, spikes, crcs = _TRAILER.unpack_from(rest)
                if self.version >= 3 and zlib.crc32(rest[2:_TRAILER.size]) != _TRAILER3.unpack(rest)[-1]:
                    self._fail("end record checksum mismatch (its tick or spike count is damaged)", pos)
                if f.read(1):
                    self._fail("bytes after the end record", pos + tr.size)
                break
            if len(head) < _SEG_HEAD.size or head[:2] != b"SG":
                self._fail("expected a segment or the end record", pos)
            _, length, crc = _SEG_HEAD.unpack(head)
            if pos + _SEG_HEAD.size + length > self.size:
                self._fail("file is truncated inside a segment", pos)
            index.append((pos + _SEG_HEAD.size, length, crc))
            pos += _SEG_HEAD.size + length
            f.seek(pos)
        if n_seg != len(index):
            self._fail(f"end record counts {n_seg} segments, the file holds {len(index)}", pos)
        seg = self.header["segment_ticks"]
        if n_ticks < 1 or -(-n_ticks // seg) != n_seg:
            self._fail(f"end record's {n_ticks} ticks do not match {n_seg} segments of {seg} ticks", pos)
        acc = 0
        for _, _, crc in index:
            acc = zlib.crc32(struct.pack("<I", crc), acc)
        if acc != crcs:
            self._fail("segment checksum list mismatch", pos)
        n_pix = self.header["height"] * self.header["width"]
        data_bytes = sum(length for _, length, _ in index)
        if self.version >= 2 and n_pix * n_seg > PIXELS_PER_BYTE * data_bytes:
            self._fail(f"the header's {self.header['height']}×{self.header['width']} pixels cannot be coded in "
                       f"{data_bytes} bytes of {n_seg} segment(s) (a genuine file holds at most "
                       f"{PIXELS_PER_BYTE} pixels per byte per segment)", pos)
        self.n_ticks = int(n_ticks)
        self.spikes_stored = int(spikes)
        if spikes > n_ticks * self.header["height"] * self.header["width"]:
            self._fail("end record's spike count is impossible", pos)
        return index

    # -- decoding
    def iter_segments(self):
        """Yield ``(decoder, segment)`` in order, each validated (CRC, structure, spike count)."""
        n_pixels = self.height * self.width
        dec = FirstSpikeDecoder(n_pixels)
        ivstate = np.zeros((n_pixels, interval_model.STATE_ROWS), np.int64) if self.version == 3 else None
        ivprobs = interval_model.new_probabilities() if self.version == 3 else None
        zc = _Zstd()
        strict = self.mode == "strict"
        banded = self.version >= 4 and strict
        if banded:  # versions 4 and 5: segments of spike ticks; ``dec`` is not used
            coding_threads()  # a bad VIFORM_THREADS is the user's setting, not damage in the file
            if self.version == 4:
                ivstate = np.zeros((n_pixels, interval_model.STATE_ROWS), np.int64)
                ivprobs = new_band_probabilities(self.height, self.header["band_rows"])
                last = np.full(n_pixels, -1, np.int64)
            elif self.version == 5:
                bands5 = vfc_v5.BandState(self.height, self.width, self.header["band_rows"])
            else:
                bands6 = vfc_v6.BandState(self.height, self.width, self.header["band_rows"])
        total = 0
        with open(self.path, "rb") as f:
            for n, (offset, length, crc) in enumerate(self._index):
                f.seek(offset)
                payload = f.read(length)
                if len(payload) != length or zlib.crc32(payload) != crc:
                    self._fail(f"segment {n} checksum mismatch (damaged data)", offset)
                try:
                    start = n * self.segment_ticks
                    if self.version == 1:
                        seg, spikes = vfc_v1._decode_payload(payload, n_pixels, dec.anchor, dec.tau_ref, strict, zc,
                                                             start, self.segment_ticks)
                    elif self.version == 2:
                        seg, spikes = vfc_v2._decode_payload_v2(payload, n_pixels, self.width, dec.anchor,
                                                                dec.tau_ref, strict, zc, start, self.segment_ticks)
                    elif banded and self.version == 4:
                        seg = vfc_v4._decode_payload_v4(payload, self.height, self.width, self.header["band_rows"],
                                                        last, ivstate, ivprobs, start, self.segment_ticks)
                        spikes = seg.n_spikes
                    elif banded and self.version == 5:
                        seg = vfc_v5.decode_payload(payload, bands5, start, self.segment_ticks)
                        spikes = seg.n_spikes
                    elif banded:
                        seg = vfc_v6.decode_payload(payload, bands6, start, self.segment_ticks)
                        spikes = seg.n_spikes
                    elif self.version == 3 and strict:
                        seg, spikes = vfc_v3._decode_payload_v3(payload, n_pixels, self.width, dec.anchor,
                                                                dec.tau_ref, ivstate, ivprobs, strict, zc, start,
                                                                self.segment_ticks)
                    else:  # the lossy modes of versions 3 to 5: version 2's payload, flag 0
                        seg, spikes = vfc_v3._decode_payload_v3(payload, n_pixels, self.width, dec.anchor,
                                                                dec.tau_ref, None, None, strict, zc, start,
                                                                self.segment_ticks)
                    expect_ticks = min(self.segment_ticks, self.n_ticks - n * self.segment_ticks)
                    if seg.n_ticks != expect_ticks:
                        raise ViformError(f"segment {n} holds {seg.n_ticks} ticks, expected {expect_ticks}")
                    if not banded and dec.check(seg) != spikes:
                        raise ViformError(f"segment {n} decodes to a different spike count than stored")
                except ViformError as exc:
                    self._fail(str(exc), offset)
                except MemoryError:
                    self._fail(f"segment {n} needs more memory than is available (its stated record count "
                               "is implausible, or the machine is too small for it)", offset)
                total += spikes
                yield dec, seg
        if total != self.spikes_stored:
            self._fail(f"segments hold {total} spikes, the end record says {self.spikes_stored}", self.size)

    def iter_blocks(self, block_ticks: int = 1024, start: int = 0, stop: int | None = None):
        # blocks sized by pixels too (bounded memory at any resolution), as every reader's
        block_ticks = block_ticks_for(self.height, self.width, check_int("block_ticks", block_ticks, 1))
        stop = self.n_ticks if stop is None else min(stop, self.n_ticks)
        pending = []
        have = 0
        first = start
        for dec, seg in self.iter_segments():
            s0 = seg.start_tick
            if s0 + seg.n_ticks <= start:
                if not isinstance(seg, TickSegment):
                    dec.check(seg, advance=True)
                continue
            if s0 >= stop:
                break
            parts = (seg.blocks(block_ticks) if isinstance(seg, TickSegment)
                     else dec.decode(seg, block_ticks=block_ticks))
            for a, blk in parts:
                lo, hi = max(a, start), min(a + blk.shape[0], stop)
                if lo >= hi:
                    continue
                pending.append(blk[lo - a:hi - a])
                have += hi - lo
                while have >= block_ticks:
                    cat = np.concatenate(pending) if len(pending) > 1 else pending[0]
                    yield first, cat[:block_ticks].reshape(-1, self.height, self.width)
                    first += block_ticks
                    rest = cat[block_ticks:]
                    pending = [rest] if rest.shape[0] else []
                    have = rest.shape[0]
        if have:
            cat = np.concatenate(pending) if len(pending) > 1 else pending[0]
            yield first, cat.reshape(-1, self.height, self.width)

    def read_ticks(self, start: int, stop: int) -> np.ndarray:
        start, stop = max(0, start), min(stop, self.n_ticks)
        if stop <= start:
            return np.zeros((0, self.height, self.width), bool)
        return np.concatenate([b for _, b in self.iter_blocks(stop - start, start, stop)])

    def verify(self) -> int:
        """Decode everything; raise on any damage. Returns the spike count."""
        n = 0
        for dec, seg in self.iter_segments():
            if isinstance(seg, TickSegment):  # decoding checked every tick against its segment
                n += seg.n_spikes
                continue
            for _, blk in dec.decode(seg, block_ticks=block_ticks_for(self.height, self.width, 256)):
                n += int(np.count_nonzero(blk))
        return n

    def quadruples(self) -> np.ndarray:
        """The stored first spikes as (i, j, t, τ) quadruples (ticks)."""
        from viform.coding.first_spike import quadruples

        segs = []
        records = FirstSpikeDecoder(self.height * self.width)
        for dec, seg in self.iter_segments():
            if isinstance(seg, TickSegment):  # version 4 stores ticks: its first spikes are derived here
                seg = _segment_from_ticks(seg.counts, seg.ticks, records.anchor, records.tau_ref, seg.start_tick,
                                          seg.n_ticks)
                dec = records
            segs.append(seg)
            dec.check(seg, advance=True)
        return quadruples(segs, self.height, self.width)


def open_coded(path) -> CodedFile:
    """Open a ``.vfc`` file as a :class:`SpikeSource`.

    Parameters
    ----------
    path : str or Path
        The ``.vfc`` file.

    Returns
    -------
    CodedFile
        The stream, decoded segment by segment as it is read.
    """
    return CodedFile(path)


def is_coded_file(path) -> bool:
    """True when ``path`` starts with the ``.vfc`` magic number.

    Parameters
    ----------
    path : str or Path
        Any file.

    Returns
    -------
    bool
        Whether it is a ``.vfc`` file (by content, not by name).
    """
    try:
        with open(path, "rb") as f:
            return f.read(len(MAGIC)) == MAGIC
    except OSError:
        return False


def describe_coded_file(path) -> dict:
    """Summary of a ``.vfc`` file for ``viform info`` (header, size, ratio; every checksum checked, no decode).

    Parameters
    ----------
    path : str or Path
        The ``.vfc`` file.

    Returns
    -------
    dict
        Size (height, width, ticks, clock, duration), coding settings, spike count, file and raw bytes,
        compression ratio and bits per spike.
    """
    cf = CodedFile(path)
    _check_segment_crcs(cf)
    h = cf.header
    raw = cf.n_ticks * cf.height * cf.width / 8
    return {
        "format": f"first-spike coded viform ({EXTENSION}, version {cf.version})",
        "height": cf.height, "width": cf.width, "n_ticks": cf.n_ticks, "clock_hz": cf.clock_hz,
        "duration_s": cf.n_ticks / cf.clock_hz, "start_time_s": cf.start_time_s,
        "threshold_electrons": cf.threshold_electrons, "mode": h["mode"], "k": h["k"],
        "slack_ticks": h.get("slack_ticks", 0), "segment_ticks": h["segment_ticks"],
        **({"band_rows": h["band_rows"]} if "band_rows" in h else {}), "segments": len(cf._index),
        "spike_count": cf.spikes_stored, "file_bytes": cf.size, "raw_bytes": raw,
        "ratio_vs_raw": raw / cf.size, "bits_per_spike": 8 * cf.size / max(1, cf.spikes_stored),
        "metadata": h.get("metadata", {}),
        "verified": True,
        "verification": ("header, end-record and every segment's checksum checked (not decoded: viform verify "
                         "decodes everything)" if cf.version >= 3 else
                         "header and every segment's checksum checked (not decoded: viform verify decodes "
                         f"everything; version {cf.version} has no checksum over the end record's counts)"),
    }


def verify_coded_file(path) -> dict:
    """Check a ``.vfc`` file completely: every checksum, then a full decode with every spike count compared.

    Returns what was checked (for ``viform verify``); damage raises :class:`ViformError` naming the
    byte offset and what is wrong.

    Parameters
    ----------
    path : str or Path
        The ``.vfc`` file.

    Returns
    -------
    dict
        ``format_version``, ``mode``, ``segments``, ``n_ticks``, ``spike_count`` and ``checks``.
    """
    cf = CodedFile(path)
    spikes = cf.verify()
    checks = ["header checksum", "end-record checksum" if cf.version >= 3 else "end record (version "
              f"{cf.version}: its counts have no checksum of their own)",
              f"{len(cf._index)} segment checksums", f"every segment decoded ({spikes} spikes, "
              f"{cf.n_ticks} ticks), spike counts match the segment headers and the end record"]
    return {"format_version": cf.version, "mode": cf.mode, "segments": len(cf._index), "n_ticks": cf.n_ticks,
            "spike_count": spikes, "checks": checks}


def _check_segment_crcs(cf: CodedFile) -> None:
    """Read every segment and compare its CRC-32 (no decoding; bounded memory)."""
    with open(cf.path, "rb") as f:
        for n, (offset, length, crc) in enumerate(cf._index):
            f.seek(offset)
            acc = 0
            left = length
            while left:
                chunk = f.read(min(left, 1 << 20))
                if not chunk:
                    break
                acc = zlib.crc32(chunk, acc)
                left -= len(chunk)
            if left or acc != crc:
                cf._fail(f"segment {n} checksum mismatch (damaged data)", offset)

