"""The short stress test (the long one is `holoflow bench stress`, docs/bench-stress.md): the tiny run's
numba-heavy steps rerun beside CPU hogs must give the same bytes every time. pcd_set and inp_set are the
steps whose outputs were once seen to differ between two stores under load (issue 33)."""

from pathlib import Path

from holoflow.bench.stress import stress

ROOT = Path(__file__).resolve().parents[2]


def test_forced_reruns_beside_cpu_hogs_give_identical_bytes(two_runs):
    """``--force pcd_set --force inp_set`` on the e2e store, round after round for about 40 s beside two
    busy-loop processes: every artifact's digest equals the first run's (bounded: at most 6 rounds)."""
    store, first, _ = two_runs
    res = stress(ROOT / "pipeline.yaml", rounds=6, n_hogs=2, budget_s=40, force=["pcd_set", "inp_set"], store=store)
    assert res["reference"] == {n: s["outputs"] for n, s in first["stages"].items()}
    assert len(res["rounds"]) >= 1
    assert [r["diffs"] for r in res["rounds"]] == [[] for _ in res["rounds"]]


def test_records_name_the_cpu_kind_and_the_pinned_paths(two_runs):
    import json

    from holoflow.flow.executors.step_env import PINNED_ENV, cpu_facts

    store, _, _ = two_runs
    recs = [json.loads(p.read_text()) for p in (store / "keys").glob("*.json")]
    assert len(recs) >= 13
    for rec in recs:
        assert rec["provenance"]["cpu"] == {**cpu_facts(), **PINNED_ENV}
