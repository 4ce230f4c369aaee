"""No command prints a library warning raw (issue 39.6): each warning is one line, without the
source line or file path Python's default display adds, and the causes found are fixed."""

from __future__ import annotations

import io
import warnings
from contextlib import redirect_stderr, redirect_stdout

import numpy as np

from viform.cli import main
from viform.stream.container import SpikeStream
from viform.stream.io import save_spikes


def run(args):
    err, out = io.StringIO(), io.StringIO()
    with redirect_stderr(err), redirect_stdout(out):
        rc = main([str(a) for a in args])
    return rc, out.getvalue(), err.getvalue()


def test_library_warnings_are_one_line_each_and_shown_in_every_run(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import viform.cli.files as files_cli

    path = save_spikes(tmp_path / "s.dat", SpikeStream(np.ones((8, 8, 16), bool), 40_000.0, 60.0))
    real_table = files_cli._table

    def noisy_table(summary):
        np.log(np.zeros(2))  # numpy: RuntimeWarning "divide by zero encountered in log"
        fig, ax = plt.subplots()
        ax.legend()  # matplotlib: "No artists with labels found to put in legend"
        plt.close(fig)
        warnings.warn("a library's own words\nwith a second line", UserWarning, stacklevel=1)
        real_table(summary)

    monkeypatch.setattr(files_cli, "_table", noisy_table)
    for _ in range(2):  # Python shows a warning once per place: every run of a command shows it again
        rc, out, err = run(["info", path])
        lines = [line for line in err.splitlines() if line.strip()]
        assert rc == 0 and len(lines) == 3, err
        assert all(line.startswith("viform: warning: ") for line in lines), err
        assert ".py" not in err and "np.log" not in err and "ax.legend" not in err, err  # no file, no source line
        assert "divide by zero encountered in log (RuntimeWarning)" in lines[0]
        assert "No artists with labels found to put in legend" in lines[1] and "from matplotlib" in lines[1]
        assert lines[2] == "viform: warning: a library's own words (UserWarning)"


def test_gated_plot_of_a_fog_that_hides_everything_warns_nothing(tmp_path):
    """``viform gated --fog-visibility-m 1e-300``: no surface signal at all set a log axis to 0."""
    from viform.report.gated_plots import plot_range_intensity

    r = np.linspace(0.0, 900.0, 50)
    profile = {"range_m": r, "surface_ungated": np.zeros_like(r), "surface_gated": np.zeros_like(r),
               "backscatter_ungated_per_m": np.zeros_like(r), "backscatter_gated_per_m": np.zeros_like(r),
               "gate_window_m": (130.0, 470.0)}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plot_range_intensity(tmp_path / "r.png", profile, "fog V = 1e-300 m")
    assert [str(w.message) for w in caught] == []
    assert (tmp_path / "r.png").stat().st_size > 0


def test_warnings_in_tasks_on_workers_are_one_line_too():
    """A dask task (dataset's clips, sweep's points) runs wrapped: its worker shows warnings as the command does."""
    import subprocess
    import sys

    code = ("import numpy as np; from viform._parallel import one_line_warnings; "
            "print(one_line_warnings(np.log)(np.zeros(1))[0])")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0 and proc.stdout.strip() == "-inf"
    assert proc.stderr.splitlines() == ["viform: warning: divide by zero encountered in log (RuntimeWarning)"]
