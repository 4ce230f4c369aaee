"""The four example descriptions in examples/scenes/ run from the command line, with truth."""

from pathlib import Path

import pytest

from viform.cli import main

EXAMPLES = sorted((Path(__file__).parents[2] / "examples" / "scenes").glob("*.yaml"))


def test_the_four_examples_are_there():
    assert {p.stem for p in EXAMPLES} == {"tunnel-exit", "headlamp-night", "conveyor", "natural-pan"}


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_example_simulates_with_truth(path, tmp_path, capsys):
    code = main(["simulate", str(path), "--duration", "0.001", "--height", "50", "--width", "80", "--out",
                 str(tmp_path / "s.dat"), "--truth", str(tmp_path / "truth"), "--truth-every-ticks", "20",
                 "--threshold-electrons", "2000"])
    assert code in (0, None), capsys.readouterr().err
    truth = tmp_path / "truth"
    assert any((truth / "flow").glob("*.flo")) and any((truth / "depth").glob("*"))
    assert (truth / "mot" / "s" / "gt" / "gt.txt").read_text().strip()
    assert (tmp_path / "s.dat").stat().st_size > 0


def test_figures_script_writes_one_figure_per_example(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("scene_figures", EXAMPLES[0].parent / "figures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    written = module.figure(EXAMPLES[0], tmp_path)
    assert written.is_file() and written.stat().st_size > 10_000
