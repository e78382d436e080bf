"""Shared fixtures: paths to the bundled sample data and to ../shared/data (skip when absent)."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "sample_data"
SHARED_DATA = REPO.parent / "shared" / "data"


def shared_path(*parts: str) -> Path:
    """Path under ../shared/data, or skip the test with the reason."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"real data {p} not present (../shared/data is not checked out beside the repo)")
    return p


@pytest.fixture
def shared_data():
    return shared_path


@pytest.fixture(scope="session")
def sample_dir() -> Path:
    p = SAMPLE / "tabletop"
    if not (p / "recording.mcap").exists():
        pytest.fail(f"{p}/recording.mcap missing: sample_data must be committed (kinfu synth -o {p})")
    return p
