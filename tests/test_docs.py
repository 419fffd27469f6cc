"""docs/stages.md's param tables are the ones generated from the stages' param classes, and every
local link and picture in the user docs exists."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_stage_param_tables_are_generated_from_the_param_classes():
    """Every stage's table in docs/stages.md is what `holoflow params --update-docs` writes now."""
    from holoflow.commands.params import update_doc
    from holoflow.flow import pipeline

    pipe = pipeline.load(ROOT / "pipeline.yaml")
    text = (ROOT / "docs" / "stages.md").read_text()
    assert set(re.findall(r"<!-- params:(\w+) -->", text)) == set(pipe.stages)
    assert update_doc(text, pipe) == text, (
        "docs/stages.md is out of date: run `holoflow params --update-docs docs/stages.md`"
    )


def test_doc_links_and_pictures_exist():
    pages = ["index.md", "stages.md", "viewers.md", "extending.md", "accuracy.md", "getting-started.md"]
    for page in pages:
        text = (ROOT / "docs" / page).read_text()
        for target in re.findall(r"\]\(([^)#]+)\)", text):
            if "://" in target:
                continue
            assert (ROOT / "docs" / target).exists(), f"{page}: {target}"
        for ref in re.findall(r"docs/[\w./-]+\.(?:md|png|csv)", text):
            assert (ROOT / ref).exists(), f"{page}: {ref}"
