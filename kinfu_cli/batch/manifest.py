"""manifest.json: per recording and stage the status, timing, fingerprint, key numbers and error line.

Written atomically by the client after every finished task, so an interrupted run leaves the record of
everything that completed and the next run resumes from it.
"""

from __future__ import annotations

import json
from pathlib import Path

from kinfu_cli.core.atomic import write_json

MANIFEST_NAME = "manifest.json"
# stage statuses: ok (ran), skipped (outputs current), failed (error line), blocked (a needed stage failed)
DONE = ("ok", "skipped")


def _previous_recordings(path: Path) -> list[dict]:
    """The recording entries of an earlier run's manifest; [] when absent or unreadable."""
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return []
    recs = doc.get("recordings", []) if isinstance(doc, dict) else []
    return [rec for rec in recs if isinstance(rec, dict)] if isinstance(recs, list) else []


def read_previous(path: Path) -> dict[tuple[str, str], dict]:
    """{(output folder, stage): entry} of an earlier run's manifest; {} when absent or unreadable."""
    out = {}
    for rec in _previous_recordings(path):
        if isinstance(rec.get("stages"), dict):
            for stage, entry in rec["stages"].items():
                if isinstance(entry, dict):
                    out[(str(rec.get("output")), stage)] = entry
    return out


def read_links(path: Path) -> dict[str, dict[str, tuple[Path, ...]]]:
    """{output folder: {link: paths}} of the paths earlier plans named for each recording, as an earlier run's
    manifest records them (the `viz` link: its `viewer`, and the `earlier_viewers` still there then); {} when
    absent or unreadable."""
    out = {}
    for rec in _previous_recordings(path):
        named = [rec.get("viewer"), *(rec.get("earlier_viewers") if isinstance(rec.get("earlier_viewers"), list)
                                      else ())]
        if paths := tuple(dict.fromkeys(Path(p) for p in named if isinstance(p, str) and p)):
            out[str(rec.get("output"))] = {"viz": paths}
    return out


def _earlier_viewers(rec) -> list[str]:
    """The combined viewer files earlier plans named for the recording (PlanRecording.earlier) that are still
    there, this plan's aside: recorded until a run removes them (a run stopped first leaves their names known)."""
    now = rec.links.get("viz")
    return [str(p) for p in rec.earlier.get("viz", ()) if p != now and (p.exists() or p.is_symlink())]


def recording_status(stages: dict[str, dict], wanted: list[str]) -> str:
    """ok when every stage is done, failed when one failed or was blocked, else pending."""
    states = [stages.get(s, {}).get("status") for s in wanted]
    if all(s in DONE for s in states):
        return "ok"
    if any(s in ("failed", "blocked") for s in states):
        return "failed"
    return "pending"


def build_manifest(plan, entries: dict[tuple[int, str], dict], engine: str) -> dict:
    """The manifest document of `plan` with the stage entries known so far."""
    recs = []
    for i, rec in enumerate(plan.recordings):
        stages = {s: entries[(i, s)] for s in rec.stages if (i, s) in entries}
        status = recording_status(stages, list(rec.stages))
        error = next((f"{s}: {e['error']}" for s, e in stages.items() if e.get("status") == "failed"), None)
        recs.append({"recording": str(rec.path), "output": str(rec.output), "status": status, "error": error,
                     "stages": stages, **({"viewer": str(rec.links["viz"])} if "viz" in rec.links else {}),
                     **({"earlier_viewers": earlier} if (earlier := _earlier_viewers(rec)) else {})})
    done = sum(r["status"] == "ok" for r in recs)
    failed = sum(r["status"] == "failed" for r in recs)
    return {"plan": str(plan.source), "output": str(plan.output), "stages": plan.stages, "engine": engine,
            "summary": {"recordings": len(recs), "done": done, "failed": failed,
                        "pending": len(recs) - done - failed},
            "recordings": recs}


def write_manifest(path: Path, doc: dict) -> None:
    write_json(path, doc)
