"""The root ``viform`` command group that every command module attaches to."""

import click


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="viform")
def cli():
    """viform: simulate and process next-generation image sensors.

    Data flows scene → sensor → output → processing → measurement. Start with
    'viform demo': one scene with fast motion, flicker and six decades of light,
    shot by every sensor (spike camera, CMOS, segmented exposure, overflow pixel,
    high-speed camera), compared in viform-demo/report.html.

    Every command takes --help, --json (JSON on stdout) and --json-file PATH.
    """
