"""Metadata that travels with spike data: the JSON sidecar of ``.dat`` files and the shared header.

A ``.dat`` file holds bits only (see :mod:`viform.stream.dat`), so viform writes a JSON file
beside it, ``clip.dat`` → ``clip.dat.json``, holding what a reader needs to interpret the bits
(height, width, clock, row order) and what a user needs to turn them into light (threshold Q,
optics, dark current: seed 000 §3.3.2, light = Q/τ) and to reproduce them (scene, seed, viform
version, command line, UTC date). :func:`viform.stream.io.open_spikes` reads it automatically.
The same header is stored inside ``.npz`` files (member ``viform_header``) and zarr stores
(attribute ``viform``), so every format carries the same fields.

Every header is validated when it is read (:func:`validate_header`): a forged or damaged field
gives a one-line :class:`~viform._validate.ViformError` naming the file and the field, before
anything is allocated from it.

Integrity cannot be edited away: a sidecar written by viform carries its ``format`` and
``version`` markers, the data's size, BLAKE2b and per-block CRC-32s
(:mod:`viform.stream.checksums`) and its own BLAKE2b (``sidecar_blake2b``), all inside the
checked part. A sidecar that holds any viform marker but lacks one of these (deleted by hand)
is refused as damaged; a sidecar with no viform marker at all is another tool's, read as such,
and nothing reports its data as verified.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import shlex
import sys
import time
from pathlib import Path

from viform._validate import ViformError

#: ``format`` value of a sidecar written by viform.
SIDECAR_FORMAT = "viform-spike-sidecar"
#: Version 2 adds per-block CRC-32s of the data (``block_bytes``, ``block_crc32``); version 1
#: sidecars (whole-file BLAKE2b only) are still read, their data checked whole before first use.
SIDECAR_VERSION = 2
SIDECAR_VERSIONS = (1, 2)
#: Fields only viform writes: a sidecar holding any of them must hold every checksum field.
VIFORM_MARKS = ("format", "sidecar_blake2b", "blake2b", "data_bytes", "block_bytes", "block_crc32",
                "viform_version", "command_line", "utc_date")
#: Fields of every header :func:`stream_header` makes (the ``.npz`` and zarr headers hold exactly
#: these plus their format's own; a ``.dat`` sidecar may hold more, e.g. a dataset's records).
HEADER_FIELDS = ("height", "width", "n_ticks", "clock_hz", "threshold_electrons", "start_time_s", "rows",
                 "bit_order", "optics", "dark_current_e_per_s", "scene", "seed", "viform_version",
                 "command_line", "utc_date", "metadata")
#: Fields that hold a number (or a name) in every header viform writes: ``null`` there is an edit
#: (``threshold_electrons``, ``optics`` and ``dark_current_e_per_s`` may be null: unknown).
NOT_NULL_FIELDS = ("height", "width", "n_ticks", "clock_hz", "start_time_s", "rows", "bit_order")
#: Largest height or width a header may declare (pixels).
MAX_DIMENSION = 1 << 16
#: Readout clock a header may declare, Hz: from 1 Hz (slower than any spike or frame sensor;
#: below it tick lengths and durations reach absurd magnitudes) to 1 THz.
MIN_CLOCK_HZ = 1.0
MAX_CLOCK_HZ = 1e12
#: Threshold Q a header may declare, e⁻: a pixel fires on at least one electron (Q is rounded to
#: whole electrons, so 0.5 rounds to 1); at most 1e12 (far above any full well; beyond it
#: Q × rate overflows the light estimates).
MIN_THRESHOLD_ELECTRONS = 0.5
MAX_THRESHOLD_ELECTRONS = 1e12
#: Largest |start time| a header may declare, s.
MAX_START_TIME_S = 1e12
#: Largest tick count a header may declare.
MAX_TICKS = 1 << 40
#: Largest sidecar read, bytes (a sidecar is a few kB; a bigger one is not ours).
MAX_SIDECAR_BYTES = 4 << 20

#: Row order names: ``bottom-up`` is the camera/SpikeCV ``.dat`` layout, ``upright`` is top row first.
ROW_ORDERS = ("bottom-up", "upright")


def sidecar_path(data_path) -> Path:
    """The sidecar of ``data_path``: the same name with ``.json`` appended (``clip.dat.json``).

    Parameters
    ----------
    data_path : str or Path
        The data file.

    Returns
    -------
    Path
        Its sidecar's path.

    Examples
    --------
    >>> sidecar_path("clip.dat").name
    'clip.dat.json'
    """
    data_path = Path(data_path)
    return data_path.with_name(data_path.name + ".json")


def provenance() -> dict:
    """Who wrote the data: viform version, command line and UTC date (ISO 8601).

    Returns
    -------
    dict
        ``viform_version``, ``command_line`` and ``utc_date``.
    """
    from viform import __version__

    argv = [Path(sys.argv[0]).name if sys.argv and sys.argv[0] else "python", *sys.argv[1:]]
    return {
        "viform_version": __version__,
        "command_line": shlex.join(argv),
        "utc_date": _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat().replace("+00:00", "Z"),
    }


def stream_header(source, *, rows: str = "upright", extra: dict | None = None) -> dict:
    """The header fields of a :class:`~viform.stream.container.SpikeSource`, with provenance.

    Flat fields: ``height``, ``width``, ``n_ticks``, ``clock_hz``, ``threshold_electrons``,
    ``start_time_s``, ``rows``, ``bit_order``; copied from the sensor description when the
    stream was simulated: ``optics``, ``dark_current_e_per_s``; from the capture: ``scene``,
    ``seed``; ``viform_version``, ``command_line``, ``utc_date``; the full stream metadata
    (sensor description included) under ``metadata``.
    """
    from viform._io import _jsonable

    if rows not in ROW_ORDERS:
        raise ViformError(f"rows = {rows!r} is not allowed: choose one of {', '.join(ROW_ORDERS)}")
    metadata = json.loads(json.dumps(dict(source.metadata or {}), default=_jsonable))
    # the reader's own bookkeeping is not part of what the stream is
    for key in ("source", "format", "flip", "stored_width", "verified"):
        metadata.pop(key, None)
    sensor = metadata.get("sensor") if isinstance(metadata.get("sensor"), dict) else {}
    header = {
        "height": int(source.height), "width": int(source.width), "n_ticks": int(source.n_ticks),
        "clock_hz": float(source.clock_hz),
        "threshold_electrons": None if source.threshold_electrons is None else float(source.threshold_electrons),
        "start_time_s": float(source.start_time_s), "rows": rows, "bit_order": "little",
        "optics": sensor.get("optics"), "dark_current_e_per_s": sensor.get("dark_current_e_per_s"),
        "scene": metadata.get("scene"), "seed": metadata.get("seed"),
        **provenance(),
        "metadata": metadata,
    }
    if extra:
        header.update(extra)
    return header


def write_sidecar(data_path, metadata: dict) -> Path:
    """Write the JSON sidecar of ``data_path`` atomically; returns its path.

    ``metadata`` is stored as given (see :func:`stream_header` for the fields viform reads)
    with ``format``/``version`` markers; provenance fields are added when absent. When
    ``metadata`` holds no checksum of the data, the data file is read once and its size,
    BLAKE2b and block CRC-32s (:func:`data_checksums`) are recorded.

    Parameters
    ----------
    data_path : str or Path
        The data file (not the sidecar).
    metadata : dict
        The fields to store (:func:`stream_header`'s and any others).

    Returns
    -------
    Path
        The sidecar written.
    """
    from viform._io import write_json

    path = sidecar_path(data_path)
    if isinstance(metadata, dict) and "blake2b" not in metadata and Path(data_path).is_file():
        metadata = {**metadata, **data_checksums(data_path)}
    write_json(path, sidecar_body(metadata))
    return path


def data_checksums(data_path) -> dict:
    """``data_bytes``, ``blake2b`` and per-block ``block_bytes``/``block_crc32`` of a data file (one read)."""
    import hashlib

    from viform.stream.checksums import BlockCrcs, block_bytes_for

    size = Path(data_path).stat().st_size
    blocks = BlockCrcs(block_bytes_for(size))
    h = hashlib.blake2b(digest_size=16)
    with open(data_path, "rb") as f:
        for chunk in iter(lambda: f.read(HASH_BLOCK_BYTES), b""):
            h.update(chunk)
            blocks.update(chunk)
    return {"data_bytes": size, "blake2b": h.hexdigest(), "block_bytes": blocks.block_bytes,
            "block_crc32": blocks.finish()}


def sidecar_body(metadata: dict) -> dict:
    """The JSON object :func:`write_sidecar` writes: markers, provenance, ``metadata``, checksum."""
    from viform._io import _jsonable

    if not isinstance(metadata, dict):
        raise ViformError(f"sidecar metadata must be a dict, got {type(metadata).__name__}")
    body = {"format": SIDECAR_FORMAT, "version": SIDECAR_VERSION}
    body.update({k: v for k, v in provenance().items() if k not in metadata})
    body.update(metadata)
    body.pop(DIGEST_KEY, None)
    # the markers say what the body holds (a reader checks them first): never copied from elsewhere
    body["format"] = SIDECAR_FORMAT
    body["version"] = SIDECAR_VERSION if "block_crc32" in body else 1
    body = json.loads(json.dumps(body, default=_jsonable))
    body[DIGEST_KEY] = _digest(body)
    return body


#: Field holding the BLAKE2b of the rest of the sidecar (damage or edits are noticed on read).
DIGEST_KEY = "sidecar_blake2b"


def _digest(body: dict) -> str:
    import hashlib

    rest = {k: v for k, v in body.items() if k != DIGEST_KEY}
    text = json.dumps(rest, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.blake2b(text.encode(), digest_size=16).hexdigest()


#: Where :func:`viform.stream.dat.write_dat` puts the new sidecar while the new data is renamed
#: in: ``clip.dat`` → ``.clip.dat.json.viform-pending.json``. It is renamed onto the sidecar
#: right after the data; a writer killed between the two renames leaves it there, and the next
#: reader (or writer) picks whichever of the two sidecars matches the data (:func:`settle_sidecar`).
PENDING_SUFFIX = ".viform-pending.json"
#: A pending sidecar older than this whose data never arrived is a dead writer's: a reader may
#: remove it (a live writer renames its data in within moments of writing it), seconds.
PENDING_STALE_S = 60.0
#: Bytes hashed at a time when a sidecar has to be matched against its data.
HASH_BLOCK_BYTES = 16 << 20


def pending_sidecar_path(data_path) -> Path:
    """The new sidecar of ``data_path`` waiting for its data (see :data:`PENDING_SUFFIX`)."""
    side = sidecar_path(data_path)
    return side.with_name(f".{side.name}{PENDING_SUFFIX}")


def data_blake2b(data_path) -> str:
    """BLAKE2b (16 bytes, hex) of the whole file, read in bounded blocks."""
    import hashlib

    h = hashlib.blake2b(digest_size=16)
    with open(data_path, "rb") as f:
        for chunk in iter(lambda: f.read(HASH_BLOCK_BYTES), b""):
            h.update(chunk)
    return h.hexdigest()


def _intact(path) -> dict | None:
    """The sidecar at ``path`` when it is a readable object whose own checksum holds, else None."""
    try:
        if path.stat().st_size > MAX_SIDECAR_BYTES:
            return None
        body = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return None
    if not isinstance(body, dict) or body.get(DIGEST_KEY) != _digest(body):
        return None
    return body


def settle_sidecar(data_path) -> dict | None:
    """After a writer was killed between renaming a ``.dat`` and its sidecar, pair them again.

    Does nothing (one ``stat``) unless a pending sidecar (:func:`pending_sidecar_path`) is
    there. Then the data is hashed once and the sidecar whose size and BLAKE2b match it is
    kept: a matching pending one is renamed onto the sidecar (or, when the folder is read-only,
    returned for the caller to use); a pending one while the sidecar in place matches is
    removed once older than :data:`PENDING_STALE_S` (a younger one may be a live writer's).
    When neither matches, both stay (the reader then reports the damage).
    """
    pending = pending_sidecar_path(data_path)
    if not os.path.lexists(pending):
        return None
    data_path = Path(data_path)
    candidate = _intact(pending)
    try:
        size = data_path.stat().st_size
    except OSError:
        return None  # no data (yet): the writer that left it will replace it
    digest = None

    def matches(body) -> bool:
        nonlocal digest
        if body is None or body.get("data_bytes") != size or not body.get("blake2b"):
            return False
        digest = data_blake2b(data_path) if digest is None else digest
        return body["blake2b"] == digest

    if matches(_intact(sidecar_path(data_path))):
        try:  # a young one may be a live writer's, still being written or about to rename its data in
            if time.time() - pending.stat().st_mtime > PENDING_STALE_S:
                pending.unlink()  # a killed writer's: its data never arrived
        except OSError:
            pass
        return None
    if not matches(candidate):
        return None
    try:
        os.replace(pending, sidecar_path(data_path))
    except FileNotFoundError:
        return None  # its writer (or another reader) has just renamed it
    except OSError:
        return candidate  # a read-only folder: use it without renaming
    return None


def read_sidecar(data_path) -> dict | None:
    """The validated sidecar of ``data_path``, or None when there is none.

    A writer killed between renaming the data and its sidecar is healed first
    (:func:`settle_sidecar`). Raises :class:`ViformError` (naming the sidecar and the field)
    when the sidecar exists but is not valid JSON, not an object, or holds an out-of-range field.

    Parameters
    ----------
    data_path : str or Path
        The data file (not the sidecar).

    Returns
    -------
    dict or None
        The sidecar's fields.
    """
    path = sidecar_path(data_path)
    chosen = settle_sidecar(data_path)
    if chosen is not None:
        check_marks(chosen, path)
        return validate_header(chosen, path, required=())
    if not path.is_file():
        return None
    try:
        size = path.stat().st_size
        if size > MAX_SIDECAR_BYTES:
            raise ViformError(f"{str(path)!r}: sidecar of {size} bytes is larger than {MAX_SIDECAR_BYTES} bytes")
        header = json.loads(path.read_text(encoding="utf-8"))
    except ViformError:
        raise
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise ViformError(f"{str(path)!r} is not a readable JSON sidecar: {_short(exc)}") from None
    if not isinstance(header, dict):
        raise ViformError(f"{str(path)!r}: a sidecar must hold a JSON object, not {type(header).__name__}")
    check_marks(header, path)
    return validate_header(header, path, required=())


def check_marks(header: dict, path) -> None:
    """A sidecar viform wrote (any of :data:`VIFORM_MARKS`) must be whole: markers, checksums, own digest.

    Deleting checksum fields does not turn the checks off: it makes the sidecar damaged.
    """
    marks = [k for k in VIFORM_MARKS if k in header]
    if not marks:
        return  # another tool's sidecar: read as such, never reported verified
    where = repr(str(path))
    if header.get("format") != SIDECAR_FORMAT:
        raise ViformError(f"{where}: field 'format' = {header.get('format')!r} is not {SIDECAR_FORMAT!r}, though "
                          f"the sidecar holds viform's field {marks[0]!r}: it is damaged or was edited")
    version = header.get("version")
    if isinstance(version, bool) or version not in SIDECAR_VERSIONS:
        raise ViformError(f"{where}: field 'version' = {version!r} is not supported (this viform reads sidecar "
                          f"versions {', '.join(map(str, SIDECAR_VERSIONS))})")
    needed = [DIGEST_KEY, "data_bytes", "blake2b"] + (["block_bytes", "block_crc32"] if version >= 2 else [])
    missing = [k for k in needed if header.get(k) is None]
    if missing:
        raise ViformError(f"{where}: the sidecar is damaged or was edited: field"
                          f"{'' if len(missing) == 1 else 's'} {', '.join(repr(k) for k in missing)}, which viform "
                          f"writes in every sidecar of version {version}, {'is' if len(missing) == 1 else 'are'} "
                          "missing; write the file again with viform")
    if header[DIGEST_KEY] != _digest(header):
        raise ViformError(f"{where}: the sidecar is damaged or was edited (its checksum {DIGEST_KEY!r} differs); "
                          "write the file again with viform")
    check_consistent(header, where)


def check_consistent(header: dict, where: str, known: tuple | None = None) -> None:
    """Checks of a viform header that need no key (a digest recomputed after an edit passes its own check).

    ``null`` in a field of :data:`NOT_NULL_FIELDS` is refused (viform writes a value there);
    a ``stored_width`` other than ``width`` is refused (viform stores rows without padding);
    with ``known`` (the header's whole field list), any other field is refused.
    """
    nulls = [k for k in NOT_NULL_FIELDS if k in header and header[k] is None]
    if nulls:
        raise ViformError(f"{where}: field {nulls[0]!r} is null, but viform always writes a value there: the "
                          "header was edited")
    if header.get("stored_width") is not None and header.get("width") is not None \
            and header["stored_width"] != header["width"]:
        raise ViformError(f"{where}: field 'stored_width' = {header['stored_width']!r} differs from 'width' = "
                          f"{header['width']!r}, but viform stores rows without padding: the header was edited")
    if known is not None:
        unknown = sorted(k for k in header if k not in known)
        if unknown:
            raise ViformError(f"{where}: field {unknown[0]!r} is not one this viform writes or reads in this "
                              "format: the header was edited, or written by a newer viform")


def _short(exc) -> str:
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return text[:200]


def _number(header: dict, key: str, where) -> float:
    value = header[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ViformError(f"{str(where)!r}: field {key!r} = {value!r} must be a number")
    return float(value)


def validate_header(header: dict, where, *, required=("height", "width", "clock_hz")) -> dict:
    """Check every field a reader relies on; return ``header`` unchanged.

    The same bounds hold for every layout (viform's sidecars and headers, other tools' arrays
    and sidecars), and are checked before anything is allocated from the fields.
    ``where`` (the file) and the field name appear in every message. Fields: ``height``,
    ``width`` (whole numbers in [1, 65536]), ``clock_hz`` (in [1, 1e12] Hz),
    ``threshold_electrons`` (null or in [0.5, 1e12] e⁻), ``start_time_s`` (|t| ≤ 1e12 s), ``n_ticks``
    (whole, in [0, 2^40]; with the clock, a duration of at most 1e12 s), ``rows`` (``bottom-up`` or
    ``upright``), ``bit_order`` (``little``), ``dark_current_e_per_s`` (null or finite ≥ 0),
    ``optics`` (null or an object of finite positive numbers).
    """
    if not isinstance(header, dict):
        raise ViformError(f"{str(where)!r}: the header must be an object, not {type(header).__name__}")
    for key in required:
        if key not in header or header[key] is None:
            raise ViformError(f"{str(where)!r}: required field {key!r} is missing")
    for key in ("height", "width"):
        if header.get(key) is not None:
            v = _number(header, key, where)
            if not (v.is_integer() and 1 <= v <= MAX_DIMENSION):
                raise ViformError(f"{str(where)!r}: field {key!r} = {header[key]!r} is not allowed: "
                                  f"it must be a whole number in [1, {MAX_DIMENSION}]")
    if header.get("clock_hz") is not None:
        v = _number(header, "clock_hz", where)
        if not (math.isfinite(v) and MIN_CLOCK_HZ <= v <= MAX_CLOCK_HZ):
            raise ViformError(f"{str(where)!r}: field 'clock_hz' = {header['clock_hz']!r} is not allowed: "
                              f"it must be a number of Hz in [{MIN_CLOCK_HZ:g}, {MAX_CLOCK_HZ:g}]")
    if header.get("threshold_electrons") is not None:
        v = _number(header, "threshold_electrons", where)
        if not (math.isfinite(v) and MIN_THRESHOLD_ELECTRONS <= v <= MAX_THRESHOLD_ELECTRONS):
            raise ViformError(f"{str(where)!r}: field 'threshold_electrons' = {header['threshold_electrons']!r} "
                              f"is not allowed: it must be a number of electrons in [{MIN_THRESHOLD_ELECTRONS:g}, "
                              f"{MAX_THRESHOLD_ELECTRONS:g}] (or null)")
    if header.get("start_time_s") is not None:
        v = _number(header, "start_time_s", where)
        if not (math.isfinite(v) and abs(v) <= MAX_START_TIME_S):
            raise ViformError(f"{str(where)!r}: field 'start_time_s' = {header['start_time_s']!r} must be finite, "
                              f"at most {MAX_START_TIME_S:g} s in magnitude")
    if header.get("n_ticks") is not None:
        v = _number(header, "n_ticks", where)
        if not (v.is_integer() and 0 <= v <= MAX_TICKS):
            raise ViformError(f"{str(where)!r}: field 'n_ticks' = {header['n_ticks']!r} is not allowed: "
                              f"it must be a whole number in [0, {MAX_TICKS}]")
        if header.get("clock_hz") is not None and v / float(header["clock_hz"]) > MAX_START_TIME_S:
            raise ViformError(f"{str(where)!r}: field 'n_ticks' = {header['n_ticks']!r} at clock_hz = "
                              f"{header['clock_hz']!r} lasts more than {MAX_START_TIME_S:g} s")
    for key, high in (("data_bytes", 1 << 62), ("stored_width", MAX_DIMENSION + 64), ("block_bytes", 1 << 40)):
        if header.get(key) is not None:
            v = header[key]
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= high:
                raise ViformError(f"{str(where)!r}: field {key!r} = {v!r} is not allowed: "
                                  f"it must be a whole number in [0, {high}]")
    for key in ("blake2b", "sidecar_blake2b", "header_blake2b"):
        if header.get(key) is not None and not isinstance(header[key], str):
            raise ViformError(f"{str(where)!r}: field {key!r} must be a hexadecimal string")
    if header.get("rows") is not None and header["rows"] not in ROW_ORDERS:
        raise ViformError(f"{str(where)!r}: field 'rows' = {header['rows']!r} is not supported: "
                          f"use one of {', '.join(ROW_ORDERS)}")
    if header.get("bit_order") is not None and header["bit_order"] != "little":
        raise ViformError(f"{str(where)!r}: field 'bit_order' = {header['bit_order']!r} is not supported: "
                          "only 'little' (least significant bit first)")
    if header.get("dark_current_e_per_s") is not None:
        v = _number(header, "dark_current_e_per_s", where)
        if not (math.isfinite(v) and v >= 0):
            raise ViformError(f"{str(where)!r}: field 'dark_current_e_per_s' = {header['dark_current_e_per_s']!r} "
                              "must be a finite number ≥ 0")
    optics = header.get("optics")
    if optics is not None:
        if not isinstance(optics, dict):
            raise ViformError(f"{str(where)!r}: field 'optics' must be an object")
        for key, value in optics.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not (math.isfinite(value) and value > 0):
                raise ViformError(f"{str(where)!r}: field 'optics.{key}' = {value!r} must be a finite number > 0")
    metadata = header.get("metadata")
    if metadata is not None and not isinstance(metadata, dict):
        raise ViformError(f"{str(where)!r}: field 'metadata' must be an object")
    return header


def source_metadata(header: dict) -> dict:
    """The stream metadata to attach to a reader: the header's ``metadata`` plus the flat fields.

    A sidecar written by another tool (e.g. a dataset writer) may give ``optics`` and
    ``dark_current_e_per_s`` flat without a ``sensor`` object: they are gathered into one so
    that imaging can give lux (:func:`viform.imaging.units.sensor_parameters_of`).
    """
    meta = dict(header.get("metadata") or {})
    for key in ("scene", "seed", "viform_version", "command_line", "utc_date"):
        if header.get(key) is not None and key not in meta:
            meta[key] = header[key]
    if "sensor" not in meta and header.get("optics") is not None:
        sensor = {"model": "spike", "optics": header["optics"],
                  "dark_current_e_per_s": header.get("dark_current_e_per_s") or 0.0}
        if header.get("threshold_electrons") is not None:
            sensor["threshold_electrons"] = header["threshold_electrons"]
        if header.get("clock_hz") is not None:
            sensor["clock_hz"] = header["clock_hz"]
        meta["sensor"] = sensor
    for key, value in header.items():  # other tools' fields (source clip, labels) stay visible
        if key not in meta and key not in _HEADER_KEYS and not isinstance(value, (dict, list)):
            meta[key] = value
    return meta


_HEADER_KEYS = {"format", "version", "height", "width", "n_ticks", "clock_hz", "threshold_electrons",
                "start_time_s", "rows", "bit_order", "optics", "dark_current_e_per_s", "metadata",
                "stored_width", "data_bytes", "blake2b", "chunks", "chunk_ticks", "axes", "block_bytes",
                "block_crc32", "header_blake2b", "member_bytes"}
