"""Shared test settings: headless plots, paths to the shared facts."""

import os
from pathlib import Path

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

REPO = Path(__file__).resolve().parents[1]
# The published test vectors live beside the repository (../shared/facts) on every machine.
FACTS = REPO.parent / "shared" / "facts"


@pytest.fixture
def facts_dir():
    if not FACTS.is_dir():
        pytest.fail(f"shared facts not found at {FACTS}")
    return FACTS
