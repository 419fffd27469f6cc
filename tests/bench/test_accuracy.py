"""holoflow bench accuracy: the sweep's points resolve against pipeline.yaml, its fits and Pareto front
are right on known data, and a two-point tiny sweep reuses upstream stages through one store."""
import csv
import math

import pytest

from holoflow.bench import accuracy as acc


@pytest.mark.parametrize("point", acc.full_points() + acc.quick_points(), ids=lambda p: p.name)
def test_every_point_resolves_against_pipeline_yaml(point):
    params = acc.resolved_params(point.profile, list(point.sets))      # raises on an unknown param
    for item in point.sets:
        stage, rest = item.split(".", 1)
        assert rest.split("=", 1)[0] in params[stage]
    assert set(acc.stage_drivers(params)) == set(acc.STAGES)


def test_fit_costs_recovers_fixed_and_linear_costs_and_names_unvaried_drivers():
    drivers = [{"it": it, "it x n": it * n, "const": 7.0} for it in (50, 100, 200) for n in (1e3, 4e3)]
    seconds = [3.0 + 0.01 * d["it"] + 2e-5 * d["it x n"] for d in drivers]
    fit = acc.fit_costs(drivers, seconds)
    assert fit["fixed"] == pytest.approx(3.0, rel=1e-6) and fit["unvaried"] == ["const"]
    assert fit["coef"] == pytest.approx({"it": 0.01, "it x n": 2e-5}, rel=1e-6)
    assert acc.predict(fit, {"it": 1000, "it x n": 1000 * 1e6, "const": 7.0}) == pytest.approx(3 + 10 + 2e4)


def test_pareto_front_keeps_only_undominated_points():
    pts = [(10.0, 30.0), (20.0, 29.0), (30.0, 35.0), (5.0, 20.0), (40.0, 35.0)]
    assert acc.pareto(pts, higher_better=True) == [3, 0, 2]
    assert acc.pareto([(t, -s) for t, s in pts], higher_better=False) == [3, 0, 2]


def test_quick_sweep_reuses_upstream_and_resumes(tmp_path):
    store, out = tmp_path / "store", tmp_path / "out.csv"
    argv = ["--quick", "--points", "base,iters-x0.5", "--store", str(store), "--csv", str(out),
            "--plot", str(tmp_path / "p.png")]
    assert acc.main(argv) == 0
    rows = list(csv.DictReader(open(out)))
    assert [r["point"] for r in rows] == ["base", "iters-x0.5"]
    assert set(rows[1]["ran"].split()) == {"pre_opt", "inp_set", "transfer_opt", "export"}   # upstream from the store
    for name in ("base_pano", "tangent_depth", "pano_set"):                       # same records, same costs
        assert rows[0][f"{name}_s"] == rows[1][f"{name}_s"] and float(rows[0][f"{name}_s"]) > 0
    for r in rows:
        assert 0 < float(r["abs_rel"]) < 1 and math.isfinite(float(r["g1_novel_psnr"]))
        assert float(r["total_cpu_s"]) > 0 and int(r["g1_gaussians"]) > 0
    assert (tmp_path / "p.png").stat().st_size > 10_000
    assert acc.main(argv) == 0                                                     # resume: nothing reruns
    again = list(csv.DictReader(open(out)))
    assert [r["ran"] for r in again] == ["", ""]
    assert [r["g1_novel_psnr"] for r in again] == [r["g1_novel_psnr"] for r in rows]
