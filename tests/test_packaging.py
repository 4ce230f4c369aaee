"""The package's build metadata stays buildable by current setuptools."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def test_the_license_is_an_spdx_expression_that_the_build_backend_reads():
    """setuptools deprecated the table form ``license = {text = ...}`` (PEP 639) and warns that builds using it
    stop being supported from 2027-02-18; a plain SPDX string needs setuptools ≥ 77 in the build requirements."""
    project = tomllib.loads(PYPROJECT.read_text())
    assert isinstance(project["project"]["license"], str)
    floors = [re.fullmatch(r"setuptools>=(\d+)(?:\.\d+)*", r) for r in project["build-system"]["requires"]]
    assert any(m and int(m.group(1)) >= 77 for m in floors), project["build-system"]["requires"]
