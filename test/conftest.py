"""Shared test set-up. The reference data at ../shared/data are required (CI has them): a test that needs
them fails, never skips, when they are missing."""

from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The reference data directory, or a failure saying where it was looked for."""
    if not SHARED_DATA.is_dir():
        pytest.fail(f"the reference data are missing: expected {SHARED_DATA} (a checkout of shared/ beside the repo)")
    return SHARED_DATA
