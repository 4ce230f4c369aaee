"""Light: radiometry (lux → photons → electrons) and scenes (light per pixel over time).

A :class:`Scene` gives the illuminance on each pixel (lux) at any time and, where it knows it, the
exact truth behind it (motion, optical flow, objects, depth: :class:`ObjectTruth`, :class:`FlowTruth`,
:class:`TruthUnavailable`). The catalogue (:data:`SCENES`, :func:`builtin_scene`, :func:`load_scene`)
names the built-in and described scenes every command takes; the scene classes build one by hand
(:class:`StillScene` from an image, :class:`VideoScene` from frames, :class:`TranslatingScene`,
:class:`DilemmaScene` ...). Active imaging (a pulsed laser through fog) is :class:`ActiveScene`.

The names are imported on first use (:mod:`viform._lazy`): ``import viform.light`` costs nothing.
"""

from viform import _lazy

__all__ = [
    "Scene", "StillScene", "VideoScene", "TranslatingScene", "RotatingScene", "HDRScene", "StepScene",
    "FlickerScene", "image_to_lux",
    "SCENES", "builtin_scene", "load_scene", "described_scene", "scene_from_description",
    "load_description", "DescriptionError", "DescribedScene",
    "DilemmaScene", "NightRoadFogScene", "MultiObjectScene", "WavingHandScene",
    "ObjectTruth", "FlowTruth", "TruthUnavailable",
    "ActiveScene", "Medium", "field_test_scene", "fog_scene", "depth_scene", "PulsedLaser", "Receiver",
    "PixelOptics", "lux_to_photons_per_s", "photon_energy_j",
]

__getattr__, __dir__ = _lazy.attach(__name__, __all__, {
    "scenes": ["Scene", "StillScene", "VideoScene", "TranslatingScene", "RotatingScene", "HDRScene", "StepScene",
               "FlickerScene", "image_to_lux"],
    "catalog": ["SCENES", "builtin_scene", "load_scene", "described_scene", "scene_from_description"],
    "description": ["load_description", "DescriptionError"],
    "layered": ["DescribedScene"],
    "dilemma": ["DilemmaScene", "NightRoadFogScene"],
    "multi_object": ["MultiObjectScene"],
    "articulated": ["WavingHandScene"],
    "truth": ["ObjectTruth", "FlowTruth", "TruthUnavailable"],
    "active": ["ActiveScene", "Medium", "field_test_scene", "fog_scene", "depth_scene"],
    "laser": ["PulsedLaser", "Receiver"],
    "radiometry": ["PixelOptics", "lux_to_photons_per_s", "photon_energy_j"],
})
