"""Whether a sensor could see an object at an instant: the physics beside the tracker's score.

A tracker that misses an object its sensor never recorded is not at fault; one that misses an
object its sensor recorded plainly is. Each truth row therefore carries a *detectability*: the
evidence the sensor's pixels hold about the object at that instant, in units of the least a
pixel can show, so that 1 is the bound.

* **Spike sensors** (seed 000 §3.3: a spike per Q electrons): the charge the object adds to
  (or takes from) a pixel it covers, η·|E_object − E_background|·τ, against the threshold Q,
  where τ is the time the pixel has been under the object: its dwell (the object's extent
  along its motion over its speed) or, for an object still on its first pixels, the time since
  it came into view (since the stream started, for objects in view then). Under one Q the pixel
  fires at most one spike more or fewer than it would without the object: no estimator can see
  it there.
* **Frame sensors**: the contrast of one exposure against its noise, η·|ΔE|·min(τ, t_exp)
  electrons (each capped at the full well) over √(shot noise of the background + read noise²).
  Under 1 the object's difference is within one standard deviation of a single pixel's noise.

An entirely hidden object has detectability 0. Scenes that do not give the object's and the
background's illuminance (:class:`~viform.light.truth.ObjectTruth` ``lux``) give NaN: unknown.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from viform._validate import check_non_negative, check_positive

#: Detectability at and above which the sensor's pixels show the object (see the module notes).
DETECTABLE = 1.0


def dwell_s(obj) -> float:
    """Time a point of the image stays under the object (its extent along its motion over its speed), s."""
    vx, vy = obj.velocity_px_per_s
    times = [extent / abs(v) for extent, v in ((obj.width_px, vx), (obj.height_px, vy)) if v]
    return min(times) if times else math.inf


@dataclass(frozen=True)
class SpikeDetectability:
    """Charge an object delivers to (or withholds from) a pixel it covers, in thresholds Q.

    Parameters
    ----------
    threshold_electrons : float
        The spike threshold Q, e⁻.
    electrons_per_lux_second : float
        Photo-electrons a pixel collects per lux and second (the optics' η).
    """

    threshold_electrons: float
    electrons_per_lux_second: float

    def __post_init__(self):
        check_positive("threshold_electrons", self.threshold_electrons)
        check_positive("electrons_per_lux_second", self.electrons_per_lux_second)

    def __call__(self, obj, seen_s: float) -> float:
        """Detectability of ``obj`` (an :class:`~viform.light.truth.ObjectTruth`) in view for ``seen_s`` s."""
        if obj.lux is None or obj.background_lux is None:
            return math.nan
        if obj.visible_fraction <= 0:
            return 0.0
        exposure = min(dwell_s(obj), max(float(seen_s), 0.0))
        charge = self.electrons_per_lux_second * abs(obj.lux - obj.background_lux) * exposure
        return charge / self.threshold_electrons


@dataclass(frozen=True)
class FrameDetectability:
    """Contrast of an object in one exposure against the pixel's noise.

    Parameters
    ----------
    electrons_per_lux_second : float
        Photo-electrons per lux and second.
    exposure_s : float
        Exposure of a frame, s.
    read_noise_electrons : float
        Read noise, e⁻ rms.
    full_well_electrons : float or None
        Charge at which the pixel saturates (None: no limit).
    """

    electrons_per_lux_second: float
    exposure_s: float
    read_noise_electrons: float = 0.0
    full_well_electrons: float | None = None

    def __post_init__(self):
        check_positive("electrons_per_lux_second", self.electrons_per_lux_second)
        check_positive("exposure_s", self.exposure_s)
        check_non_negative("read_noise_electrons", self.read_noise_electrons)

    def __call__(self, obj, seen_s: float = math.inf) -> float:
        if obj.lux is None or obj.background_lux is None:
            return math.nan
        if obj.visible_fraction <= 0:
            return 0.0
        eta, t = self.electrons_per_lux_second, self.exposure_s
        on = min(dwell_s(obj), t)  # the part of the exposure the object covers the pixel (blur beyond)
        background = eta * obj.background_lux * t
        with_object = eta * (obj.lux * on + obj.background_lux * (t - on))
        if self.full_well_electrons is not None:
            background = min(background, self.full_well_electrons)
            with_object = min(with_object, self.full_well_electrons)
        noise = math.sqrt(background + self.read_noise_electrons ** 2)
        return abs(with_object - background) / noise if noise > 0 else math.inf


def spike_detectability_of(source) -> SpikeDetectability | None:
    """The detectability of a spike stream's sensor, from its threshold and recorded optics (None if unknown).

    Simulated streams record both (the sidecar of a file, the metadata of a stream in memory);
    recordings of a real chip state neither, and get None.
    """
    from viform.light.radiometry import PixelOptics

    q = getattr(source, "threshold_electrons", None)
    optics = ((getattr(source, "metadata", None) or {}).get("sensor") or {}).get("optics")
    if not q or not isinstance(optics, dict):
        return None
    try:
        eta = PixelOptics(**optics).electrons_per_lux_second
    except (TypeError, ValueError):
        return None
    return SpikeDetectability(float(q), float(eta))
