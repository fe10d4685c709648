"""benchmarks/bench_sampling.py: the marginal errors, the equal-wall-time reference and the refusal cell."""
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
bench = pytest.importorskip("bench_sampling")


def test_marginal_errors_against_hand_computed_values():
    """Mean error in reference sds and sd ratios, per coordinate, against a hand-built sample."""
    rng = np.random.default_rng(0)
    z = rng.standard_normal((400, 3))
    z = (z - z.mean(axis=0)) / z.std(axis=0, ddof=1)  # exactly mean 0, sd 1 per coordinate
    x = z * np.array([2.0, 1.05, 0.5]) + np.array([0.3, 0.0, -0.1])
    ref = dict(mean=np.zeros(3), cov=np.diag([1.0, 1.0, 0.25]))  # sds 1, 1, 0.5
    out = bench.marginal_errors(x, ref)
    # |mean - mu| / s = 0.3, 0, 0.2; sd ratios 2, 1.05, 1
    assert out["mean_err_sd_max"] == pytest.approx(0.3)
    assert out["mean_err_sd_median"] == pytest.approx(0.2)
    assert out["sd_ratio_min"] == pytest.approx(1.0)
    assert out["sd_ratio_max"] == pytest.approx(2.0)
    assert out["sd_within_10pct"] == pytest.approx(2 / 3)


def test_equal_wall_reference_falls_back_when_the_default_refuses():
    ran = dict(result=SimpleNamespace(wall_time=7.0))
    assert bench.sph_wall_reference({"sph-default": dict(error="M < 656", refused=True), "iid": ran,
                                     "sph-knn+whiten": ran}) == ("sph-knn+whiten", 7.0)
    both = {"sph-knn": dict(result=SimpleNamespace(wall_time=3.0)),
            "sph-default": dict(result=SimpleNamespace(wall_time=5.0))}
    assert bench.sph_wall_reference(both) == ("sph-default", 5.0)
    assert bench.sph_wall_reference({"svgd": ran}) == (None, None)


def test_report_marks_a_refusal_apart_from_a_divergence(tmp_path):
    rows = [dict(target="gaussian10d", m=100, seed=0, method="iid", wall=0.0, energy=1.0),
            dict(target="gaussian10d", m=100, seed=0, method="sph-default", wall=0.0, error="M", refused=True),
            dict(target="gaussian10d", m=100, seed=0, method="sph-knn", wall=1.0, error="diverged")]
    meta = dict(git="x", sizes=[100], repeats=1, steps=10, load_average=(0, 0, 0))
    bench.write_report(rows, meta, tmp_path)
    line = next(s for s in (tmp_path / "report.md").read_text().splitlines() if s.startswith("| gaussian10d"))
    assert [c.strip() for c in line.strip("| ").split("|")][3:5] == ["refused", "div"]
