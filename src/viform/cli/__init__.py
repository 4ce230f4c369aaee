"""Command-line interface: ``viform COMMAND``.

Each processing family registers its commands in its own module under ``viform.cli``
(listed in :data:`COMMAND_MODULES`) on the shared :data:`viform.cli.app.cli` group.
"""

from __future__ import annotations

import importlib
import os
import sys

import click

from viform._validate import ViformError
from viform.cli.app import cli

#: Modules that add commands to :data:`cli` (imported on start).
COMMAND_MODULES = [
    "viform.cli.spike",  # simulate (issue 2)
    "viform.cli.reconstruct",  # reconstruct (issue 2)
    "viform.cli.files",  # info (issue 2)
    "viform.cli.demo",  # demo (issue 2)
    "viform.cli.frame",  # characterize (issue 3)
    "viform.cli.highspeed",  # highspeed (issue 4)
    "viform.cli.gated",  # gated (issue 5)
    "viform.cli.coding",  # encode, decode, dr (issue 6)
    "viform.cli.display",  # lightcomm, display (issue 7)
    "viform.cli.dataset",  # dataset (issue 14)
    "viform.cli.capture",  # capture (issue 12)
    "viform.cli.compare",  # compare (issue 12)
    "viform.cli.sweep",  # sweep (issue 23)
    "viform.cli.chip_figures",  # chip-figures (issue 16)
    "viform.cli.calibrate",  # calibrate (issue 10)
    "viform.cli.flow",  # flow (issue 21)
    "viform.cli.track",  # track (issue 22)
    "viform.cli.scenes",  # scenes, scenes show (issue 35)
]


def _load_commands() -> None:
    from viform.cli._types import install

    for module in COMMAND_MODULES:
        importlib.import_module(module)
    install(cli)  # bounded numeric options and flag names in errors, for every command


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is so that atomic writers clean up as for Ctrl-C."""


def _on_sigterm(signum, frame):
    from viform._io import raise_or_defer

    raise_or_defer(_Terminated())


def _on_sigint(signum, frame):
    from viform._io import raise_or_defer

    raise_or_defer(KeyboardInterrupt())


def _install_sigterm() -> None:
    """SIGTERM as Ctrl-C; both held while a library call that must not be cut runs (_io.interrupts_deferred)."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _on_sigterm)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, _on_sigint)


def _first_line(exc: BaseException) -> str:
    lines = [line for line in str(exc).splitlines() if line.strip()]
    return lines[0] if lines else type(exc).__name__


def main(argv=None) -> int:
    """Entry point: bad input prints one line on stderr and exits 2; no traceback.

    SIGTERM is handled as Ctrl-C (temporary outputs removed; exit 143).
    """
    _install_sigterm()
    try:
        _load_commands()
    except KeyboardInterrupt as exc:
        click.echo("viform: interrupted", err=True)
        return 143 if isinstance(exc, _Terminated) else 130
    try:
        cli.main(args=argv, prog_name="viform", standalone_mode=False)
    except click.exceptions.Exit as exc:
        return exc.exit_code
    except click.ClickException as exc:
        click.echo(f"viform: error: {exc.format_message()}", err=True)
        return exc.exit_code if exc.exit_code else 2
    except click.Abort as exc:  # click turns Ctrl-C (and our SIGTERM) into Abort
        click.echo("viform: interrupted; no partial output was left", err=True)
        return 143 if isinstance(exc.__cause__, _Terminated) else 130
    except KeyboardInterrupt as exc:
        click.echo("viform: interrupted; no partial output was left", err=True)
        return 143 if isinstance(exc, _Terminated) else 130
    except MemoryError:
        if os.environ.get("VIFORM_DEBUG"):
            raise
        click.echo("viform: error: not enough memory for this request; reduce its size (--duration, --height, "
                   "--width, --frames) or run it on a bigger machine", err=True)
        return 2
    except (ViformError, ValueError, OSError) as exc:
        if os.environ.get("VIFORM_DEBUG"):
            raise
        click.echo(f"viform: error: {_first_line(exc)}", err=True)
        return 2
    except Exception as exc:  # last resort: still one line, exit non-zero
        if os.environ.get("VIFORM_DEBUG"):
            raise
        click.echo(f"viform: internal error ({type(exc).__name__}): {_first_line(exc)}; "
                   "set VIFORM_DEBUG=1 for the traceback", err=True)
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
