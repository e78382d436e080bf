"""The public Python API: every exported name resolves, and the README's example script runs as written."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

import kinfu_cli.api as kf

REPO = Path(__file__).resolve().parents[1]


def test_every_exported_name_exists_and_is_documented():
    for name in kf.__all__:
        obj = getattr(kf, name)
        if callable(obj):
            assert obj.__doc__, f"kinfu_cli.api.{name} has no docstring"


def _readme_script() -> str:
    text = (REPO / "README.md").read_text()
    section = text.split("## Python API", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_readme_script_fuses_and_ranks_views_around_each_poi():
    script = _readme_script()
    assert len(script.strip().splitlines()) <= 12  # the README promises a short script
    cwd = os.getcwd()
    os.chdir(REPO)
    try:
        scope: dict = {}
        exec(compile(script, "README.md", "exec"), scope)
    finally:
        os.chdir(cwd)
    vol, pois, rankings = scope["volume"], scope["pois"], scope["rankings"]
    assert vol.counts()["occupied"] > 10_000 and vol.frames_integrated > 10
    assert len(pois) == len(rankings) >= 1
    for poi, ranking in zip(pois, rankings):
        best = ranking.scores.poses[ranking.scores.order()[0]]
        to_poi = poi.position - best[:3, 3]
        # the best view looks at its POI from the paper's viewing sphere (0.8 m) and sees unknown space
        assert np.isclose(np.linalg.norm(to_poi), 0.8, atol=1e-6)
        assert np.degrees(np.arccos(best[:3, 2] @ to_poi / np.linalg.norm(to_poi))) < 1.0
        assert ranking.best_gain > 0
