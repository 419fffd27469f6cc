"""One summary printer for run, run --prompts and sweep (holoflow/flow/summary.py)."""

from pathlib import Path

from holoflow.flow.store import Store
from holoflow.flow.summary import summary_lines

STAGES = {"gen": {"how": "cached", "reasons": []}, "upper": {"how": "ran", "reasons": ["never run"]}}


def test_one_run_and_its_dry_run():
    store = Store(Path("/s"))
    assert summary_lines({"stages": STAGES, "seconds": 1.234, "run": "r1"}, store) == [
        f"holoflow: done in 1.23 s (1 cached, 1 ran); outputs in {store.run_dir('r1')}"
    ]
    assert summary_lines({"dry_run": True, "stages": STAGES}, store) == [
        "gen              cached  ",
        "upper            ran       (never run)",
    ]


def test_a_batch_and_its_dry_run():
    scenes = [
        {"label": "s1", "stages": STAGES, "run": "r1", "prompt": "a", "sets": ["upper.mode=title"]},
        {"label": "s2", "stages": {}, "run": None, "prompt": None},
    ]
    assert summary_lines({"scenes": scenes, "seconds": 2.0, "executor": "local -j 2"}, Store(Path("/s"))) == [
        's1: 1 cached, 1 ran; run r1; "a" [upper.mode=title]',
        "s2: nothing; run None; null",
        "holoflow: batch of 2 scenes done in 2.00 s (local -j 2); runs pinned, latest -> the last scene",
    ]
    assert summary_lines({"dry_run": True, "scenes": scenes[:1]}, Store(Path("/s"))) == [
        "s1   gen              cached  ",
        "s1   upper            ran       (never run)",
    ]
