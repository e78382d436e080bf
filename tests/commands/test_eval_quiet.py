"""`--quiet` of the eval commands prints only warnings and errors, as fuse, segment, poi and eval nbv do: eval
fusion, localize, grasp, segment and poi printed their tables with it. --quiet --json still prints the JSON, and
only it, on stdout; without --quiet the table is printed."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import SAMPLE, write_hand_dataset
from kinfu_cli.cli import cli
from kinfu_cli.evaluation import reconstruction
from kinfu_cli.grasp import evaluate as grasp_evaluate

MODES = {"table": [], "quiet": ["--quiet"], "quiet-json": ["--quiet", "--json"]}


def _run(args: list[str], mode: str, out=None):
    res = CliRunner().invoke(cli, [*args, *MODES[mode], *(["-o", str(out)] if out is not None else [])])
    assert res.exit_code == 0, res.output
    return res


def _check(res, mode: str, table_text: str, warning_text: str | None, out=None) -> None:
    """The table only without --quiet, the JSON alone with --json, nothing else on stdout; warnings on stderr."""
    if mode == "table":
        assert table_text in res.stdout, res.stdout
    elif mode == "quiet":
        assert res.stdout == "", res.stdout
    else:
        doc = json.loads(res.stdout)  # the whole of stdout is the JSON
        if out is not None:
            assert doc == json.loads(out.read_text())
    warnings = [line for line in res.stderr.splitlines() if line.startswith("kinfu: warning: ")]
    if warning_text is None:
        assert res.stderr.strip() == "", res.stderr
    else:
        assert any(warning_text in w for w in warnings), res.stderr


@pytest.mark.parametrize("mode", MODES)
def test_eval_fusion(mode, tmp_path, monkeypatch):
    monkeypatch.setattr(reconstruction, "MAX_SAMPLES", 2000)  # a coarser sampling, with a warning that says so
    out = tmp_path / "fusion.json"
    res = _run(["eval", "fusion", str(SAMPLE / "tabletop" / "ground_truth" / "scene_after.ply"), "--ground-truth",
                str(SAMPLE / "tabletop"), "--spacing", "0.05", "--no-volume"], mode, out)
    _check(res, mode, "accuracy (recon -> true)", "more than the sampler's 2000", out)


@pytest.mark.parametrize("mode", MODES)
def test_eval_localize(mode, tmp_path):
    out = tmp_path / "localize.json"
    res = _run(["eval", "localize", "--shapes", "box", "--trials", "1", "--methods", "mupf", "--particles", "50",
                "--recognition-trials", "0"], mode, out)
    _check(res, mode, "method", None, out)


@pytest.mark.parametrize("mode", MODES)
def test_eval_grasp(mode, tmp_path, monkeypatch):
    """One generated object; the scenes (the only source of warnings, slow to segment) give one warning."""
    every_object = grasp_evaluate.generated_objects
    monkeypatch.setattr(grasp_evaluate, "generated_objects", lambda yaws, seed: every_object(yaws, seed)[:1])
    monkeypatch.setattr(grasp_evaluate, "evaluate_scenes", lambda options, seeds, progress=None: {
        "rows": [], "summary": {}, "warnings": ["scene 0: segment 3 has no superquadric"]})
    out = tmp_path / "grasp.json"
    res = _run(["eval", "grasp", "--conditions", "none", "--yaws", "1", "--scenes", "0"], mode, out)
    _check(res, mode, "none/single", "scene 0: segment 3 has no superquadric", out)


@pytest.mark.parametrize("mode", MODES)
def test_eval_segment(mode, tmp_path):
    """A quarter of the segmented points have no ground truth near them: a warning."""
    points = np.random.default_rng(0).random((40, 3))
    np.savez(tmp_path / "segments.npz", points=points, labels=np.arange(40) % 3)
    np.savez(tmp_path / "labels.npz", points=points[:30], labels=np.arange(30) % 3)
    out = tmp_path / "segment.json"
    res = _run(["eval", "segment", str(tmp_path / "segments.npz"), "--ground-truth", str(tmp_path / "labels.npz"),
                "--max-distance", "0.001"], mode, out)
    _check(res, mode, "bnd P", "10 of 40 segmented points (25%) have no ground-truth point", out)


@pytest.fixture(scope="module")
def hand_dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("hand")
    for user in ("user1", "user4"):  # two users: --loo has a pair to score
        write_hand_dataset(root, seeds=range(1), user=user, groups=("pick_and_place",))
    return root


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("loo", [False, True], ids=["tables", "loo"])
def test_eval_poi(mode, loo, hand_dataset):
    res = _run(["eval", "poi", str(hand_dataset), "--algorithm", "zvc", "--workers", "1", *(["--loo"] if loo else [])],
               mode)
    _check(res, mode, "user1" if loo else "Table 2", None)


@pytest.mark.parametrize("name", ["fusion", "localize", "grasp", "segment", "poi", "nbv"])
def test_quiet_help_says_what_it_leaves_out(name):
    res = CliRunner().invoke(cli, ["eval", name, "--help"])
    assert res.exit_code == 0, res.output
    assert "--quiet Only warnings and errors: no progress bar, no tables (--json still prints the JSON)." in \
        " ".join(res.output.split())
