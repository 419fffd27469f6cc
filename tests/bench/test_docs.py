"""docs/stages.md documents exactly the params pipeline.yaml has, with their default values, and every
local link and picture in the user docs exists."""
import re
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]


def documented_params() -> dict[str, dict[str, str]]:
    """{stage: {param: default cell}} from the tables under each '## STAGE: ...' heading."""
    out, stage = {}, None
    for line in (ROOT / "docs" / "stages.md").read_text().splitlines():
        m = re.match(r"## (\w+): ", line)
        if m:
            stage = m.group(1)
            out[stage] = {}
        m = re.match(r"\| `(\w+)` \| `(.*?)` \|", line)
        if m and stage:
            out[stage][m.group(1)] = m.group(2)
    return out


def test_stage_params_match_pipeline_yaml():
    pipe = yaml.safe_load((ROOT / "pipeline.yaml").read_text())
    docs = documented_params()
    assert set(docs) == set(pipe["stages"])
    for stage, spec in pipe["stages"].items():
        params = spec.get("params", {})
        assert set(docs[stage]) == set(params), stage
        for k, v in params.items():
            assert docs[stage][k] in (str(v), '""' if v == "" else str(v)), (stage, k)


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
