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
    "viform.cli.spike",  # simulate
    "viform.cli.reconstruct",  # reconstruct
    "viform.cli.files",  # info
    "viform.cli.demo",  # demo
    "viform.cli.frame",  # characterize
    "viform.cli.highspeed",  # highspeed
    "viform.cli.gated",  # gated
    "viform.cli.coding",  # encode, decode, dr
    "viform.cli.display",  # lightcomm, display
    "viform.cli.dataset",  # dataset
    "viform.cli.capture",  # capture
    "viform.cli.compare",  # compare
    "viform.cli.sweep",  # sweep
    "viform.cli.chip_figures",  # chip-figures
    "viform.cli.calibrate",  # calibrate
    "viform.cli.flow",  # flow
    "viform.cli.track",  # track
    "viform.cli.sensors",  # sensors: the sensor catalogue
    "viform.cli.scenes",  # scenes, scenes show
]


def _load_commands() -> None:
    from viform.cli._types import install

    for module in COMMAND_MODULES:
        importlib.import_module(module)
    install(cli)  # bounded numeric options and flag names in errors, for every command


class ExitStatus(Exception):  # noqa: N818 -- not an error: a status the command chose
    """Raised by a command that has printed its result and ends with exit status ``code``."""

    def __init__(self, code: int):
        super().__init__(code)
        self.code = int(code)


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is so that atomic writers clean up as for Ctrl-C."""


def _on_sigterm(signum, frame):
    from viform._io import raise_or_defer

    raise_or_defer(_Terminated())


def _on_sigint(signum, frame):
    from viform._io import raise_or_defer

    raise_or_defer(KeyboardInterrupt())


def wait_passively() -> None:
    """Let numba's OpenMP threads sleep between parallel kernels (``OMP_WAIT_POLICY=PASSIVE``) unless the
    user chose a policy; read when the OpenMP runtime loads, at the first parallel kernel.

    numba runs its parallel kernels on an OpenMP team (its "omp" threading layer, the default on Linux),
    whose threads by default spin after each parallel region before they sleep (300,000 polls in GNU
    libgomp): CPU taken, on a machine with few cores, from the threads that work meanwhile (the
    tracker's reader and association threads, a test run's other worker). Set by the command line and
    the test suite, which own their processes, not by importing the library: the same variable slows
    PyTorch's small operations in a process that also trains a network (15–40 % measured).
    """
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def _install_sigterm() -> None:
    """SIGTERM as Ctrl-C; both held while a library call that must not be cut runs (_io.interrupts_deferred),
    numba's compiles included (_io.defer_interrupts_in_compiles)."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        from viform._io import defer_interrupts_in_compiles

        signal.signal(signal.SIGTERM, _on_sigterm)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, _on_sigint)
        defer_interrupts_in_compiles()


def _first_line(exc: BaseException) -> str:
    lines = [line for line in str(exc).splitlines() if line.strip()]
    return lines[0] if lines else type(exc).__name__


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Every warning as one line on stderr (:func:`viform._validate.warning_line`)."""
    from viform._validate import warning_line

    click.echo(warning_line(message, category), err=True)


def _interrupted(exc: BaseException) -> int:
    """The line an interrupted command prints: what it kept (complete files), never a partial one."""
    from viform._io import completed_outputs

    kept = completed_outputs()
    if not kept:
        click.echo("viform: interrupted; no output was left (the file being written was removed)", err=True)
    else:
        names = ", ".join(str(p) for p in kept[:3]) + (f" and {len(kept) - 3} more" if len(kept) > 3 else "")
        click.echo(f"viform: interrupted; kept {len(kept)} complete file(s) written before it: {names} (the file "
                   "being written was removed)", err=True)
    terminated = isinstance(exc, _Terminated) or isinstance(exc.__cause__, _Terminated)
    return 143 if terminated else 130


def main(argv=None) -> int:
    """Entry point: bad input prints one line on stderr and exits 2; no traceback.

    SIGTERM is handled as Ctrl-C (temporary outputs removed; exit 143). Warnings (viform's and
    the libraries') are printed one line each.
    """
    import warnings

    from viform._io import begin_outputs

    wait_passively()
    _install_sigterm()
    begin_outputs()
    with warnings.catch_warnings():
        # a filter added here also clears the "already shown" records of earlier runs in this process
        warnings.filterwarnings("default", category=UserWarning)
        warnings.showwarning = _show_warning
        return _main(argv)


def _main(argv) -> int:
    try:
        _load_commands()
    except KeyboardInterrupt as exc:
        click.echo("viform: interrupted", err=True)
        return 143 if isinstance(exc, _Terminated) else 130
    try:
        cli.main(args=argv, prog_name="viform", standalone_mode=False)
    except ExitStatus as exc:  # a command's own status after its output (verify's 3)
        return exc.code
    except click.exceptions.Exit as exc:
        return exc.exit_code
    except click.ClickException as exc:
        click.echo(f"viform: error: {exc.format_message()}", err=True)
        return exc.exit_code if exc.exit_code else 2
    except click.Abort as exc:  # click turns Ctrl-C (and our SIGTERM) into Abort
        return _interrupted(exc)
    except KeyboardInterrupt as exc:
        return _interrupted(exc)
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
