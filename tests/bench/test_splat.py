"""`holoflow bench splat`'s measuring function runs on a tiny case and counts plausible work."""

from holoflow.bench.splat import run_one


def test_run_one_counts_pairs_within_the_dense_bound():
    row = run_one(300, 16, repeat=1, ref_mem_gb=1.0, threads=1)
    assert 0 < row["pairs"] <= 300 * 16 * 16  # never more than the dense reference's work
    assert row["fast_fwd_s"] > 0 and row["ref_fwd_bwd_s"] > 0 and row["fast_peak_rss_mb"] > 0
