"""`make demo`: the whole pipeline on the bundled sample recording, the paper's way round.

1. `kinfu info` — what is in the recording.
2. `kinfu fuse --end T_hand_in` — the initial scan, before the person acts.
3. `kinfu poi` — points of interest from the hand trajectory (analysed when the hand has left).
4. `kinfu nbv --clear` — ForgetAround the POIs in the scan volume and rank views around them.
5. `kinfu fuse --init scan --clear-pois --start T_hand_out` — forget the POI spheres, fuse the
   views taken after the change (without the clearing KinFu keeps the old surface).
6. `kinfu diff scan after --pois` — what changed (removed / added regions) and how well the POIs point at it.
7. `kinfu segment` — segments, saliency and superquadrics of the updated scene.
8. `kinfu eval fusion` / `kinfu eval nbv` — scores against the generator's ground truth.

Every stage is a real `kinfu` sub-command run in-process; a stage whose command does not exist is
reported as not available, never faked. Exit status 1 when a stage fails.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.io.hand import load_hand_trajectory
from kinfu_cli.io.recording import open_recording


def _run(args: list[str]) -> tuple[int, str]:
    res = CliRunner().invoke(cli, args, catch_exceptions=True)
    out = res.output
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        out += f"\n{type(res.exception).__name__}: {res.exception}"
    return res.exit_code, out


def hand_window(recording: Path) -> tuple[float, float]:
    """Seconds from the recording start at which the hand trajectory starts and ends."""
    with open_recording(recording) as rec:
        start_ns = rec.start_ns
    traj = load_hand_trajectory(recording)
    offset = (traj.t0_ns - start_ns) / 1e9
    return offset + float(traj.t[0]), offset + float(traj.t[-1])


SHOWN = ("poi", "diff", "eval fusion", "eval nbv")  # stages whose printed results the demo shows


def demo_stages(rec: Path, gt: Path, out: Path, t_in: float, t_out: float) -> list[tuple[str, list[str], Path]]:
    """The pipeline's stages as (name, kinfu arguments, output): scan before the hand enters, POIs, views, the
    scene after it left, what changed, segments, and the evaluations, whose printed tables (and those of poi and
    diff: SHOWN) the demo shows, so those run without --quiet."""
    scan, fused, seg, diff = out / "scan", out / "fuse", out / "segment", out / "diff"
    pois, views = out / "pois.json", out / "views.json"
    return [
        ("info", ["info", str(rec), "--json"], out / "info.json"),
        ("fuse scan", ["fuse", str(rec), "-o", str(scan), "--end", f"{t_in:.3f}", "--quiet", "--plot"], scan),
        ("poi", ["poi", str(rec), "-o", str(pois), "--plot", str(out / "pois.png")], pois),
        ("nbv", ["nbv", str(scan / "volume.npz"), "--pois", str(pois), "--clear", "--top", "5",
                 "-o", str(views), "--plot", str(out / "views.png"), "--quiet"], views),
        ("fuse after", ["fuse", str(rec), "-o", str(fused), "--init", str(scan / "volume.npz"),
                        "--clear-pois", str(pois), "--start", f"{t_out:.3f}", "--quiet"], fused),
        ("diff", ["diff", str(scan / "volume.npz"), str(fused / "volume.npz"), "-o", str(diff), "--pois", str(pois)],
         diff),
        ("segment", ["segment", str(fused / "volume.npz"), "-o", str(seg), "--plot", "--quiet"], seg),
        ("eval fusion", ["eval", "fusion", str(fused), "--ground-truth", str(gt), "--state", "after",
                         "-o", str(out / "eval_fusion.json")], out / "eval_fusion.json"),
        ("eval nbv", ["eval", "nbv", str(gt), "--views", "3", "--strategy", "poi,random",
                      "-o", str(out / "eval_nbv.json"), "--plot", str(out / "eval_nbv.png")],
         out / "eval_nbv.json"),
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default="sample_data", help="folder holding tabletop/recording.mcap")
    ap.add_argument("--out", default="out/demo", help="output folder")
    a = ap.parse_args(argv)
    data, out = Path(a.data), Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rec = data / "tabletop" / "recording.mcap"
    gt = data / "tabletop" / "ground_truth"
    if not rec.exists():
        print(f"demo: {rec} not found (make it with `kinfu synth -o {data}/tabletop`)", file=sys.stderr)
        return 2
    t_in, t_out = hand_window(rec)
    stages = demo_stages(rec, gt, out, t_in, t_out)
    print(f"kinfu demo on {rec} (hand in the workspace {t_in:.2f}-{t_out:.2f} s)")
    failed = 0
    tables: list[str] = []
    for name, args, output in stages:
        t0 = time.perf_counter()
        code, text = _run(args)
        dt = time.perf_counter() - t0
        if name == "info" and code == 0:
            (out / "info.json").write_text(text)
        print(f"  {name:12s} {'ok' if code == 0 else f'FAILED (exit {code})':10s} {dt:6.1f} s  -> {output}")
        if code != 0:
            failed += 1
            print("    " + text.strip().replace("\n", "\n    "))
        elif name in SHOWN:
            tables.append(f"--- {name}\n{text.strip()}")
    summary = _summary(out)
    if summary:
        print("\nSummary\n  " + "\n  ".join(summary))
    for t in tables:
        print("\n" + t)
    print(f"\nall outputs in {out}/")
    return 1 if failed else 0


def _percent(share: float | None) -> str:
    """A ratio as a percentage; 'undefined' for null (changes.json: no POI or no change to divide by)."""
    return "undefined" if share is None else f"{100 * share:.0f} %"


def _summary(out: Path) -> list[str]:
    lines = []
    for name in ("scan", "fuse"):
        rep = out / name / "report.json"
        if rep.exists():
            r = json.loads(rep.read_text())
            c = r.get("counts", {})
            lines.append(f"{name:5s}: {r['frames']['used']} frames, occupied {c.get('occupied')}, "
                         f"empty {c.get('empty')}, unknown {c.get('unknown')} voxels; mesh {out / name / 'mesh.ply'}")
    if (out / "views.json").exists():
        v = json.loads((out / "views.json").read_text())
        for p in v.get("pois", []):
            best = (p.get("views") or [{}])[0]
            pos = best.get("position")
            if pos is not None:
                lines.append(f"POI {p.get('id')}: best view at ({pos[0]:.2f}, {pos[1]:.2f}, {pos[2]:.2f}) m, gain "
                             f"{best.get('gain')}")
    if (out / "diff" / "changes.json").exists():
        d = json.loads((out / "diff" / "changes.json").read_text())
        n = d["counts"]["regions"]
        text = f"changes: {n['removed']} removed, {n['added']} added regions"
        if d.get("pois"):
            text += f"; POIs vs changes precision {_percent(d['pois']['precision'])}, recall " \
                    f"{_percent(d['pois']['recall'])}"
        lines.append(text + f"; {out / 'diff' / 'changes.ply'}")
    if (out / "segment" / "segments.json").exists():
        s = json.loads((out / "segment" / "segments.json").read_text())["segments"]
        objects = [x for x in s if x.get("kind") == "object"]
        top = max(objects, key=lambda x: x.get("saliency") or 0.0, default=None)
        support = " + support plane" if any(x.get("kind") == "support_plane" for x in s) else ""
        text = f"segments: {len(objects)} objects{support}"
        if top is not None:
            text += f"; most salient #{top['id']} saliency {top['saliency']:.3f}"
        lines.append(text + f"; {out / 'segment' / 'segments.json'}")
    return lines


if __name__ == "__main__":
    sys.exit(main())
