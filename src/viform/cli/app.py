"""The root ``viform`` command group that every command module attaches to."""

import click


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="viform")
def cli():
    """viform: simulate and process next-generation image sensors.

    Data flows scene → sensor → output → processing → measurement. Run
    ``viform demo`` for the built-in default scene shot by the spike camera.
    """
