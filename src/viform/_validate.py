"""Parameter checks used at every public boundary.

Each check raises :class:`ValueError` whose message names the parameter, the value given
and what is allowed, so the CLI can print it as a single line.
"""

from __future__ import annotations

import math
import numbers


class ViformError(ValueError):
    """Bad input to viform; the message is a complete one-line explanation.

    ``remedies`` maps a parameter name to a way out that needs it (``{"allow_partial": "keep
    the whole frames with allow_partial=True"}``): each is appended to the message (after
    "; "). A caller that lacks the parameter drops its remedy (the command line keeps only
    those of flags the command has, see :attr:`message` and :attr:`remedies`).
    """

    def __init__(self, message: str = "", *args, remedies: dict | None = None):
        self.message = str(message)
        self.remedies = dict(remedies or {})
        text = self.message + "".join(f"; {r}" for r in self.remedies.values())
        super().__init__(text, *args)

    def without(self, keep) -> str:
        """The message with only the remedies whose parameter ``keep(name)`` accepts."""
        return self.message + "".join(f"; {r}" for name, r in self.remedies.items() if keep(name))


class ViformWarning(UserWarning):
    """Something the user should know about a result that is still produced (one line)."""


class UnverifiedDataWarning(ViformWarning):
    """Data read without checksums viform can verify (another tool's file, or its checksums removed)."""


def size_text(height: int, width: int, unit: str = "px") -> str:
    """An image size as viform prints it everywhere: width × height, as cameras are quoted
    (``size_text(250, 400)`` is ``'400×250 px'``); ``unit=""`` leaves the unit off.

    Examples
    --------
    >>> size_text(250, 400)
    '400×250 px'
    >>> size_text(250, 400, unit="")
    '400×250'
    """
    return f"{width}×{height}" + (f" {unit}" if unit else "")


def warning_line(message, category) -> str:
    """A warning as one line: ``viform: warning: TEXT`` (its first line), and for a library's warning
    ``(Category from library)`` — no source line, no file path."""
    import sys

    lines = [line for line in str(message).splitlines() if line.strip()]
    text = lines[0] if lines else category.__name__
    if not issubclass(category, ViformWarning):
        origin = _warning_origin(sys._getframe(2))
        text += f" ({category.__name__}{f' from {origin}' if origin else ''})"
    return f"viform: warning: {text}"


def _warning_origin(frame) -> str | None:
    """The installed library whose code issued the warning being shown (the first frame below the
    warnings machinery), or None (viform's own code, or a warning raised from C)."""
    import os

    while frame is not None and frame.f_globals.get("__name__", "").split(".")[0] in ("warnings", "viform"):
        if frame.f_globals.get("__name__", "").startswith("viform"):
            return None
        frame = frame.f_back
    if frame is None:
        return None
    parts = os.path.normpath(frame.f_code.co_filename).split(os.sep)
    for i in range(len(parts) - 1):
        if parts[i] in ("site-packages", "dist-packages"):
            name = parts[i + 1]
            return name[:-3] if name.endswith(".py") else name
    return None


def show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A replacement of :func:`warnings.showwarning` that prints :func:`warning_line` on stderr."""
    import sys

    stream = sys.stderr if file is None else file
    try:
        stream.write(warning_line(message, category) + "\n")
        stream.flush()
    except (OSError, ValueError):  # a closed or broken stream: as Python's own display does
        pass


def _as_float(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise ViformError(f"{name} must be a number, got {value!r}") from None
    value = float(value)
    if math.isnan(value):
        raise ViformError(f"{name} is NaN; a finite number is required")
    return value


def check_positive(name: str, value, *, allow_inf: bool = False) -> float:
    """``value`` > 0 (finite unless ``allow_inf``)."""
    v = _as_float(name, value)
    if not v > 0 or (math.isinf(v) and not allow_inf):
        raise ViformError(f"{name} = {value!r} is not allowed: it must be a finite number > 0")
    return v


def check_non_negative(name: str, value) -> float:
    """``value`` ≥ 0 and finite."""
    v = _as_float(name, value)
    if not (v >= 0) or math.isinf(v):
        raise ViformError(f"{name} = {value!r} is not allowed: it must be a finite number ≥ 0")
    return v


def check_range(name: str, value, low: float, high: float, *, low_open: bool = False,
                high_open: bool = False) -> float:
    """``low ≤ value ≤ high`` (open ends on request)."""
    v = _as_float(name, value)
    ok_low = v > low if low_open else v >= low
    ok_high = v < high if high_open else v <= high
    if not (ok_low and ok_high):
        left = "(" if low_open else "["
        right = ")" if high_open else "]"
        raise ViformError(f"{name} = {value!r} is not allowed: it must lie in {left}{low:g}, {high:g}{right}")
    return v


def check_int(name: str, value, low: int | None = None, high: int | None = None) -> int:
    """An integer within [low, high]."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        if isinstance(value, numbers.Real) and float(value).is_integer():
            value = int(value)
        else:
            raise ViformError(f"{name} = {value!r} is not allowed: it must be a whole number")
    value = int(value)
    if (low is not None and value < low) or (high is not None and value > high):
        bounds = f"[{'-inf' if low is None else low}, {'inf' if high is None else high}]"
        raise ViformError(f"{name} = {value} is not allowed: it must be a whole number in {bounds}")
    return value


def check_choice(name: str, value, choices) -> str:
    """One of ``choices``."""
    if value not in choices:
        raise ViformError(f"{name} = {value!r} is not allowed: choose one of {', '.join(map(str, choices))}")
    return value


def one_line(exc: BaseException, limit: int = 300) -> str:
    """A short one-line summary of a third-party exception (its last non-empty line)."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    text = lines[-1] if lines else type(exc).__name__
    return text if len(text) <= limit else text[: limit - 1] + "…"
