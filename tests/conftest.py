"""Shared fixtures: the real spike data kept beside the project (never copied into it)."""

import os
from pathlib import Path

import pytest

#: The real recordings (README, "Tests that read real recordings"): ``$VIFORM_SPIKE_DATA`` if set,
#: else ``<repo>/../shared/data/spike``.
SHARED_SPIKE_DATA = Path(os.environ.get("VIFORM_SPIKE_DATA")
                         or Path(__file__).resolve().parents[1].parent / "shared" / "data" / "spike")


@pytest.fixture(scope="session")
def spike_data_dir() -> Path:
    """The real recordings' folder; tests that need it are skipped when it is absent."""
    if not SHARED_SPIKE_DATA.is_dir():
        pytest.skip(f"shared spike data absent: {SHARED_SPIKE_DATA}")
    return SHARED_SPIKE_DATA
