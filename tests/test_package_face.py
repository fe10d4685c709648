"""The package face (issue 16 item 7): submodules and names reachable as attributes after a bare
``import ase_sphrelax``, still without loading numba, and ``help(ase_sphrelax)`` a useful first page."""
import subprocess
import sys

import pytest

import ase_sphrelax

SUBMODULES = ("domains", "build", "analysis", "drivers", "boundary", "sampling", "calculators", "models",
              "kernels", "neighbors", "pairs", "sph")
METHOD_NAMES = ("FanCalculator", "FanRelaxation", "BIPICalculator", "BIPIPacker", "pack", "ALARICCalculator",
                "ALARICDynamics", "relax_density", "WVTRelaxation", "ParVICalculator", "ParVISampler", "sample")


def _fresh(code):
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_submodules_are_attributes_after_a_bare_import():
    # each in a fresh process: no other import may have loaded the submodule first
    code = ("import sys, ase_sphrelax as sr\n"
            "assert 'numba' not in sys.modules\n"
            "c = sr.domains.Circle((0.5, 0.5), 0.2)\n"
            "atoms = sr.build.fill(c, 0.05, seed=0)\n"
            "print(len(atoms), type(sr.analysis).__name__, sr.drivers.ALARICDynamics.__name__,"
            " sr.sampling.sample.__name__, sr.boundary.BoundarySegments.__name__, sr.models.fan.__name__)")
    n, kind, driver, entry, segments, model = _fresh(code).split()
    assert int(n) > 0 and kind == "module" and driver == "ALARICDynamics" and entry == "sample"
    assert segments == "BoundarySegments" and model == "ase_sphrelax.models.fan"


@pytest.mark.parametrize("name", SUBMODULES)
def test_each_submodule_resolves_alone(name):
    assert _fresh(f"import ase_sphrelax as sr; print(sr.{name}.__name__)") == f"ase_sphrelax.{name}"


def test_bare_import_loads_no_numba_and_dir_lists_the_face():
    out = _fresh("import sys, ase_sphrelax as sr; names = dir(sr); "
                 "print('numba' in sys.modules, 'domains' in names, 'ALARICDynamics' in names)")
    assert out == "False True True"


def test_every_exported_name_resolves():
    for name in ase_sphrelax.__all__:
        assert getattr(ase_sphrelax, name) is not None, name
    for name in METHOD_NAMES:
        assert name in ase_sphrelax.__all__, name


def test_unknown_attribute_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no_such_name"):
        ase_sphrelax.no_such_name  # noqa: B018


def test_help_is_a_first_page_naming_every_method():
    doc = ase_sphrelax.__doc__
    for method in ("Fan", "BIPI", "ALARIC", "SPH-ParVI"):
        assert method in doc
    for name in METHOD_NAMES:
        assert name in doc, name
    assert "support" in doc and "z = 0" in doc
