"""reproductions/lib/alaric_figures.py runs on tiny cases (Figs. 1 and 9; Figs. 12 and 16 take minutes even when quick)."""
import json

import pytest
from examples_loader import load_script



@pytest.fixture(scope="module")
def figures():
    return load_script("reproductions/lib/alaric_figures.py")


def test_figure1_quick_writes_its_files_and_the_maps_agree(figures, tmp_path):
    figures.main(["--figure", "1", "--quick", "--out", str(tmp_path)])
    data = json.loads((tmp_path / "results.json").read_text())
    assert (tmp_path / "fig1.png").stat().st_size > 0 and "Command:" in (tmp_path / "README.md").read_text()
    for row in data["rows"]:
        assert row["max position difference between the maps"] < 1e-9
    # the mirrored stretch beats the open interval, and both fall with N
    assert data["slopes"]["Eq. 26 analytic"] < -2 and data["slopes"]["open interval (analytic map)"] < -0.5
    assert all(r["Eq. 26 analytic"] < r["open interval (analytic map)"] for r in data["rows"])


def test_stretch_maps_put_equal_mass_between_neighbours(figures):
    import numpy as np

    r0 = (np.arange(7) + 0.5) / 7
    for stretch in figures.STRETCHES.values():
        x = stretch(r0)
        mass = (1 - np.exp(-5 * x)) / 5  # int_0^x exp(-5 t) dt
        np.testing.assert_allclose(mass, r0 * figures.MASS_TOTAL, rtol=1e-9)


def test_figure9_quick_is_monotone(figures, tmp_path):
    figures.main(["--figure", "9", "--quick", "--out", str(tmp_path)])
    data = json.loads((tmp_path / "results.json").read_text())
    assert data["monotone"] and set(data["panels"]) == {"1", "2", "3"}
    assert (tmp_path / "fig9.png").stat().st_size > 0
