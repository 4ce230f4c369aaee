"""Spike-camera presets for the real chips, and JSON presets written by ``viform calibrate``.

Seed 000 §6 describes two chips: SpikeOne (2017, 110 nm CMOS, 450×200 pixels; the
recordings people share are 400×250, so the ``spikeone`` preset uses that size) and SpikeTwo
(2021, 1000×1000), clocked at 40 kHz (shortest interval 25 µs) or in a 20 kHz mode, with an
externally set accumulation threshold Q that "supports 16 levels of adjustment".

Thresholds. The seed gives Q only as worked examples (100 e⁻, §4.3; 10⁴ e⁻ is where the
interval RSD falls below 1 %, §5.1). Real recordings settle it: the intervals of steady
pixels are nearly pure tick-rounded integrate-and-fire, which needs an *effective*
threshold of order 10⁴ e⁻ (every per-spike charge noise — photon, reset, comparator —
lumped into one Gamma(Q_eff) law, :mod:`viform.measure.calibration`). Light that changes
during a recording only adds interval noise, so every recording bounds Q_eff from below:
static recordings of the real chip give ≈ 9,500 e⁻ (RSD 0.025 at 17.9 ticks), and
``viform calibrate`` on the shared 40 kHz clip ``real_uhsr_250x250.npz`` gives
Q_eff ≥ 15,903 e⁻ (95 % lower bound from its steadiest tiles; fit 19,260 e⁻; 16,188 before
the clip's 3 % drift entered the rounding term). The
built-in presets use the chip level nearest that bound, :data:`DEFAULT_THRESHOLD_LEVEL`
(16,250 e⁻): the noisiest sensor the real data allow.

The 16 levels are not listed in the seed. viform assumes a linear threshold DAC
(Q = C·ΔV with ΔV in 16 equal steps): level k (0…15) gives (k + 1) · 1,250 e⁻, i.e.
1,250 … 20,000 e⁻ (C ≈ 3.2 fF at a 1 V full swing), so the measured real thresholds fall
inside the range. This is an assumption; a calibrated
preset (``viform calibrate``) states its own measured Q instead.

Preset JSON (``save_spike_preset`` writes it; ``load_spike_preset`` validates it)::

    {"format": "viform-spike-preset", "version": 1,
     "name": "...", "description": "...", "height": 250, "width": 400,
     "threshold_level": null,                   # or 0…15 instead of sensor.threshold_electrons
     "sensor": {"threshold_electrons": 10000, "clock_hz": 40000, ...,
                "optics": {"pixel_pitch_m": 1e-05, "quantum_efficiency": 0.7, ...}},
     "calibration": {...}}                      # optional, free-form: what was measured

``sensor`` accepts any field of :class:`~viform.sensors.spike.SpikeSensorParameters`;
unknown keys are refused with the list of allowed ones.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from viform._validate import ViformError, check_int
from viform.light.radiometry import PixelOptics
from viform.sensors.spike import CLOCK_20KHZ, CLOCK_40KHZ, SpikeSensor, SpikeSensorParameters

#: Format tag of preset JSON files.
PRESET_FORMAT = "viform-spike-preset"
PRESET_VERSION = 1

#: Threshold step of the assumed linear 16-level threshold DAC, e⁻ (see the module notes).
THRESHOLD_LEVEL_STEP_ELECTRONS = 1250.0
#: Number of chip threshold levels (seed 000 §6).
N_THRESHOLD_LEVELS = 16
#: Level used by the built-in chip presets: 16,250 e⁻, the level nearest the lower bound of
#: the effective threshold measured on the shared real recording (module notes,
#: docs/calibration.md).
DEFAULT_THRESHOLD_LEVEL = 12

_TOP_KEYS = ("format", "version", "name", "description", "height", "width", "threshold_level", "sensor",
             "calibration")
_OPTICS_KEYS = tuple(f.name for f in dataclasses.fields(PixelOptics))


def threshold_level_electrons(level: int) -> float:
    """Threshold Q of chip level ``level`` (0…15), e⁻: (level + 1) · 1,250 e⁻.

    Seed 000 §6: the threshold "supports 16 levels of adjustment"; the linear DAC law is
    viform's assumption (module notes).
    """
    from viform.sensors.spike import CHIP_THRESHOLD_LEVELS_ELECTRONS

    level = check_int("threshold level", level, 0, N_THRESHOLD_LEVELS - 1)
    return CHIP_THRESHOLD_LEVELS_ELECTRONS[level]


def threshold_levels_electrons() -> tuple[float, ...]:
    """All 16 chip threshold levels, e⁻."""
    return tuple(threshold_level_electrons(k) for k in range(N_THRESHOLD_LEVELS))


def _sensor_fields() -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(SpikeSensorParameters)}


@dataclass(frozen=True)
class SpikePreset:
    """A named spike sensor: resolution plus :class:`SpikeSensorParameters`.

    Attributes
    ----------
    name, description : str
    height, width : int
        Resolution, pixels.
    parameters : SpikeSensorParameters
    threshold_level : int or None
        The chip level the threshold came from, if any.
    calibration : dict
        What a calibration measured (free-form, kept in the JSON), empty for built-ins.
    """

    name: str
    description: str
    height: int
    width: int
    parameters: SpikeSensorParameters
    threshold_level: int | None = None
    calibration: dict = field(default_factory=dict)

    def sensor(self, **overrides) -> SpikeSensor:
        """The :class:`SpikeSensor` of this preset; ``overrides`` replace parameter fields.

        ``height``/``width`` may be overridden too; ``threshold_level=N`` sets the threshold
        to chip level N (:func:`threshold_level_electrons`).
        """
        height = overrides.pop("height", self.height)
        width = overrides.pop("width", self.width)
        level = overrides.pop("threshold_level", None)
        if level is not None:
            if "threshold_electrons" in overrides:
                raise ViformError("give either threshold_level or threshold_electrons, not both")
            overrides["threshold_electrons"] = threshold_level_electrons(level)
        return SpikeSensor(self.parameters, height, width, **overrides)

    def with_threshold_level(self, level: int) -> SpikePreset:
        """A copy at chip threshold level ``level``."""
        q = threshold_level_electrons(level)
        return dataclasses.replace(self, parameters=dataclasses.replace(self.parameters, threshold_electrons=q),
                                   threshold_level=int(level))

    def to_dict(self) -> dict:
        """The JSON form (see the module notes)."""
        sensor = dataclasses.asdict(self.parameters)
        return {"format": PRESET_FORMAT, "version": PRESET_VERSION, "name": self.name,
                "description": self.description, "height": self.height, "width": self.width,
                "threshold_level": self.threshold_level, "sensor": sensor, "calibration": self.calibration}


def _optics(**kw) -> PixelOptics:
    return PixelOptics(**kw)


def _chip_parameters(clock_hz: float, **extra) -> SpikeSensorParameters:
    """Parameters common to the chip presets; noise-model fields set only where this tree has them."""
    kw = dict(optics=_optics(pixel_pitch_m=10e-6, quantum_efficiency=0.7),
              threshold_electrons=threshold_level_electrons(DEFAULT_THRESHOLD_LEVEL),
              clock_hz=clock_hz, dark_current_e_per_s=20.0)
    names = _sensor_fields()
    kw.update({k: v for k, v in extra.items() if k in names})
    return SpikeSensorParameters(**kw)


#: Pixel-to-pixel photo-response (gain) spread of a flat field, std/mean: ≈ 3 % in the flat
#: regions of static real recordings. The shared clip gives ≤ 8.1 %
#: (``viform calibrate``: an upper bound, the displayed picture's grain included).
CHIP_GAIN_SPREAD_FRACTION = 0.03


def _builtin(name: str) -> SpikePreset:
    noise = dict(gain_spread_fraction=CHIP_GAIN_SPREAD_FRACTION)
    if name == "spikeone":
        return SpikePreset(
            "spikeone", "SpikeOne-class spike camera, 400×250 pixels at 40 kHz (as the shared recordings), "
            f"Q = {threshold_level_electrons(DEFAULT_THRESHOLD_LEVEL):,.0f} e⁻ (level {DEFAULT_THRESHOLD_LEVEL})",
            250, 400, _chip_parameters(CLOCK_40KHZ, **noise), DEFAULT_THRESHOLD_LEVEL)
    if name == "spiketwo":
        return SpikePreset(
            "spiketwo", "SpikeTwo spike camera, 1000×1000 pixels, 20 kHz mode, "
            f"Q = {threshold_level_electrons(DEFAULT_THRESHOLD_LEVEL):,.0f} e⁻ (level {DEFAULT_THRESHOLD_LEVEL})",
            1000, 1000, _chip_parameters(CLOCK_20KHZ, **noise), DEFAULT_THRESHOLD_LEVEL)
    if name == "spiketwo-40k":
        return SpikePreset(
            "spiketwo-40k", "SpikeTwo spike camera, 1000×1000 pixels, 40 kHz mode, "
            f"Q = {threshold_level_electrons(DEFAULT_THRESHOLD_LEVEL):,.0f} e⁻ (level {DEFAULT_THRESHOLD_LEVEL})",
            1000, 1000, _chip_parameters(CLOCK_40KHZ, **noise), DEFAULT_THRESHOLD_LEVEL)
    raise ViformError(f"spike preset = {name!r} is not allowed: choose one of {', '.join(SPIKE_PRESET_NAMES)} "
                      "or give a .json preset file")


#: Built-in spike presets (``load_spike_preset(name)``).
SPIKE_PRESET_NAMES = ("spikeone", "spiketwo", "spiketwo-40k")


def describe_spike_preset(name: str) -> str:
    return _builtin(name).description


# ---------------------------------------------------------------------- JSON
def _bad(where: str, value, allowed: str) -> ViformError:
    return ViformError(f"{where} = {value!r} is not allowed: {allowed}")


def _check_keys(where: str, d: dict, allowed) -> None:
    for key in d:
        if key not in allowed:
            raise ViformError(f"{where}: unknown key {key!r}; allowed keys: {', '.join(allowed)}")


def _number(where: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _bad(where, value, "it must be a finite number")
    return float(value)


def preset_from_dict(d, source: str = "preset") -> SpikePreset:
    """Validate a preset's JSON form and build the :class:`SpikePreset`.

    Every error names the offending key (as ``source: key``) and what is allowed.
    """
    if not isinstance(d, dict):
        raise ViformError(f"{source}: a spike preset must be a JSON object, got {type(d).__name__}")
    _check_keys(source, d, _TOP_KEYS)
    if d.get("format", PRESET_FORMAT) != PRESET_FORMAT:
        raise _bad(f"{source}: format", d.get("format"), f"it must be {PRESET_FORMAT!r}")
    if d.get("version", PRESET_VERSION) != PRESET_VERSION:
        raise _bad(f"{source}: version", d.get("version"), f"this viform reads version {PRESET_VERSION}")
    for key in ("height", "width", "sensor"):
        if key not in d:
            raise ViformError(f"{source}: missing key {key!r} (required: height, width, sensor)")
    height = check_int(f"{source}: height", d["height"], 1, 1 << 16)
    width = check_int(f"{source}: width", d["width"], 1, 1 << 16)
    name = d.get("name", Path(source).stem)
    description = d.get("description", "")
    for key, value in (("name", name), ("description", description)):
        if not isinstance(value, str):
            raise _bad(f"{source}: {key}", value, "it must be a string")
    calibration = d.get("calibration") or {}
    if not isinstance(calibration, dict):
        raise _bad(f"{source}: calibration", calibration, "it must be a JSON object")
    sensor = d["sensor"]
    if not isinstance(sensor, dict):
        raise _bad(f"{source}: sensor", sensor, "it must be a JSON object of spike-sensor parameters")
    fields = _sensor_fields()
    _check_keys(f"{source}: sensor", sensor, tuple(fields))
    kw = {}
    for key, value in sensor.items():
        where = f"{source}: sensor.{key}"
        if key == "optics":
            if not isinstance(value, dict):
                raise _bad(where, value, "it must be a JSON object with keys " + ", ".join(_OPTICS_KEYS))
            _check_keys(where, value, _OPTICS_KEYS)
            try:
                kw[key] = PixelOptics(**{k: _number(f"{where}.{k}", v) for k, v in value.items()})
            except ViformError as exc:
                raise ViformError(f"{where}: {exc}") from None
            continue
        default = fields[key].default
        if isinstance(default, bool):
            if not isinstance(value, bool):
                raise _bad(where, value, "it must be true or false")
        elif isinstance(default, str):
            if not isinstance(value, str):
                raise _bad(where, value, "it must be a string")
        elif isinstance(default, int) and not isinstance(default, bool):
            if isinstance(value, bool) or not isinstance(value, int):
                raise _bad(where, value, "it must be a whole number")
        elif isinstance(default, float):
            value = _number(where, value)
        kw[key] = value
    level = d.get("threshold_level")
    if level is not None:
        level = check_int(f"{source}: threshold_level", level, 0, N_THRESHOLD_LEVELS - 1)
        if "threshold_electrons" in sensor and sensor["threshold_electrons"] != threshold_level_electrons(level):
            raise ViformError(f"{source}: threshold_level = {level} gives {threshold_level_electrons(level):g} e⁻ "
                              f"but sensor.threshold_electrons = {sensor['threshold_electrons']!r}: give one of them")
        kw["threshold_electrons"] = threshold_level_electrons(level)
    try:
        params = SpikeSensorParameters(**kw)
    except ViformError as exc:
        raise ViformError(f"{source}: sensor.{exc}") from None
    return SpikePreset(name, description, height, width, params, level, calibration)


def load_spike_preset(spec: str | Path) -> SpikePreset:
    """A built-in preset by name (:data:`SPIKE_PRESET_NAMES`) or a ``.json`` preset file, validated.

    Parameters
    ----------
    spec : str or Path
        A built-in preset's name or the path of a preset ``.json`` (:func:`save_spike_preset`).

    Returns
    -------
    SpikePreset
        The preset; ``preset.sensor(...)`` builds its :class:`~viform.sensors.spike.SpikeSensor`.
    """
    text = str(spec)
    if text in SPIKE_PRESET_NAMES:
        return _builtin(text)
    path = Path(text)
    if path.suffix.lower() != ".json":
        raise _bad("spike preset", text, f"choose one of {', '.join(SPIKE_PRESET_NAMES)} or give a .json preset file")
    try:
        raw = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ViformError(f"spike preset {text!r} cannot be read: {exc.strerror or exc}") from None
    try:
        d = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise ViformError(f"spike preset {text!r} is not valid JSON: {exc.msg} at line {exc.lineno}") from None
    return preset_from_dict(d, text)


def save_spike_preset(path, preset: SpikePreset) -> Path:
    """Write ``preset`` as JSON (atomically); :func:`load_spike_preset` reads it back.

    Parameters
    ----------
    path : str or Path
        The ``.json`` file to write.
    preset : SpikePreset
        The preset to save.

    Returns
    -------
    Path
        The file written.
    """
    from viform._io import write_json

    path = Path(path)
    write_json(path, preset.to_dict())
    return path
