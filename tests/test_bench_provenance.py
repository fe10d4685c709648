"""The machine a benchmark's timing was taken on is stored with it, and a stored LAMMPS time is divided by only when
it was taken on the same kind of machine (benchmarks/_provenance.py, bench_fan_1e6.stored_lammps)."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
provenance = pytest.importorskip("_provenance")
bench = pytest.importorskip("bench_fan_1e6")


def test_machine_names_the_cpu_and_what_numba_compiles_for():
    here = provenance.machine()
    for key in provenance.MACHINE_KEYS + ("mhz", "load_average"):
        assert key in here, key
    assert here["cpus"] >= 1
    assert here["vector"] in ("avx512", "avx2", "other")
    assert isinstance(here["compile_target"], str) and here["compile_target"]  # llvmlite's host CPU, numba's target


def test_same_machine_ignores_the_load_and_the_clock_reading_only():
    here = provenance.machine()
    assert provenance.same_machine(here, dict(here, load_average=[9.0, 9.0, 9.0], mhz=1.0))
    assert not provenance.same_machine(here, dict(here, compile_target="skylake-avx512"))
    assert not provenance.same_machine(here, dict(here, l2_kib=2048))
    assert not provenance.same_machine(here, None)  # a record without its machine compares with nothing
    assert not provenance.same_machine(None, here)
    assert not provenance.same_machine({}, {})


def test_a_stored_lammps_time_of_another_machine_is_not_divided_by():
    here = provenance.machine()
    other = dict(here, cpu="another CPU")
    run = dict(wall_time=120.0, steps=800, reached=True)
    estimate = dict(wall_time=600.0, rate_run=dict(wall_time=30.0))
    assert bench.stored_lammps({}, here) is None
    assert bench.stored_lammps({"lammps": run}, here) is None  # stored before machines were recorded
    assert bench.stored_lammps({"lammps": dict(run, machine=other)}, here) is None
    assert bench.stored_lammps({"lammps": dict(run, machine=here)}, here) == "run"
    assert bench.stored_lammps({"lammps_estimate": estimate}, here) is None
    rated_here = dict(estimate, rate_run=dict(estimate["rate_run"], machine=here))
    assert bench.stored_lammps({"lammps_estimate": rated_here}, here) == "estimate"
    rated_elsewhere = dict(estimate, rate_run=dict(estimate["rate_run"], machine=other))
    assert bench.stored_lammps({"lammps_estimate": rated_elsewhere, "lammps": dict(run, machine=here)}, here) == "run"


def test_repeated_keeps_the_run_of_median_time_and_every_time():
    times = iter([5.0, 3.0, 9.0, 4.0])
    record = bench.repeated(lambda: dict(wall_time=next(times), steps=1), 3)
    assert record["wall_time"] == 5.0 and record["wall_times"] == [5.0, 3.0, 9.0]
    times = iter([5.0, 3.0])
    assert bench.repeated(lambda: dict(wall_time=next(times)), 2)["wall_time"] == 3.0  # the lower median
    with pytest.raises(ValueError, match="repeat"):
        bench.repeated(dict, 0)
