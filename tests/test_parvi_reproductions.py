"""The SPH-ParVI registry scripts (reproductions/parvi-*): they import from their new places, and every sampler
they build runs with the pinned configuration the stored results were made with (reproductions/lib/parvi_pinned.py),
whatever the defaults of ``sample`` become."""
import inspect

import numpy as np
import pytest
from examples_loader import load_script

from ase_sphrelax.sampling import get_target
from ase_sphrelax.sampling.sampler import ParVISampler

SCRIPTS = ["reproductions/parvi-highdim/run.py", "reproductions/parvi-logistic-goal/run.py",
           "reproductions/parvi-variants/run.py", "reproductions/parvi-steps/run.py",
           "reproductions/parvi-banana-m2000/diagnose_coarse.py", "reproductions/parvi-banana-m2000/svgd_cost.py",
           "reproductions/parvi-rest-vs-time/run_rest.py", "reproductions/parvi-rest-vs-time/summarize.py",
           "reproductions/lib/parvi_run_sph.py", "reproductions/lib/parvi_means.py",
           "reproductions/parvi-stationary/run.py"]
#: the issue-18 keywords whose defaults change, with the values the stored results were made with
PRE_CHANGE = dict(time_step="global", friction=None, score_every=1, n_neighbours=None, hold_max=4)


@pytest.mark.parametrize("path", SCRIPTS)
def test_script_imports_from_its_registry_place(path):
    assert callable(load_script(path).main)


def test_classic_names_every_keyword_of_the_sampler_but_the_data():
    pinned = load_script("reproductions/lib/parvi_pinned.py")
    params = set(inspect.signature(ParVISampler.__init__).parameters) - {"self"}
    assert set(pinned.CLASSIC) == params - {"log_density", "score", "dim", "n", "x0", "seed", "progress"}
    assert {k: pinned.CLASSIC[k] for k in PRE_CHANGE} == PRE_CHANGE


def test_run_sph_and_pinned_sampler_build_the_pre_change_configuration():
    run_sph = load_script("reproductions/lib/parvi_run_sph.py")
    pinned = load_script("reproductions/lib/parvi_pinned.py")
    target = get_target("banana")
    x0 = np.random.default_rng(0).standard_normal((50, 2))
    built = run_sph.build_sampler(target, "default", 50, x0, 10, 0)
    assert {k: built._options[k] for k in PRE_CHANGE} == PRE_CHANGE
    assert built._options["steps"] == 10  # the caller's keywords win over CLASSIC
    local = run_sph.build_sampler(target, "local+critical", 50, x0, 10, 0)
    assert (local._options["time_step"], local._options["friction"]) == ("local", "critical")
    sampler = pinned.pinned_sampler_class()(target.log_density, target.score, dim=2, n=50, x0=x0, steps=10)
    assert {k: sampler._options[k] for k in PRE_CHANGE} == PRE_CHANGE


def test_means_are_per_seed_ratios_and_ratios_of_means():
    means = load_script("reproductions/lib/parvi_means.py").means
    rows = [dict(target="t", m=10, seed=s, method=meth, energy=e)
            for s, meth, e in ((0, "iid", 1.0), (1, "iid", 3.0), (0, "sph", 2.0), (1, "sph", 3.0))]
    sph = next(r for r in means(rows) if r["method"] == "sph")
    assert sph["seeds"] == 2 and sph["energy_mean"] == 2.5
    assert sph["over_iid_mean"] == pytest.approx((2.0 + 1.0) / 2)  # per seed: 2/1, 3/3
    assert sph["over_iid_of_means"] == pytest.approx(2.5 / 2.0)


def test_gzipped_results_round_trip(tmp_path):
    io = load_script("reproductions/lib/results_io.py")
    data = dict(rows=[dict(a=1.5)])
    io.write_json(tmp_path / "x.json.gz", data)
    assert io.read_json(tmp_path / "x.json.gz") == data
    assert (tmp_path / "x.json.gz").read_bytes()[:2] == b"\x1f\x8b"  # gzip, not plain text
