"""batch's eval-poi stage: a ratio with nothing to divide by is null with a warning, not 0.0 (which reads as all
wrong)."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

from kinfu_cli.commands._batch_stages import EVAL_POI_FILE, run_eval_poi
from kinfu_cli.core.pois import write_pois

GROUND_TRUTH = Path(__file__).resolve().parents[2] / "sample_data" / "tabletop" / "ground_truth"


def test_no_poi_gives_an_undefined_precision_and_says_why(tmp_path):
    write_pois(tmp_path / "pois.json", [], "gmm-as", {})
    rec = SimpleNamespace(output=tmp_path, links={"ground_truth": GROUND_TRUTH})
    run = run_eval_poi(rec, {}, force=False)
    assert run.numbers["precision"] is None and run.numbers["recall"] == 0.0  # the changes are there, none found
    (warning,) = run.warnings
    assert "precision is undefined (null): no POI was found" in warning
    doc = json.loads((tmp_path / EVAL_POI_FILE).read_text())
    assert doc["precision"] is None and doc["warnings"] == run.warnings
