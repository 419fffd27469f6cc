"""`holoflow bench accuracy --profiles P --truth DIR`: a truth set is run the ways asked, each scored per ring
beside its seconds; an absent truth set is skipped with a note."""

import json
import math


def test_truth_ways_are_the_commands_of_the_issue(tmp_path):
    from holoflow.bench import profiles

    (tmp_path / "cameras.json").write_text("{}")
    cases, notes = profiles.truth_cases(tmp_path, ["exact", "simulated", "rgb"])
    assert notes == [] and [c.kind for c in cases] == ["truth"] * 3
    exact, sim, rgb = cases
    assert exact.uses == (f"base_pano={tmp_path}/pano_z.exr", f"metric_align={tmp_path}/pano_z.exr") and not exact.sets
    assert sim.uses == (f"base_pano={tmp_path}/pano_z.exr",)
    assert sim.sets == ("tangent_depth.engine=simulated", "metric_align.engine=simulated")
    assert rgb.uses == (f"base_pano={tmp_path}/pano.png",) and rgb.truth == tmp_path
    cases, notes = profiles.truth_cases(tmp_path / "nope", ["rgb"])
    assert cases == [] and "no truth set" in notes[0]


def test_a_truth_set_is_run_and_scored_per_ring(tiny_truth_set, tmp_path):
    from holoflow.bench import accuracy as acc

    truth = tiny_truth_set
    doc = tmp_path / "acc.md"
    argv = [
        "--profiles",
        "tiny",
        "--scenes",
        "",
        "--photos",
        "",
        "--truth",
        str(truth),
        "--truth-ways",
        "exact",
        "--size",
        "48",
        "--nr-cameras",
        "0",
        "--store",
        str(tmp_path / "store"),
        "--doc",
        str(doc),
        "--json",
        str(tmp_path / "p.json"),
    ]
    assert acc.main(argv) == 0
    (run,) = json.loads((tmp_path / "p.json").read_text())["runs"]
    row = run["row"]
    assert (row["case"], row["kind"]) == ("room-exact", "truth") and row["wall_s"] > 0
    assert all(math.isfinite(row[f"truth_psnr_{k}"]) for k in ("0", "0.5"))
    assert list(run["scores"]["truth"]["rings"]) == ["0", "0.5"]
    text = doc.read_text()
    assert "| room-exact | tiny |" in text and "0.5 m dB" in text
    assert (tmp_path / "images" / "truth-room-exact-tiny-ring-0.5.jpg").stat().st_size > 500
    assert acc.main(argv[:6] + ["--truth", str(tmp_path / "none")] + argv[8:]) == 0
    assert "- note: no truth set" in doc.read_text()
