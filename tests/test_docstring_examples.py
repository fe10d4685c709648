"""The examples in the docstrings run (doctest), module by module (issue 19 item 3)."""
import doctest
import importlib
import pkgutil

import pytest

import ase_sphrelax
import lammps_io


def _modules():
    names = []
    for package in (ase_sphrelax, lammps_io):
        names.append(package.__name__)
        for info in pkgutil.walk_packages(package.__path__, prefix=package.__name__ + "."):
            if not info.name.endswith("__main__"):
                names.append(info.name)
    return names


MODULES = _modules()


def test_the_walk_finds_the_packages():
    assert "ase_sphrelax.calculators.fan" in MODULES and "lammps_io.data_file" in MODULES


@pytest.mark.parametrize("name", [m for m in MODULES
                                  if ">>>" in (importlib.util.find_spec(m).loader.get_source(m) or "")])
def test_docstring_examples_run(name, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False)
    assert result.attempted > 0, f"{name}: its '>>>' lines were not collected as examples"
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} docstring examples failed"
