"""`make demo`: run the pipeline as far as it exists on the bundled sample recording.

Each stage is a real `kinfu` sub-command run in-process; a stage whose command is not
registered yet is reported as not available, never faked.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from click.testing import CliRunner

from kinfu_cli.cli import cli


def _run(args: list[str]) -> tuple[int, str]:
    res = CliRunner().invoke(cli, args, catch_exceptions=True)
    out = res.output
    if res.exception and not isinstance(res.exception, SystemExit):
        out += f"\n{type(res.exception).__name__}: {res.exception}"
    return res.exit_code, out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--data", default="sample_data")
    ap.add_argument("--out", default="out/demo")
    a = ap.parse_args(argv)
    data, out = Path(a.data), Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rec = data / "tabletop" / "recording.mcap"
    if not rec.exists():
        print(f"demo: {rec} not found (run `kinfu synth -o {data}/tabletop`)", file=sys.stderr)
        return 2
    gt = data / "tabletop" / "ground_truth"
    fuse_dir, seg_dir = out / "fuse", out / "segment"
    stages = [
        ("info", ["info", str(rec), "--json"], out / "info.json"),
        ("fuse", ["fuse", str(rec), "-o", str(fuse_dir), "--quiet"], fuse_dir),
        ("poi", ["poi", str(rec), "-o", str(out / "pois.json")], out / "pois.json"),
        ("segment", ["segment", str(fuse_dir / "volume.npz"), "-o", str(seg_dir)], seg_dir),
        ("nbv", ["nbv", str(fuse_dir / "volume.npz"), "--pois", str(out / "pois.json"), "--clear",
                 "-o", str(out / "views.json"), "--quiet"], out / "views.json"),
        ("eval", ["eval", "nbv", str(gt), "--views", "3", "--quiet"], None),
    ]
    available = set(cli.commands)
    failed = 0
    print(f"kinfu demo on {rec}")
    for name, args, output in stages:
        if args[0] not in available:
            print(f"  {name:8s} not available yet")
            continue
        t0 = time.perf_counter()
        code, text = _run(args)
        dt = time.perf_counter() - t0
        if name == "info" and code == 0:
            (out / "info.json").write_text(text)
        status = "ok" if code == 0 else f"FAILED (exit {code})"
        print(f"  {name:8s} {status:10s} {dt:6.1f} s  -> {output if output else '(table below)'}")
        if code != 0:
            failed += 1
            print("    " + text.strip().replace("\n", "\n    "))
        elif name == "eval":
            print("    " + text.strip().replace("\n", "\n    "))
    print(f"outputs in {out}/")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
