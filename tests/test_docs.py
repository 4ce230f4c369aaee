"""Every code block of the README and docs/ runs as written, as a user would paste it.

Each fenced block carries its language:

* ``python`` and ``bash`` blocks run, each document's blocks in order in one fresh folder (so a later
  block may use the files an earlier one made), with the project's ``viform`` and ``python`` first on
  PATH and matplotlib drawing off screen. A block that reads ``../shared/`` (the shared real
  recordings, outside the repository) is skipped where that folder is absent, one that imports torch
  where the optional extra is not installed; the test says which.
* ``text`` blocks are output, file layouts and usage synopses: they are not run, so a ``viform`` or
  ``python`` line in one must be a synopsis (placeholders in capitals or ``[options]``), or the block
  is tagged ``text long-run`` (a benchmark or a sweep that takes minutes: not run by the tests).
* ``json``, ``yaml`` and ``ini`` blocks are data, parsed to check they are well formed (``…`` marks
  an elided part and is allowed in json).

The README's set-up block (the two commands) is proven by ``.ci/run``, each in a fresh environment.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ["VIFORM_SPIKE_DATA"]).parents[1] if os.environ.get("VIFORM_SPIKE_DATA") \
    else ROOT.parent / "shared"
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
RUN = {"python", "bash"}
DATA = {"json", "yaml", "ini"}
LANGUAGES = RUN | DATA | {"text"}
FENCE = re.compile(r"^```(.*)$")


def blocks(path: Path) -> list[tuple[int, str, str]]:
    """(line number, info string, code) of every fenced block of one Markdown file."""
    out, info, start, lines = [], None, 0, []
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        match = FENCE.match(line)
        if match and info is None:
            info, start, lines = match.group(1).strip(), number, []
        elif line.startswith("```") and info is not None:
            out.append((start, info, "\n".join(lines) + "\n"))
            info = None
        elif info is not None:
            lines.append(line)
    assert info is None, f"{path.name}: the block opened at line {start} is never closed"
    return out


def _setup_block(path: Path, start: int) -> bool:
    return path.name == "README.md" and start == blocks(path)[0][0]


def _is_synopsis(line: str) -> bool:
    return "[" in line or re.search(r"\b[A-Z][A-Z_]{1,}\b(?![=])", line.split("#")[0]) is not None


@pytest.mark.parametrize("path", DOCS, ids=[p.name for p in DOCS])
def test_every_block_says_what_it_is(path):
    for start, info, code in blocks(path):
        language = info.split()[0] if info else ""
        where = f"{path.name}:{start}"
        assert language in LANGUAGES, f"{where}: a code block needs a language, one of {sorted(LANGUAGES)}"
        if language == "text" and "long-run" not in info.split():
            commands = [line for line in code.splitlines() if re.match(r"\s*(viform|python|PYTHONPATH=\S+ python) ",
                                                                      line)]
            loose = [line for line in commands if not _is_synopsis(line)]
            assert not loose, f"{where}: a text block holds runnable commands {loose[:2]}: make it a bash block " \
                              "(it then runs in the tests) or a synopsis"
        if language == "json":
            json.loads(code.replace('"…": "…"', '"elided": 0').replace('"…"', '"elided"'))
        if language == "yaml":
            import yaml

            yaml.safe_load(code)


def _runnable(path: Path):
    return [(start, info.split()[0], code) for start, info, code in blocks(path)
            if info and info.split()[0] in RUN and not _setup_block(path, start)]


RUNNABLE = [p for p in DOCS if _runnable(p)]


@pytest.mark.parametrize("path", RUNNABLE, ids=[p.name for p in RUNNABLE])
def test_code_blocks_run(path, tmp_path):
    work = tmp_path / "work"
    work.mkdir()
    have_shared = SHARED.is_dir()
    if have_shared:
        (tmp_path / "shared").symlink_to(SHARED)
    bin_dir = Path(sys.executable).parent
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}", "MPLBACKEND": "Agg",
           "PYTHONPATH": str(ROOT / "src")}
    env.pop("VIFORM_DEBUG", None)
    skipped = []
    for start, language, code in _runnable(path):
        where = f"{path.name}:{start}"
        if "../shared/" in code and not have_shared:
            skipped.append(f"{where} reads ../shared/ (the shared recordings), absent here")
            continue
        if re.search(r"^\s*(from|import) torch", code, re.M) and importlib.util.find_spec("torch") is None:
            skipped.append(f"{where} needs the optional torch extra, not installed")
            continue
        if "benchmarks/" in code:  # benchmarks are run from the repository root, as the docs say
            (work / "benchmarks").exists() or (work / "benchmarks").symlink_to(ROOT / "benchmarks")
        if language == "python":
            command = [sys.executable, "-c", code]
        else:
            command = ["bash", "-euo", "pipefail", "-c", code]
        run = subprocess.run(command, cwd=work, env=env, capture_output=True, text=True)
        assert run.returncode == 0, f"{where} failed ({run.returncode}):\n{code}\n{run.stdout[-2000:]}\n" \
                                    f"{run.stderr[-3000:]}"
    shutil.rmtree(work, ignore_errors=True)
    if skipped:
        pytest.skip("; ".join(skipped))


def test_ci_proves_the_readme_setup_block():
    """The README's first block is the two commands; .ci/run runs both, each in a fresh environment."""
    _, info, code = blocks(ROOT / "README.md")[0]
    lines = [line.split("#")[0].strip() for line in code.splitlines() if line.strip()]
    assert lines == ["pip install -e . && viform demo", 'pip install -e ".[test]" && pytest']
    ci = (ROOT / ".ci" / "run").read_text()
    assert "pip install -q -e ." in ci and "viform demo" in ci and 'pip install -e ".[test]" && pytest' in ci
    assert ci.count("python3 -m venv") >= 2
