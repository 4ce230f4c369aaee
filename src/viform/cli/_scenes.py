"""What every command that takes a SCENE shares: the scene list for help texts, and ``--scene-set``.

Help texts list the scenes from the catalogue (:data:`viform.light.catalog.SCENES`), so a new scene
appears in every command's help; ``--scene-set NAME=VALUE,...`` sets any parameter of a built-in
scene or a scene description, and the ``brightness``, ``peak_lux`` and ``speed`` every scene takes.
"""

from __future__ import annotations

import click

SCENE_SET_HELP = ("Scene settings NAME=VALUE,...: any parameter of the scene (viform scenes lists them), and "
                  "brightness (factor on its light), peak_lux (its brightest level, lux) or speed (factor on its "
                  "motion), e.g. --scene-set brightness=20,speed=0.5.")


def scene_names() -> list[str]:
    from viform.light.catalog import SCENES

    return list(SCENES)


def scene_list(prefix: str = "Built-in scenes: ") -> str:
    """One sentence naming every catalogue scene and the other kinds of SCENE."""
    return (prefix + ", ".join(scene_names()) + "; or a scene description (.yaml, .yml, .json: viform scenes "
            "show NAME prints one to start from), an image, a video or a folder of images.")


def with_scene_list(f):
    """Fill ``{scenes}`` in a command's docstring with :func:`scene_list` (apply below ``@cli.command``'s
    options, next to the function)."""
    if f.__doc__ and "{scenes}" in f.__doc__:
        f.__doc__ = f.__doc__.replace("{scenes}", scene_list())
    return f


def built_in_scene_options(f):
    """The options compare and sweep share to make a built-in scene: its size in pixels and the
    named settings of the dilemma and night-road-fog scenes."""
    options = [
        click.option("--height", type=int, default=64, show_default=True, help="Resolution of built-in scenes."),
        click.option("--width", type=int, default=128, show_default=True),
        click.option("--brightness", type=float, default=None,
                     help="Factor on the light of the dilemma and night-road-fog scenes."),
        click.option("--speed", type=float, default=None, help="Factor on the dilemma scene's speeds."),
        click.option("--visibility-m", type=float, default=None, help="Fog visibility of night-road-fog, m."),
    ]
    for option in reversed(options):
        f = option(f)
    return f


def scene_set_option(f):
    """The ``--scene-set`` option (value: the raw text; parse it with :func:`scene_settings`)."""
    return click.option("--scene-set", "scene_set", default=None, metavar="NAME=VALUE,...", help=SCENE_SET_HELP)(f)


def scene_settings(text: str | None) -> dict:
    """``--scene-set``'s text as a mapping (errors name the flag)."""
    from viform.light.description import parse_settings

    return parse_settings(text, "--scene-set")


def scene_options(scene: str, text: str | None) -> dict:
    """``--scene-set`` for SCENE as the keyword arguments of a built-in scene, or the settings of a
    scene description; refused for an image or video (errors name the flag)."""
    from viform._validate import ViformError
    from viform.light.catalog import BUILTIN_SCENES, entry_settings
    from viform.light.description import is_description_file, load_description

    settings = scene_settings(text)
    if not settings:
        return {}
    if scene in BUILTIN_SCENES:
        return entry_settings(scene, settings, "--scene-set")
    if is_description_file(scene):
        try:
            load_description(scene, settings)  # checks the names and values before any work
        except ViformError as exc:
            raise ViformError(f"--scene-set: {exc}") from None
        return settings
    raise ViformError(f"--scene-set applies to built-in scenes and scene descriptions, not to SCENE = {scene!r} "
                      "(an image or video)")
