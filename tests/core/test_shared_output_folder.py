"""Two commands writing into one folder: each replaces only its own outputs.

Before: `kinfu diff ... -o out` then `kinfu segment ... -o out` left out/ with segments.json, segments.ply and
saliency.ply only: diff's changes.json, changes.ply and regions/ were deleted (kinfu had written them, so the
folder swap treated them as the segment run's to replace); `kinfu fuse -o out` after `kinfu poi -o out/pois.json`
deleted pois.json the same way.
"""

import json

from kinfu_cli.core.atomic import atomic_dir, write_json
from kinfu_cli.core.ownership import MANIFEST, written_by_kinfu


def _run(out, own, files):
    with atomic_dir(out, own=own) as tmp:
        for name, text in files.items():
            (tmp / name).parent.mkdir(parents=True, exist_ok=True)
            (tmp / name).write_text(text)


def test_a_second_command_keeps_the_first_ones_outputs_and_drops_only_its_own_stale_ones(tmp_path):
    out = tmp_path / "out"
    _run(out, ("changes.json", "regions"), {"changes.json": "1", "regions/0.ply": "r"})
    write_json(out / "pois.json", {"pois": []})  # a single-file output written into the folder
    (out / "notes.txt").write_text("mine")  # the user's
    _run(out, ("segments.json", "*.png"), {"segments.json": "s", "segments.png": "p"})
    assert (out / "changes.json").read_text() == "1" and (out / "regions" / "0.ply").read_text() == "r"
    assert (out / "pois.json").exists() and (out / "notes.txt").read_text() == "mine"
    # still kinfu's: the first command can replace them again, with no "not written by kinfu" refusal
    assert all(written_by_kinfu(out / n) for n in ("changes.json", "regions", "pois.json", "segments.json"))
    assert not written_by_kinfu(out / "notes.txt")
    # the second command again, without its plot: its stale PNG goes, nothing else
    _run(out, ("segments.json", "*.png"), {"segments.json": "s2"})
    assert not (out / "segments.png").exists() and (out / "segments.json").read_text() == "s2"
    _run(out, ("changes.json", "regions"), {"changes.json": "2"})
    assert (out / "changes.json").read_text() == "2" and not (out / "regions").exists()
    assert sorted(p.name for p in out.iterdir()) == sorted([MANIFEST, "changes.json", "notes.txt", "pois.json",
                                                            "segments.json"])
    files = json.loads((out / MANIFEST).read_text())["files"]
    assert set(files) == {"changes.json", "pois.json", "segments.json"}


def test_without_own_the_folder_is_the_callers_whole(tmp_path):
    out = tmp_path / "bag"
    _run(out, None, {"a.db3": "1", "metadata.yaml": "m"})
    _run(out, None, {"b.db3": "2", "metadata.yaml": "m"})
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == ["b.db3", "metadata.yaml"]


def test_cli_diff_then_segment_into_one_folder(tmp_path):
    import numpy as np
    from click.testing import CliRunner

    from kinfu_cli.cli import cli
    from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid, save_ternary

    lab = np.full((60, 60, 60), EMPTY, np.int8)
    lab[:, :, :15] = UNKNOWN
    lab[:, :, 15] = OCCUPIED
    lab[25:37, 25:37, 16:28] = OCCUPIED
    lab[26:36, 26:36, 16:27] = UNKNOWN
    vol = tmp_path / "ternary.npz"
    save_ternary(vol, TernaryGrid(lab, np.zeros(3), 0.008))
    out = tmp_path / "out"
    for args in (["diff", str(vol), str(vol), "-o", str(out), "--quiet"],
                 ["segment", str(vol), "-o", str(out), "--quiet", "--no-superquadrics"]):
        res = CliRunner().invoke(cli, args)
        assert res.exit_code == 0, res.output
    assert {"changes.json", "segments.json", "segments.ply", "saliency.ply"} <= {p.name for p in out.iterdir()}


def test_synth_rerun_keeps_what_other_commands_wrote_beside_its_recording(tmp_path):
    """Before: `kinfu synth -o S` again deleted S/pois.json and S/fuse/ that poi and fuse had written there."""
    from click.testing import CliRunner

    from kinfu_cli.cli import cli

    out = tmp_path / "S"
    synth = ["synth", "-o", str(out), "--width", "32", "--height", "24", "--frames", "2", "--n-objects", "1", "-q"]
    res = CliRunner().invoke(cli, synth + ["--formats", "mcap,bag"])
    assert res.exit_code == 0, res.output
    write_json(out / "pois.json", {"pois": []})
    _run(out / "fuse", ("report.json",), {"report.json": "{}"})
    res = CliRunner().invoke(cli, synth + ["--formats", "mcap", "--seed", "1"])
    assert res.exit_code == 0, res.output
    names = {p.name for p in out.iterdir()}
    assert {"pois.json", "fuse", "recording.mcap", "ground_truth"} <= names
    assert "recording.bag" not in names  # synth's own earlier output, not written this time
