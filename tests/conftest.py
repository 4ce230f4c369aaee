"""Shared fixtures: the real spike data kept beside the project (never copied into it)."""

from pathlib import Path

import pytest

SHARED_SPIKE_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "spike"


@pytest.fixture(scope="session")
def spike_data_dir() -> Path:
    """``<repo>/../shared/data/spike``; tests that need it are skipped when it is absent."""
    if not SHARED_SPIKE_DATA.is_dir():
        pytest.skip(f"shared spike data absent: {SHARED_SPIKE_DATA}")
    return SHARED_SPIKE_DATA
