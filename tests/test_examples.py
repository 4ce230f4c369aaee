"""The README's Python quick start and every script in examples/ run as a user would run them."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))


def _quickstart_code() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## Python quick start", 1)
    assert len(section) == 2, "README has no '## Python quick start' section"
    match = re.search(r"```python\n(.*?)```", section[1], re.S)
    assert match, "the quick-start section has no python code block"
    return match.group(1)


def test_readme_quickstart_runs_and_writes_its_figure(tmp_path):
    code = _quickstart_code()
    assert len([line for line in code.splitlines() if line.strip()]) <= 10, "the quick start promises ≤ 10 lines"
    run = subprocess.run([sys.executable, "-c", "import matplotlib; matplotlib.use('Agg')\n" + code],
                         cwd=tmp_path, capture_output=True, text=True, timeout=1800)
    assert run.returncode == 0, run.stderr
    assert (tmp_path / "quickstart.png").stat().st_size > 10_000


@pytest.mark.parametrize("script", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_runs(script, tmp_path):
    run = subprocess.run([sys.executable, str(script), str(tmp_path)], cwd=tmp_path, capture_output=True,
                         text=True, timeout=1800, env={**os.environ, "MPLBACKEND": "Agg"})
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip(), "an example prints what it found"
