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


def one_line_error(res, *needles):
    """Assert a CliRunner result ended with exactly one `kinfu: error:` line (exit 2) holding `needles`."""
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    lines = [l for l in res.output.splitlines() if l.strip()]
    assert len(lines) == 1 and lines[0].startswith("kinfu: error: "), res.output
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]
