"""reproductions/lib/bipi_figures.py: its after-the-fact stopping rule is the packer's, and its history file keeps every row."""
import csv

import numpy as np
import pytest
from examples_loader import load_script

bipi_figures = load_script("reproductions/lib/bipi_figures.py")


def _packer(window, n2a):
    from ase_sphrelax.boundary import BoundarySegments
    from ase_sphrelax.calculators.bipi import BIPICalculator
    from ase_sphrelax.drivers.bipi_packer import BIPIPacker, initial_fill

    seg = BoundarySegments.from_vertices([[0.0, 0.0], [1.0, 0.0], [1.3, 0.8], [0.0, 0.8]])
    dx = 0.05
    atoms = initial_fill(seg, dx)
    calc = BIPICalculator.from_paper(2.0, dx, seg)
    return BIPIPacker(atoms, calc, max_steps_2a=n2a, max_steps_2c=1, window=window, stages=("2a",))


@pytest.mark.filterwarnings("ignore:BIPIPacker. not converged")
@pytest.mark.parametrize("window", [1, 10])
def test_stop_iteration_matches_the_packer(window):
    fixed = _packer(bipi_figures.NEVER, 400)
    fixed.run()
    tpd = [r["tpd_avg"] for r in fixed.history]
    ruled = _packer(window, 400)
    ruled.run()
    expected = ruled.stage_iterations["2a"]
    assert ruled.stopped_by["2a"] == "rule"
    assert bipi_figures.stop_iteration(tpd, window) == expected
    np.testing.assert_array_equal(tpd[:expected], [r["tpd_avg"] for r in ruled.history])


def test_history_writer_blocks_and_stage_ends(tmp_path):
    rows = [dict(stage="2a", iteration=i, tpd_avg=float(i), gradc_avg=float(i % 2), n_pack=1, rejected=0, time=0.0)
            for i in range(1, 1036)]
    writer = bipi_figures.HistoryWriter(tmp_path / "h.csv")
    writer.flush(rows[:1015])
    writer.flush(rows)
    rows += [dict(stage="2c", iteration=i, tpd_avg=1.0, gradc_avg=2.0, n_pack=1, rejected=0, time=0.0) for i in (1, 2)]
    writer.flush(rows, final=True)
    with open(tmp_path / "h.csv") as fh:
        out = list(csv.DictReader(fh))
    assert [int(r["iteration"]) for r in out] == list(range(1, 1001)) + [1010, 1020, 1030, 1035, 1, 2]
    block = out[1000]  # iterations 1001-1010
    assert float(block["tpd_avg"]) == pytest.approx(1005.5)
    assert (float(block["gradc_min"]), float(block["gradc_max"])) == (0.0, 1.0)
    assert float(out[1003]["tpd_avg"]) == pytest.approx(1033.0)  # the partial block 1031-1035 at the stage's end
