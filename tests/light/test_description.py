"""Scene descriptions: the schema refuses what it should, with one line naming the file and the key path."""

import json

import numpy as np
import pytest

from viform.light.catalog import SCENES, described_scene, load_scene
from viform.light.description import DescriptionError, load_description, parse_settings

MINIMAL = {"viform_scene": 1, "name": "t", "canvas": {"width_px": 32, "height_px": 24},
           "background": {"source": {"solid": {"lux": 5.0}}}}


def _with(**changes):
    doc = json.loads(json.dumps(MINIMAL))
    doc.update(changes)
    return doc


def _layer(**kw):
    layer = {"source": {"solid": {"lux": 50.0}}, "shape": {"rectangle": {"width_px": 6, "height_px": 4}},
             "position_px": [10, 10]}
    layer.update(kw)
    return layer


@pytest.mark.parametrize("doc,path,words", [
    (_with(layers=[_layer(), _layer(), _layer(motion={"keyframes": {"keys": [{"t_s": 0.0}, {"t_s": -1.0}]}})]),
     "layers[2].motion.keyframes.keys[1].t_s = -1.0", "≥ 0"),
    (_with(layers=[_layer(shap={})]), "layers[0].shap", "unknown key"),
    (_with(background={"source": {"solid": {"lux": -3}}}), "background.source.solid.lux = -3", "≥ 0"),
    (_with(background={"source": {"solid": {"lux": float("nan")}}}), "background.source.solid.lux = NaN",
     "finite"),
    (_with(canvas={"width_px": 100000, "height_px": 10000}), "canvas.width_px = 100000", "≤ 16384"),
    (_with(canvas={"width_px": 16000, "height_px": 16000}), "canvas = [16000, 16000]", "67,108,864"),
    (_with(layers=[_layer(source={"solid": {"lux": 1}, "pattern": {"name": "edge", "lux": [0, 1]}})]),
     "layers[0].source", "exactly one of"),
    (_with(layers=[_layer(source={"image": {"path": "missing.png"}})]),
     "layers[0].source.image.path = 'missing.png'", "no such image file"),
    (_with(layers=[_layer(motion={"keyframes": {"keys": [{"t_s": 0.0}, {"t_s": 0.0}]}})]),
     "layers[0].motion.keyframes.keys[1].t_s", "must increase"),
    (_with(layers=[_layer(depth_m=3.0), _layer()]), "layers[1].depth_m", "required"),
    (_with(viform_scene=2), "viform_scene = 2", "it must be 1"),
    (_with(layers=[_layer(source={"solid": {"lux": "$bright"}})]), "layers[0].source.solid.lux = '$bright'",
     "no parameter"),
])
def test_bad_descriptions_are_refused_with_the_key_path(tmp_path, doc, path, words):
    file = tmp_path / "scene.json"
    file.write_text(json.dumps(doc))
    with pytest.raises(DescriptionError) as err:
        load_description(file)
    message = str(err.value)
    assert message.startswith(f"{file}: {path}")
    assert words in message and "\n" not in message


def test_yaml_errors_and_non_mappings_name_the_file(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("canvas: [unclosed\n")
    with pytest.raises(DescriptionError, match="bad.yaml.*not valid YAML"):
        load_description(bad)
    bad.write_text("- a list\n")
    with pytest.raises(DescriptionError, match="must hold a mapping"):
        load_description(bad)


def test_parameters_substitute_and_settings_are_checked(tmp_path):
    doc = _with(parameters={"level": {"default": 2.0, "minimum": 0}},
                background={"source": {"solid": {"lux": "$level"}}})
    assert load_description(doc)["background"]["source"]["solid"]["lux"] == 2.0
    assert load_description(doc, {"level": 7})["background"]["source"]["solid"]["lux"] == 7.0
    with pytest.raises(DescriptionError, match=r"setting level=-1 is not allowed: it must lie in \[0, inf\]"):
        load_description(doc, {"level": -1})
    with pytest.raises(DescriptionError, match="setting levle=.*brightness, level, peak_lux, speed"):
        load_description(doc, {"levle": 1})


def test_image_paths_resolve_relative_to_the_description(tmp_path):
    import imageio.v3 as iio

    folder = tmp_path / "d"
    folder.mkdir()
    iio.imwrite(folder / "tex.png", (np.arange(64, dtype=np.uint8).reshape(8, 8) * 4))
    doc = _with(layers=[_layer(source={"image": {"path": "tex.png", "lux": [0.0, 100.0], "transfer": "linear"}},
                               shape=None)])
    del doc["layers"][0]["shape"]
    (folder / "s.yaml").write_text(json.dumps(doc))
    scene = load_scene(str(folder / "s.yaml"))
    assert scene.shape == (24, 32)
    lux = scene.illuminance_lux(0.0)
    assert lux.max() > 50 and np.isclose(lux[0, 0], 5.0)  # the image sits about (10, 10), the rest is background


def test_scene_set_parsing():
    assert parse_settings("brightness=300,speed=0.5") == {"brightness": 300, "speed": 0.5}
    assert parse_settings("velocity_px_per_s=[100,0],pattern=bars") == {"velocity_px_per_s": [100, 0],
                                                                       "pattern": "bars"}
    with pytest.raises(Exception, match="--scene-set"):
        parse_settings("brightness")
    with pytest.raises(Exception, match="finite"):
        parse_settings("speed=nan")


@pytest.mark.parametrize("name", [n for n, e in SCENES.items() if e.description])
def test_shipped_descriptions_validate_and_render(name):
    scene = described_scene(name)
    lux = scene.illuminance_lux(0.001)
    assert lux.shape == scene.shape and np.all(np.isfinite(lux)) and lux.min() >= 0


def test_docs_format_reference_is_the_schemas():
    from pathlib import Path

    from viform.light.description import schema_reference

    doc = (Path(__file__).parents[2] / "docs" / "scenes.md").read_text(encoding="utf-8")
    assert doc.endswith(schema_reference())
