"""Central bounds on every command's options, applied after the command modules load.

Command modules declare options with plain ``type=float`` / ``type=int``; :func:`install`
walks every command and

- replaces float and int types by :class:`BoundedFloat` / :class:`BoundedInt`: finite, and
  |x| ≤ 1e12 for floats, |n| ≤ 2^31 for whole numbers (values past those overflow, hang or
  exhaust memory downstream); the error names the flag the user typed (``--duration``);
  an option may declare its own limit with ``param.viform_limit``, and :data:`OPTION_BOUNDS`
  gives some options a physical range with the reason (``lightcomm --clock-hz``, ``--bits``,
  ``display --eye-ms``);
- wraps each command so that a :class:`~viform._validate.ViformError` naming a Python
  parameter (``duration_s``) names the flag instead (``--duration``);
- refuses, before any work, requests too big for memory (``--height × --width`` above
  :func:`max_pixels`, ``VIFORM_MAX_PIXELS`` to raise it; pixel-ticks of ``--duration`` ×
  ``--clock-hz`` × pixels above :func:`max_pixel_ticks`, ``VIFORM_MAX_PIXEL_TICKS``; light-link
  ticks of bits × ``--clock-hz`` / ``--bitrate`` above :data:`MAX_LINK_TICKS`), output
  paths that cannot be written (an existing folder where a file goes, an unwritable folder;
  ``--json-file`` of every command by :func:`viform._io.check_json_file`, whose help it sets),
  and inputs that are not regular files or folders (a FIFO would block the reader).
"""

from __future__ import annotations

import functools
import math
import os
import re
from pathlib import Path

import click

from viform._io import JSON_FILE_HELP, check_json_file, folder_writable
from viform._validate import ViformError

#: Largest magnitude of a float option unless the option declares ``viform_limit``.
FLOAT_LIMIT = 1e12
#: Largest magnitude of an int option.
INT_LIMIT = 2**31
#: Default caps on the size of a request (environment variables raise them).
DEFAULT_MAX_PIXELS = 4096 * 4096
DEFAULT_MAX_PIXEL_TICKS = 1e12
#: Most ticks one request may produce (tick indices are 32-bit in the event and coded formats).
MAX_TICKS = 2**31
#: Sampling rate assumed when a command with ``--duration`` is given no clock (the spike camera's 40 kHz).
DEFAULT_RATE_HZ = 40_000.0

#: Bounds of single options that the magnitude limit above does not give, by (command, option
#: name): (low, high, unit, why). Values outside them describe no real device and would run for
#: minutes or hours before doing anything useful; the error says what is allowed and why.
OPTION_BOUNDS = {
    ("lightcomm", "clock_hz"): (1.0, 1e8, "Hz", "a spike pixel is read at most every 10 ns, and every tick of the "
                                               "link is simulated"),
    ("lightcomm", "n_bits"): (1, 1_000_000, "bits", "0 errors in 10⁶ bits already bounds the bit-error rate below "
                                                    "3e-6 at 95 %, and every bit is simulated tick by tick"),
    ("display", "eye_ms"): (0.025, 200.0, "ms", "at least one 25 µs tick of the 40 kHz camera; the eye integrates "
                                                "for 10–100 ms, and 200 ms already simulates 0.32 s of the camera"),
    ("reconstruct", "fps"): (0.1, 1000.0, "frames/s", "a GIF holds each frame at most 655 s, and no display shows "
                                                      "more than about 1000 frames a second"),
    ("simulate", "clock_hz"): (1.0, 1e12, "Hz", "the clock range a spike file may record: a file written at "
                                               "another clock could not be read back"),
    ("dataset", "frame_rate_hz"): (1.0, 1e6, "Hz", "the frame rate of real videos and image sequences; a clip lasts "
                                                   "its frames ÷ this rate, all of it simulated at the spike clock"),
}
#: Simulation work a command runs without ``--force``, estimated seconds (about a minute). The
#: estimate uses the simulator's speed on one core of an idle machine (README "Speed": 1.6–3.8e8
#: pixel-ticks/s on textured scenes; ~14 µs of scene and bookkeeping per tick measured
#: at 48×32): :data:`SIM_PIXEL_TICKS_PER_S` and :data:`SIM_S_PER_TICK`, on the slow side.
FORCE_WORK_S = 60.0
SIM_PIXEL_TICKS_PER_S = 1e8
SIM_S_PER_TICK = 1e-5
#: Ticks one run of the light link may simulate: it holds them all (about 1 kB each over its
#: 8×8 pixels, ~8 µs each on one core), so 10⁶ ticks is about 1 GB and 10 s.
MAX_LINK_TICKS = 1e6
#: Ticks all the runs of one ``lightcomm`` may simulate (the BER sweeps repeat the link 23 times).
MAX_LINK_TICKS_TOTAL = 4e6
#: Runs and payload bits of the distance and ambient-light sweeps (``lightcomm --sweeps`` / ``--out``).
SWEEP_RUNS, SWEEP_BITS = 23, 300

#: Library parameter names that hold the value of a command's option in the same unit, by
#: (command, option name): an error raised deep inside (``gate_range_m = 1e+09 m is beyond…``)
#: then names the flag the user typed (``--gate-m``).
LIBRARY_NAMES = {
    ("gated", "gate_m"): ("gate_range_m",),
    ("lightcomm", "led_cd"): ("luminous_intensity_cd",),
    ("highspeed", "scene_fps"): ("frame_rate_hz",),
    ("dataset", "worker_memory"): ("memory_limit",),
}

#: Option names that hold an output path.
OUTPUT_NAMES = ("out", "out_path", "out_dir", "output", "json_file", "json_path", "preview", "dst", "video")
#: Suffixes that name files (an existing folder of that name cannot be replaced by a file).
FILE_SUFFIXES = (".dat", ".npz", ".vfc", ".png", ".json", ".gif", ".mp4", ".html", ".csv", ".txt", ".yaml")


def _env_number(name: str, default: float) -> float:
    text = os.environ.get(name)
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        raise ViformError(f"environment variable {name} = {text!r} must be a number") from None
    if not (math.isfinite(value) and value > 0):
        raise ViformError(f"environment variable {name} = {text!r} must be a finite number > 0")
    return value


def max_pixels() -> float:
    """Largest height × width a command accepts (``VIFORM_MAX_PIXELS``, default 4096²)."""
    return _env_number("VIFORM_MAX_PIXELS", DEFAULT_MAX_PIXELS)


def max_pixel_ticks() -> float:
    """Largest ticks × pixels a command accepts (``VIFORM_MAX_PIXEL_TICKS``, default 1e12)."""
    return _env_number("VIFORM_MAX_PIXEL_TICKS", DEFAULT_MAX_PIXEL_TICKS)


def _check_bounds(kind: click.ParamType, number, value, param, ctx) -> None:
    """Refuse ``number`` outside the option's :data:`OPTION_BOUNDS` entry, saying why."""
    if kind.bounds is None:
        return
    low, high, unit, why = kind.bounds
    if not low <= number <= high:
        kind.fail(f"{value!r} is not allowed: it must be in [{low:g}, {high:g}] {unit} ({why})", param, ctx)


class BoundedFloat(click.ParamType):
    """A finite float with |x| ≤ ``limit`` (and within ``bounds``), then the original type's own checks."""

    name = "float"

    def __init__(self, inner: click.ParamType | None = None, limit: float = FLOAT_LIMIT, bounds=None):
        self.inner = inner if inner is not None else click.FLOAT
        self.limit = float(limit)
        self.bounds = bounds

    def convert(self, value, param, ctx):
        if isinstance(value, bool):
            self.fail(f"{value!r} is not a number", param, ctx)
        try:
            number = float(value)
        except (TypeError, ValueError, OverflowError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not allowed: give a finite number", param, ctx)
        if abs(number) > self.limit:
            self.fail(f"{value!r} is not allowed: its magnitude must be at most {self.limit:g}", param, ctx)
        _check_bounds(self, number, value, param, ctx)
        return self.inner.convert(number if isinstance(value, str) else value, param, ctx)

    def get_metavar(self, param, ctx=None):
        return self.inner.get_metavar(param, ctx) if ctx is not None else None

    def __repr__(self):
        return "FLOAT"


class BoundedInt(click.ParamType):
    """A whole number with |n| ≤ ``limit`` (and within ``bounds``), then the original type's own checks."""

    name = "integer"

    def __init__(self, inner: click.ParamType | None = None, limit: int = INT_LIMIT, bounds=None):
        self.inner = inner if inner is not None else click.INT
        self.limit = int(limit)
        self.bounds = bounds

    def convert(self, value, param, ctx):
        if isinstance(value, bool):
            self.fail(f"{value!r} is not a whole number", param, ctx)
        if isinstance(value, str):
            text = value.strip()
            if not re.fullmatch(r"[+-]?\d{1,30}", text):
                self.fail(f"{value!r} is not a whole number", param, ctx)
            number = int(text)
        elif isinstance(value, int):
            number = value
        else:
            try:
                f = float(value)
            except (TypeError, ValueError):
                self.fail(f"{value!r} is not a whole number", param, ctx)
            if not (math.isfinite(f) and f.is_integer()):
                self.fail(f"{value!r} is not a whole number", param, ctx)
            number = int(f)
        if abs(number) > self.limit:
            self.fail(f"{value!r} is not allowed: its magnitude must be at most {self.limit}", param, ctx)
        _check_bounds(self, number, value, param, ctx)
        return self.inner.convert(number, param, ctx)

    def get_metavar(self, param, ctx=None):
        return self.inner.get_metavar(param, ctx) if ctx is not None else None

    def __repr__(self):
        return "INT"


def _bounded(kind: click.ParamType, param, bounds=None) -> click.ParamType:
    if isinstance(kind, (BoundedFloat, BoundedInt)):
        return kind
    limit = getattr(param, "viform_limit", None)
    if isinstance(kind, click.types.FloatParamType):
        return BoundedFloat(kind, FLOAT_LIMIT if limit is None else limit, bounds)
    if isinstance(kind, click.types.IntParamType):
        return BoundedInt(kind, INT_LIMIT if limit is None else int(limit), bounds)
    if isinstance(kind, click.Tuple):
        kind.types = [_bounded(t, param) for t in kind.types]
    return kind


def flag_of(param: click.Parameter) -> str:
    """The flag the user types for ``param`` (its longest ``--`` form), or its metavar name."""
    if isinstance(param, click.Argument):
        return (param.name or "").upper()  # as the usage line shows it (DST)
    longs = [o for o in param.opts if o.startswith("--")]
    if longs:
        return max(longs, key=len)
    return param.opts[0] if param.opts else param.name


def flag_message(message: str, flags: dict) -> str:
    """``message`` with the library parameters it names replaced by their flags, by the explicit
    mapping ``flags`` (parameter name → flag); unchanged when it names none of them.

    Library errors begin with the name of the parameter they are about (``duration_s = 20 s is not
    allowed …``), and name any other parameter in the same form (``… could not connect within
    connect_timeout_s = 20 s``); a command that declares its mapping (``command.viform_flags``)
    gets only these exact replacements (the leading name, and ``NAME = `` as a whole word later),
    no guessing from its option names.
    """
    names = sorted(flags, key=len, reverse=True)
    for name in names:
        if message.startswith(name) and message[len(name):len(name) + 1] in (" ", ":", "="):
            head, message = flags[name], message[len(name):]
            break
    else:
        head = ""
    for name in names:
        message = re.sub(rf"(?<![\w'\"./-]){re.escape(name)}(?= = )", lambda _, flag=flags[name]: flag, message)
    return head + message


def name_flags(message: str, command: click.Command) -> str:
    """Replace Python parameter names (``duration_s``) in ``message`` by the command's flags.

    A command with an explicit mapping (``command.viform_flags``, parameter name → flag) gets
    :func:`flag_message`. Otherwise only option names are replaced, only as whole words not inside
    quotes (file fields such as ``'clock_hz'`` stay), and names without an underscore only when
    followed by `` = ``. A remedy in keyword form names the flag as it is typed: ``height=250`` →
    ``--height 250``, ``allow_partial=True`` → ``--allow-partial``.
    """
    explicit = getattr(command, "viform_flags", None)
    if explicit is not None:
        return flag_message(message, explicit)
    names = {p.name for p in command.params if p.name}
    names_with_units = {n for n in names if any(m.startswith(n + "_") for m in names)}
    for param in sorted(command.params, key=lambda p: -len(p.name or "")):
        if not isinstance(param, click.Option) or not param.name:
            continue
        flag = flag_of(param)
        # a library remedy in keyword form: "allow_partial=True" is the flag itself, "height=250" is "--height 250"
        if getattr(param, "is_flag", False):
            message = re.sub(rf"(?<![\w'\"./-]){re.escape(param.name)}=True(?![\w'\"-])", flag, message)
        else:
            message = re.sub(rf"(?<![\w'\"./-]){re.escape(param.name)}=(?=[^\s,;)])", flag + " ", message)
        if flag.lstrip("-") == param.name and "_" not in param.name:
            pattern = rf"(?<![\w'\"./-]){re.escape(param.name)}(?= = )"
        elif "_" in param.name:
            pattern = rf"(?<![\w'\"./-]){re.escape(param.name)}(?![\w'\"-])"
        else:
            pattern = rf"(?<![\w'\"./-]){re.escape(param.name)}(?= = )"
        message = re.sub(pattern, flag, message)
        # the library's name with its unit (--slack → slack_ticks, --threshold → threshold_electrons)
        if param.name not in names_with_units:
            message = re.sub(rf"(?<![\w'\"./-]){re.escape(param.name)}_(?:{_UNIT_SUFFIXES})(?![\w'\"-])", flag,
                             message)
        for alias in LIBRARY_NAMES.get((command.name, param.name), ()):
            message = re.sub(rf"(?<![\w'\"./-]){re.escape(alias)}(?![\w'\"-])", flag, message)
    return message


_UNIT_SUFFIXES = "ticks|electrons|s|hz|m|lux|v|e_per_s|fraction|db|bps|ms|us|mhz|px_per_s|cd"


def _first(kwargs: dict, *names):
    for name in names:
        if kwargs.get(name) is not None:
            return name, kwargs[name]
    return None, None


def check_request(command: click.Command, kwargs: dict) -> None:
    """Refuse requests that would exceed memory, unwritable outputs and non-regular inputs."""
    flags = {p.name: flag_of(p) for p in command.params}
    height, width = kwargs.get("height"), kwargs.get("width")
    size = kwargs.get("size")
    pixels = None
    if isinstance(height, int) and isinstance(width, int):
        if height < 1 or width < 1:
            raise ViformError(f"{flags['height']} = {height} and {flags['width']} = {width}: both must be ≥ 1")
        pixels = height * width
        what = f"{flags['width']} {width} × {flags['height']} {height}"
    elif isinstance(size, int) and size > 0:
        pixels = size * size
        what = f"{flags['size']} {size} (× {size})"
    if pixels is not None and pixels > max_pixels():
        raise ViformError(f"{what} = {pixels:.4g} pixels is more than the limit of {max_pixels():.4g} pixels "
                          "(about 64 bytes of working memory each); raise it with the environment variable "
                          "VIFORM_MAX_PIXELS if this machine has the memory")
    _, duration = _first(kwargs, "duration_s")
    rate_name, rate = _first(kwargs, "clock_hz", "frame_rate_hz")
    if rate_name is None:
        rate = DEFAULT_RATE_HZ  # the spike camera's clock: the fastest sampling a command takes by default
    if isinstance(duration, (int, float)) and isinstance(rate, (int, float)) and duration > 0 and rate > 0 \
            and duration * rate > MAX_TICKS:
        raise ViformError(f"{flags['duration_s']} {duration:g} s at {rate:g} Hz is {duration * rate:.4g} ticks, more "
                          f"than the {MAX_TICKS:.4g} a stream may hold; split the recording")
    if pixels is not None and isinstance(duration, (int, float)) and isinstance(rate, (int, float)) \
            and duration > 0 and rate > 0:
        pixel_ticks = pixels * duration * rate
        if pixel_ticks > max_pixel_ticks():
            raise ViformError(f"{flags['duration_s']} {duration:g} s at {rate:g} Hz over {pixels:.4g} pixels is "
                              f"{pixel_ticks:.4g} pixel-ticks ({pixel_ticks / 8e9:.4g} GB of raw spike bits), more "
                              f"than the limit of {max_pixel_ticks():.4g}; raise it with the environment variable "
                              "VIFORM_MAX_PIXEL_TICKS")
    if isinstance(kwargs.get("bitrate_bps"), (int, float)):
        _check_link_work(kwargs, flags)
    for param in command.params:
        value = kwargs.get(param.name)
        if value is None or not isinstance(param.type, click.Path) or isinstance(value, (tuple, list)):
            continue
        path = Path(value)
        if flags[param.name] == "--json-file":
            check_json_file(path, "--json-file")  # one rule for every command (viform._io)
        elif param.name in OUTPUT_NAMES:
            _check_output(flags[param.name], path)
        elif path.exists() and not (path.is_file() or path.is_dir()):
            raise ViformError(f"{flags[param.name]}: {str(path)!r} is not a regular file or folder "
                              "(a FIFO, socket or device cannot be read as data)")


def check_simulation_work(duration_s: float, clock_hz: float, pixels: int, force: bool,
                          clock_flag: str = "--clock-hz") -> None:
    """Refuse, unless ``--force``, a simulation estimated to take more than :data:`FORCE_WORK_S`.

    The user is told the size and the estimate before minutes of work, and how to go on;
    ``clock_flag`` is how the command's user sets the clock.
    """
    ticks = duration_s * clock_hz
    seconds = ticks * SIM_S_PER_TICK + ticks * pixels / SIM_PIXEL_TICKS_PER_S
    if seconds > FORCE_WORK_S and not force:
        raise ViformError(f"--duration {duration_s:g} s at {clock_flag} {clock_hz:g} Hz over {pixels:,} pixels is "
                          f"{ticks:.3g} ticks ({ticks * pixels:.3g} pixel-ticks), about {seconds / 60:.0f} min of "
                          f"simulation or more (the limit without --force is {FORCE_WORK_S:.0f} s): add --force to "
                          "run it, or shorten --duration")


def _check_link_work(kwargs: dict, flags: dict) -> None:
    """Refuse a light-link request whose simulation would hold or run too many ticks.

    One bit lasts clock / bit rate ticks whatever the modulation; every tick is simulated.
    """
    bitrate, clock = kwargs["bitrate_bps"], kwargs.get("clock_hz") or DEFAULT_RATE_HZ
    if not (bitrate > 0 and clock > 0):
        return  # the command's own checks name the flag
    message = kwargs.get("message")
    bits = 8 * len(message.encode("utf-8", "replace")) if message else (kwargs.get("n_bits") or 0)
    what = f"{len(message)} characters of --message ({bits} bits)" if message else f"{flags['n_bits']} {bits}"
    per_bit = clock / bitrate
    ticks = bits * per_bit
    sweeps = bool(kwargs.get("sweeps") or kwargs.get("out"))
    total = ticks + (SWEEP_RUNS * SWEEP_BITS * per_bit if sweeps else 0.0)
    if ticks > MAX_LINK_TICKS:
        raise ViformError(f"{flags['bitrate_bps']} {bitrate:g} bit/s with {what} at {flags['clock_hz']} {clock:g} Hz "
                          f"is {ticks:.3g} ticks of the link to simulate (about 1 kB of memory each), more than "
                          f"the {MAX_LINK_TICKS:,.0f} a run may hold: use at least {bits * clock / MAX_LINK_TICKS:.3g} "
                          f"bit/s, fewer bits or a slower {flags['clock_hz']}")
    if total > MAX_LINK_TICKS_TOTAL:
        raise ViformError(f"{flags['bitrate_bps']} {bitrate:g} bit/s at {flags['clock_hz']} {clock:g} Hz: the BER "
                          f"sweeps (--sweeps, or --out) send {SWEEP_BITS} bits {SWEEP_RUNS} more times, "
                          f"{total:.3g} ticks in all, more than {MAX_LINK_TICKS_TOTAL:,.0f} (about 30 s): use at least "
                          f"{(bits + SWEEP_RUNS * SWEEP_BITS) * clock / MAX_LINK_TICKS_TOTAL:.3g} bit/s or leave the "
                          "sweeps out")


def _check_output(flag: str, path: Path) -> None:
    if path.suffix.lower() in FILE_SUFFIXES and path.is_dir():
        raise ViformError(f"{flag} = {str(path)!r} is an existing folder; a {path.suffix} file was expected")
    if path.exists() and not (path.is_file() or path.is_dir()):
        raise ViformError(f"{flag} = {str(path)!r} is not a regular file or folder")
    existing = path.parent if path.suffix else path
    existing = existing if str(existing) else Path(".")
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ViformError(f"{flag} = {str(path)!r} cannot be written: {str(existing)!r} is not a folder")
    if not folder_writable(existing):
        raise ViformError(f"{flag} = {str(path)!r} cannot be written: the folder {str(existing)!r} is not writable")


def _wrap(command: click.Command) -> None:
    callback = command.callback
    if callback is None or getattr(callback, "_viform_wrapped", False):
        return

    @functools.wraps(callback)
    def run(*args, **kwargs):
        try:
            check_request(command, kwargs)
            return callback(*args, **kwargs)
        except ViformError as exc:
            # a remedy that needs a parameter this command has no flag for is left out
            options = {p.name for p in command.params if isinstance(p, click.Option)}
            text = name_flags(exc.without(options.__contains__) if exc.remedies else str(exc), command)
            if text == str(exc):
                raise
            raise ViformError(text) from None

    run._viform_wrapped = True
    command.callback = run


def walk(group: click.Command):
    """Every leaf command under ``group``."""
    if isinstance(group, click.Group):
        for sub in group.commands.values():
            yield from walk(sub)
    else:
        yield group


def install(group: click.Group) -> None:
    """Bound every numeric option of every command under ``group`` and wrap its callback."""
    for command in walk(group):
        for param in command.params:
            bounds = OPTION_BOUNDS.get((command.name, param.name))
            param.type = _bounded(param.type, param, bounds)
            if bounds is not None and isinstance(param, click.Option) and "allowed:" not in (param.help or ""):
                param.help = f"{param.help or ''}  [allowed: {bounds[0]:g}–{bounds[1]:g} {bounds[2]}]".strip()
            if isinstance(param, click.Option) and flag_of(param) == "--json-file":
                # one behaviour, checked by one function and described the same way everywhere
                param.type = click.Path()
                param.help = JSON_FILE_HELP
        _wrap(command)
