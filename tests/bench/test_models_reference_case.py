"""The case-3 references of ``meshphase bench models``: the directional one (small sizes),
its cache, the plain fallback and the estimator table's reference columns."""

import json

import numpy as np
import pytest

from meshphase.bench.models import (ESTIMATOR_COLUMNS, _bench_reference, _markdown,
                                    _rel_errors, _rel_errors_ref)
from meshphase.bench.models_reference import (REFERENCE_SUMMARIES, directional_reference,
                                              plain_reference)
from meshphase.models.tolerance import (ALL_STATISTICS, Tolerances, ToleranceBand,
                                        monte_carlo, observation_window, table2_case)


@pytest.fixture(scope="module")
def case():
    g, sp, tol = table2_case(3)
    return g, sp, tol, observation_window(sp, "slowest-offset")


@pytest.fixture(scope="module")
def small_ref(case, tmp_path_factory):
    out = tmp_path_factory.mktemp("ref")
    return out, directional_reference(case, out, n_evaluations=2000, check_directions=4,
                                      case_name="t")


def test_directional_reference_layout_and_cache(case, small_ref):
    out, ref = small_ref
    assert ref["method"] == "directional-cv" and not ref["cached"]
    assert ref["n_samples"] == 2000 and ref["n_directions"] == 500 and ref["nodes"] == 4
    path = out / "models_reference_directional_2000_20261126.json"
    assert ref["file"] == str(path) and path.is_file()
    for part in ("values", "stderr", "stderr_batch"):
        assert set(ref[part]) == set(REFERENCE_SUMMARIES)
        for k in REFERENCE_SUMMARIES:
            assert set(ref[part][k]) == set(ALL_STATISTICS)
            assert all(len(v) == 4 for v in ref[part][k].values())
            # batch means over 10 groups of 50 rays may leave a bound off the grid: null
            if part != "stderr_batch":
                assert all(np.all(np.isfinite(v)) for v in ref[part][k].values())
    assert json.loads(path.read_text())["values"] == json.loads(json.dumps(ref["values"]))
    v = ref["values"]
    # planet 1 has no relative spread; Dev is positive and its bounds bracket the mean
    assert v["std"]["dev_r"][0] == 0.0 and v["bound3_hi"]["dev_r"][0] == 0.0
    for n in range(1, 4):
        assert 0 < v["bound3_lo"]["dev_r"][n] < v["mean"]["dev_r"][n] < v["bound3_hi"]["dev_r"][n]
    assert ref["unconverged"] == 0 and ref["interpolation"]["n_directions"] == 4
    again = directional_reference(case, out, n_evaluations=2000, check_directions=4,
                                  case_name="t")
    assert again["cached"] and again["values"] == json.loads(json.dumps(ref["values"]))
    # another label is another key: recomputed, not read
    other = directional_reference(case, out, n_evaluations=2000, check_directions=4,
                                  case_name="u")
    assert not other["cached"]


def test_reference_errors_resolve_the_estimator(case, small_ref):
    _, ref = small_ref
    g, sp, tol, win = case
    res = monte_carlo(g, sp, tol, win, 64, method="cv", rng=0, tail_directions=4)
    stats = [s for s in ALL_STATISTICS if max(ref["values"]["std"][s]) > 1e-12]
    err, ref_se, own, z = _rel_errors(res, ref, stats)
    assert set(err) == set(ref_se) == {"mean_std", "bound3"}
    se_all = _rel_errors_ref(ref, stats)
    # the SE beside each largest error is one of the reference's own SEs (<= the largest)
    assert 0 <= ref_se["mean_std"] <= se_all[0] and 0 <= ref_se["bound3"] <= se_all[1]
    assert np.isfinite(z) and err["bound3"] > 0


def test_fallback_to_plain(case, tmp_path):
    g, sp, _, win = case
    tol = Tolerances(e_sun=ToleranceBand(0.0, 0.2e-3), kappa_sun=ToleranceBand.full_circle(),
                     e_ring=ToleranceBand(0.0, 0.5e-3), kappa_ring=ToleranceBand.full_circle(),
                     e_planet=ToleranceBand(0.0, 0.2e-3),
                     kappa_planet=ToleranceBand.full_circle())
    ref = _bench_reference((g, sp, tol, win), tmp_path, 400, True, "directional", False)
    assert ref["method"] == "plain" and "random" in ref["fallback_reason"]
    ref2 = _bench_reference(case, tmp_path, 400, True, "plain", False)
    assert ref2["method"] == "plain" and ref2["fallback_reason"] == "asked for"


def test_markdown_names_the_reference(small_ref):
    _, ref = small_ref
    row = {c: 1.0 for c in ESTIMATOR_COLUMNS}
    row["method"] = "cv"
    est = {"rows": [row], "load_average": [[1.0, 2.0, 3.0], None],
           "reference": {"method": "directional-cv", "n_samples": 2000, "n_directions": 500,
                         "nodes": 4, "seed": 1, "wall_time_s": 1.0, "cached": True,
                         "file": ref["file"], "se_mean_std": 1e-5, "se_bound3": 2e-5,
                         "se_batch_mean_std": 1e-5, "se_batch_bound3": 2e-5,
                         "interpolation": ref["interpolation"], "unconverged": 0}}
    result = {"meta": {"window": {"name": "w", "t0": 0.0, "duration": 1.0}, "n_times": 2,
                       "engine": "numba", "replicates": 2, "cpu_count": 2, "error_unit": "u"},
              "reference": {"n_samples": 1, "wall_time_s": 0.0, "skipped_metrics": []},
              "rows": [], "estimators": est}
    md = _markdown(result)
    assert "directional control variate" in md and ref["file"] in md
    assert "| " + " | ".join(ESTIMATOR_COLUMNS) + " |" in md
    assert "1.00, 2.00, 3.00 / -" in md
    est["reference"] = {"method": "plain", "n_samples": 10, "seed": 1, "wall_time_s": 1.0,
                        "cached": False, "se_mean_std": 1e-3, "se_bound3": 1e-3,
                        "fallback_reason": "why"}
    assert "plain pseudo-random (fallback: why)" in _markdown(result)


def test_bad_inputs(case, tmp_path):
    with pytest.raises(ValueError):
        directional_reference(case, tmp_path, n_evaluations=40)       # < 2 groups x nodes
    with pytest.raises(ValueError):
        directional_reference(case, tmp_path, n_evaluations=0)
    with pytest.raises(ValueError):
        directional_reference(case, tmp_path, n_evaluations=2000, groups=1)
    with pytest.raises(ValueError):
        directional_reference(case, tmp_path, n_evaluations=2000, check_directions=0)
    g, sp, tol, win = case
    uniform = Tolerances(e_sun=ToleranceBand(0.0, 0.2e-3, "uniform"),
                         kappa_sun=tol.kappa_sun, e_ring=tol.e_ring,
                         kappa_ring=tol.kappa_ring, e_planet=tol.e_planet,
                         kappa_planet=tol.kappa_planet)
    with pytest.raises(ValueError):
        directional_reference((g, sp, uniform, win), tmp_path, n_evaluations=2000)
    with pytest.raises(ValueError):
        plain_reference(case, tmp_path, n_samples=3)


def test_bench_reference_builds_then_reads(tmp_path, capsys):
    # `meshphase bench reference` builds the reference as its own step, then reads it
    from meshphase.cli import main
    args = ["-q", "bench", "reference", "--out", str(tmp_path), "--evaluations", "2000"]
    assert main(args) == 0
    assert "built" in capsys.readouterr().out
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "read from the cache" in out and "models_reference_directional_2000_" in out
    assert main(["-q", "bench", "reference", "--out", str(tmp_path), "--evaluations", "400",
                 "--plain"]) == 0
    assert "plain reference, 400 evaluations" in capsys.readouterr().out


def test_build_reference_bad_input(tmp_path):
    from meshphase.bench.models_reference import build_reference
    with pytest.raises((ValueError, TypeError)):
        build_reference(tmp_path, evaluations=0)
    with pytest.raises((ValueError, TypeError)):
        build_reference(tmp_path, evaluations="many", plain=True)


def test_estimator_row_over_repeats(case, small_ref):
    from meshphase.bench.models import _estimator_row
    _, ref = small_ref
    stats = [s for s in ALL_STATISTICS if max(ref["values"]["std"][s]) > 1e-12]
    row = _estimator_row(case, ("cv", "sobol", 64, 4), [1, 2], ref, stats)
    assert set(ESTIMATOR_COLUMNS) <= set(row)
    assert row["repeats"] == 2 and row["tail_directions"] == 4 and row["samples"] == 64
    # RMS over the runs lies between the best and the worst run
    assert 0 < row["err_bound3"] <= row["err_bound3_worst"]
    assert row["wall_s"] > 0 and row["evaluations"] > row["samples"]
    plain = _estimator_row(case, ("plain", "random", 32, None), [3], ref, stats)
    assert plain["method"] == "plain-random" and plain["tail_directions"] is None
    with pytest.raises(ValueError):
        _estimator_row(case, ("cv", "sobol", 64, 4), [], ref, stats)
