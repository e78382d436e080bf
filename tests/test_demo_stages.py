"""`make demo`'s stages: those whose printed results the demo shows run without --quiet (the eval stages printed
empty sections once --quiet came to mean 'only warnings and errors')."""

from __future__ import annotations

from pathlib import Path

from kinfu_cli.demo import SHOWN, demo_stages


def test_shown_stages_print_their_results_and_the_others_are_quiet(tmp_path):
    stages = demo_stages(Path("rec.mcap"), Path("gt"), tmp_path, 6.1, 11.0)
    names = [name for name, _, _ in stages]
    assert set(SHOWN) <= set(names)
    for name, args, _ in stages:
        assert ("--quiet" in args) == (name not in SHOWN and name != "info"), name
