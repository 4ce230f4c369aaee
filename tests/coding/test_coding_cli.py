"""``viform encode`` / ``decode`` / ``dr`` command lines: JSON convention, bad input, notices."""

import json
import subprocess
import sys

import numpy as np
import pytest

from viform.cli import main
from viform.stream.container import SpikeStream
from viform.stream.io import open_spikes, save_spikes


@pytest.fixture()
def stream_file(tmp_path):
    rng = np.random.default_rng(3)
    spikes = rng.random((40, 6, 8)) < 0.2
    return save_spikes(tmp_path / "s.npz", SpikeStream(spikes, 40_000.0, 100.0)), spikes


def test_encode_decode_json_and_json_file(tmp_path, stream_file, capsys):
    src, spikes = stream_file
    vfc, out = tmp_path / "s.vfc", tmp_path / "back.npz"
    assert main(["encode", str(src), str(vfc), "--json", "--json-file", str(tmp_path / "e.json")]) == 0
    text = capsys.readouterr().out
    summary = json.loads(text)
    assert json.loads((tmp_path / "e.json").read_text()) == summary
    assert summary["spikes"] == int(spikes.sum())
    assert main(["decode", str(vfc), str(out), "--json", "--json-file", str(tmp_path / "d.json")]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert json.loads((tmp_path / "d.json").read_text()) == summary
    assert (summary["n_ticks"], summary["height"], summary["width"]) == spikes.shape
    back = open_spikes(out)
    assert np.array_equal(back.read_ticks(0, back.n_ticks), spikes)
    # the human line: thousands separators, no JSON
    assert main(["decode", str(vfc), str(out)]) == 0
    assert capsys.readouterr().out.startswith(f"{out}: 40 ticks × 8×6 pixels")


@pytest.mark.parametrize("value", ["0", "-5"])
def test_segment_ticks_must_be_positive(tmp_path, stream_file, capsys, value):
    src, _ = stream_file
    vfc = tmp_path / "s.vfc"
    assert main(["encode", str(src), str(vfc), "--segment-ticks", value]) == 2
    err = capsys.readouterr().err
    assert "--segment-ticks" in err and value in err and err.count("\n") == 1
    assert not vfc.exists()


@pytest.mark.parametrize("mode", ["statistical", "intensity"])
@pytest.mark.parametrize("flag, value", [("--threshold", "0"), ("--threshold", "-5"), ("--threshold", "inf"),
                                         ("--threshold", "1e308"), ("--k", "-1"), ("--k", "nan"), ("--slack", "-2")])
def test_tolerance_options_are_bounded(tmp_path, stream_file, capsys, mode, flag, value):
    """--threshold 0 once divided by zero and -5 gave "math domain error": one line naming the flag, exit 2."""
    src, _ = stream_file
    vfc = tmp_path / "s.vfc"
    assert main(["encode", str(src), str(vfc), "--mode", mode, flag, value]) == 2
    err = capsys.readouterr().err
    assert flag in err and "allowed" in err and err.count("\n") == 1
    assert not vfc.exists()


@pytest.mark.parametrize("command", ["encode", "decode", "dr"])
def test_json_file_under_a_file_is_refused(tmp_path, stream_file, capsys, command):
    """A --json-file that cannot be made (under a regular file) is refused before any work, by name."""
    src, _ = stream_file
    vfc = tmp_path / "s.vfc"
    assert main(["encode", str(src), str(vfc)]) == 0
    capsys.readouterr()
    args = {"encode": ["encode", str(src), str(tmp_path / "t.vfc")],
            "decode": ["decode", str(vfc), str(tmp_path / "t.npz")], "dr": ["dr"]}[command]
    blocker = tmp_path / "no"
    blocker.write_text("x")
    assert main(args + ["--json-file", str(blocker / "such" / "x.json")]) == 2
    err = capsys.readouterr().err
    assert "--json-file" in err and err.count("\n") == 1
    assert blocker.is_file()
    assert not (tmp_path / "t.vfc").exists() and not (tmp_path / "t.npz").exists()


def test_dr_console_speaks_plainly_and_json_keys_stay(tmp_path, capsys):
    assert main(["dr"]) == 0
    text = capsys.readouterr().out
    assert "§" not in text and "τ" not in text and "shortest interval" in text and "longest interval" in text
    assert main(["dr", "--json", "--json-file", str(tmp_path / "dr.json")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert json.loads((tmp_path / "dr.json").read_text()) == out
    assert [sorted(ex) for ex in out["seed_examples"]][0] == ["computed_db", "example", "seed_db"]


def test_help_says_spike_stream(capsys):
    try:
        code = main(["encode", "--help"])
    except SystemExit as exit_:
        code = exit_.code
    assert code == 0
    text = capsys.readouterr().out
    assert "spike stream SRC" in text and "viform SRC" not in text


def test_compile_notice_is_said_once_and_only_for_a_coding_compile(monkeypatch):
    """The notice is tied to numba's compile event of a coding kernel (a cache load fires none): once per
    process, never for another package's kernel."""
    from numba.core import event

    from viform.coding import _compile_cache, interval_model
    from viform.sensors import _spike_kernels

    monkeypatch.setattr(_compile_cache, "_ANNOUNCED", False)
    said = []
    _compile_cache.announce_compiles(lambda: said.append(1))
    other = next(v for v in vars(_spike_kernels).values() if hasattr(v, "py_func") and hasattr(v, "stats"))
    with event.trigger_event("numba:compile", data={"dispatcher": other}):
        pass
    assert said == []
    for _ in range(2):
        with event.trigger_event("numba:compile", data={"dispatcher": interval_model.encode_segment}):
            pass
    assert said == [1]


_RUN_TWICE = """
import json, sys
from viform.cli import main
from viform.coding._compile_cache import coding_dispatchers
src, vfc, back = sys.argv[1:4]
assert main(["encode", src, vfc]) == 0
assert main(["encode", src, vfc + ".lossy.vfc", "--mode", "statistical"]) == 0
assert main(["decode", vfc, back]) == 0
assert main(["decode", vfc + ".lossy.vfc", back]) == 0
stats = [d.stats for d in coding_dispatchers()]
print(json.dumps({"misses": sum(sum(s.cache_misses.values()) for s in stats),
                  "hits": sum(sum(s.cache_hits.values()) for s in stats)}))
"""


def test_second_process_loads_the_kernels_from_the_cache(tmp_path, stream_file):
    """Encode and decode (strict and lossy) in one process, then again in a second: the second compiles
    nothing (numba's cache hit count, not a timing) and prints no compile notice."""
    src, _ = stream_file
    runs = []
    for k in range(2):
        args = [str(src), str(tmp_path / f"s{k}.vfc"), str(tmp_path / f"b{k}.npz")]
        done = subprocess.run([sys.executable, "-c", _RUN_TWICE, *args], capture_output=True, text=True,
                              check=True)
        runs.append((json.loads(done.stdout.strip().splitlines()[-1]), done.stderr))
    (_, _), (second, err) = runs
    assert second["misses"] == 0 and second["hits"] > 0, second
    assert "compiling the coding kernels" not in err


def test_kernels_are_stamped_by_every_coding_source(tmp_path):
    """The coding kernels inline code of other modules (the range coder): their cache entries carry a
    stamp of every source file of the package that defines kernels, so an edit of any one of them makes
    every entry stale (and an edit of a file without kernels none)."""
    from viform.coding import _compile_cache, interval_model

    locator = interval_model.encode_segment._cache._impl.locator
    assert locator.get_source_stamp() == ("viform.coding", _compile_cache.sources_stamp())
    for name in ("a.py", "b.py"):
        (tmp_path / name).write_text("from numba import njit\nx = 1\n")
    (tmp_path / "c.py").write_text("y = 1\n")
    before = _compile_cache.sources_stamp(tmp_path)
    (tmp_path / "c.py").write_text("y = 2\n")  # no kernel in it: nothing compiled depends on it
    assert _compile_cache.sources_stamp(tmp_path) == before
    (tmp_path / "b.py").write_text("from numba import njit\nx = 2\n")
    assert _compile_cache.sources_stamp(tmp_path) != before


def test_segment_ticks_too_large_for_the_sensor_is_refused_by_flag(tmp_path, capsys):
    """A strict segment is held in memory while it is coded: --segment-ticks beyond 2^28 pixel-ticks is refused."""
    src = tmp_path / "wide.npz"
    save_spikes(src, SpikeStream(np.zeros((2, 1024, 1024), bool), 20_000.0))
    assert main(["encode", str(src), str(tmp_path / "w.vfc"), "--segment-ticks", "300"]) == 2
    err = capsys.readouterr().err
    assert "--segment-ticks = 300" in err and "at most 256 ticks" in err and err.count("\n") == 1
    assert not (tmp_path / "w.vfc").exists()
    assert main(["encode", str(src), str(tmp_path / "w.vfc"), "--segment-ticks", "256"]) == 0
