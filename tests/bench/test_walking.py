"""`holoflow bench accuracy --walk --truth DIR`: knobs turned one at a time around a profile, each run on a
truth set with its depth given, scored per ring beside its fresh-run seconds."""

import json
import math


def test_each_knob_is_run_on_the_truth_set_and_scored_per_ring_with_its_seconds(tiny_truth_set, tmp_path):
    from holoflow.bench import accuracy as acc
    from holoflow.bench.walking import BEGIN, END

    doc, out = tmp_path / "acc.md", tmp_path / "w.json"
    doc.write_text("# kept\n")
    argv = ["--walk", "--walk-profile", "tiny", "--truth", str(tiny_truth_set), "--points", "base,no-layer"]
    argv += ["--store", str(tmp_path / "store"), "--doc", str(doc), "--json", str(out)]
    assert acc.main(argv) == 0
    base, no_layer = json.loads(out.read_text())["rows"]
    assert (base["way"], base["point"], no_layer["point"]) == ("room-exact", "base", "no-layer")
    assert base["wall_s"] > 0 and base["gaussians"] > no_layer["gaussians"]  # the layer's Gaussians
    assert all(math.isfinite(r[f"psnr_{k}"]) for r in (base, no_layer) for k in ("0", "0.5"))
    assert "tangent_depth" not in base["ran"] and "point_cloud" in no_layer["ran"]  # given depth; the knob's reach
    assert "pano_set" not in no_layer["ran"]  # served from the shared store
    text = doc.read_text()
    assert text.startswith("# kept\n") and BEGIN in text and END in text
    assert "| room-exact | base | profile | tiny |" in text and "| +0.00 / - |" in text
    assert "| room-exact | no-layer | background layer | off |" in text


def test_a_sweep_without_a_truth_set_or_with_an_unknown_point_says_why(tiny_truth_set, tmp_path, capsys):
    from holoflow.bench import accuracy as acc

    assert acc.main(["--walk", "--truth", str(tmp_path / "none")]) == 2
    assert "no truth set" in capsys.readouterr().err
    assert acc.main(["--walk", "--truth", str(tiny_truth_set), "--points", "base,warp-9"]) == 2
    assert "unknown point(s) ['warp-9']" in capsys.readouterr().err


def test_a_stopped_sweep_leaves_the_last_table_and_its_rows_in_json(tiny_truth_set, tmp_path, monkeypatch):
    import pytest

    from holoflow.bench import accuracy as acc
    from holoflow.bench import walking
    from holoflow.bench.walking import BEGIN, END

    doc, out = tmp_path / "acc.md", tmp_path / "w.json"
    old = f"# kept\n\n{BEGIN}\nthe last whole table\n{END}\n"
    doc.write_text(old)
    real, calls = walking.measure, []

    def stops_on_the_second(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt  # Ctrl-C, or a full disk
        return real(*args, **kwargs)

    monkeypatch.setattr(walking, "measure", stops_on_the_second)
    argv = ["--walk", "--walk-profile", "tiny", "--truth", str(tiny_truth_set), "--points", "base,no-layer"]
    with pytest.raises(KeyboardInterrupt):
        acc.main(argv + ["--store", str(tmp_path / "store"), "--doc", str(doc), "--json", str(out)])
    assert doc.read_text() == old
    assert [r["point"] for r in json.loads(out.read_text())["rows"]] == ["base"]
