"""ase_sphrelax: particle distributions for SPH by relaxation, as an ASE plugin.

Each method is an ASE :class:`~ase.calculators.calculator.Calculator` whose energy is the
method's objective and whose forces are its exact negative gradient (``calc.conservative``
says so; a method whose paper rule is not a gradient has a driver and says it is not), so ASE's
optimisers and MD drive it next to the driver of the paper's own rule. ``h`` is the kernel
**support** radius everywhere; 2D atoms live at z = 0 with pbc (True, True, False), 1D atoms
on the x axis with ``atoms.info["dim"] = 1``; the dimension is inferred from the Atoms.

Methods (calculator, driver, entry function)
--------------------------------------------
Fan et al., total error (Eq. 3.8) with a level-set boundary term (Eq. 4.4)
    :class:`FanCalculator`, :class:`FanRelaxation` (Eq. 2.4), :func:`make_optimizer`
    (ASE optimisers scaled to SPH units); lattice patterns in :mod:`ase_sphrelax.analysis`.
BIPI (Boregowda & Liu), packing against boundary segments/triangles with exact boundary integrals
    :class:`BIPICalculator`, :class:`BIPIPacker` (Steps 2a/2b/2c), :func:`pack`.
ALARIC (Vela Vela et al.), isothermal SPH in an external potential for any target density
    :class:`ALARICCalculator`, :class:`ALARICDynamics`, :func:`relax_density`; the baseline
    :class:`WVTRelaxation` (weighted Voronoi tessellation, Diehl et al.) and :class:`AFCRelaxation`
    (the paper's naive away-from-closest baseline, Sec. 5.1).
SPH-ParVI (Huang), SPH as a sampler of unnormalised densities
    :class:`ParVICalculator`, :class:`ParVISampler`, :func:`sample`.

Quick start
-----------
>>> import ase_sphrelax as sr
>>> domain = sr.domains.Circle((0.5, 0.5), 0.2)
>>> atoms = sr.build.fill(domain, 1 / 64, seed=0)        # 2D particles at z = 0
>>> atoms.calc = sr.FanCalculator(h=2.6 / 64, dx=1 / 64, domain=domain)
>>> e0 = atoms.get_potential_energy()                   # total error E, Eq. 3.8
>>> _ = sr.FanRelaxation(atoms, c=0.01, logfile=None).run(fmax=0, steps=20)  # Eq. 2.4
>>> bool(atoms.get_potential_energy() < e0), atoms.calc.conservative
(True, True)

Submodules (loaded on first use, so ``import ase_sphrelax`` loads no numba)
---------------------------------------------------------------------------
``domains`` level-set domains; ``build`` particle fills; ``boundary`` boundary segments,
triangles and integrals; ``calculators``; ``drivers``; ``analysis`` quality metrics and
lattice patterns; ``sampling`` SPH-ParVI, targets, metrics and baselines; ``kernels``;
``neighbors``; ``pairs`` (the pair mechanism); ``sph`` (shared SPH physics); ``models``
(one module per method); ``cli`` (the ``sphrelax`` command); ``io`` (SWIFT, GADGET-4 and VTU
files). LAMMPS export and engines are in the separate package ``lammps_io``.

To export a name, add one line to ``_WHERE`` (name -> defining submodule), never an eager
import (``tests/test_cli.py`` checks that ``import ase_sphrelax`` loads no numba).
"""
from .lazy import lazy_exports

__version__ = "0.1.0"

_SUBMODULES = ("analysis", "boundary", "build", "calculators", "checks", "cli", "domains", "drivers",
               "io", "kernel_sums", "kernels", "models", "neighbors", "pairs", "parallel", "plotting",
               "sampling", "sph", "splitting", "tree_neighbors")

_WHERE = {
    # Fan et al.
    "FanCalculator": ".calculators.fan",
    "FanRelaxation": ".drivers.fan_relaxation",
    "make_optimizer": ".drivers.optimizers",
    "KeepInDomain": ".drivers.keep_inside",
    # BIPI
    "BIPICalculator": ".calculators.bipi",
    "BIPIPacker": ".drivers.bipi_packer",
    "pack": ".drivers.bipi_packer",
    # ALARIC (and its baseline, WVT)
    "ALARICCalculator": ".calculators.alaric",
    "ALARICDynamics": ".drivers.alaric_dynamics",
    "relax_density": ".drivers.alaric_dynamics",
    "WVTRelaxation": ".drivers.wvt",
    "AFCRelaxation": ".drivers.afc",
    # SPH-ParVI
    "ParVICalculator": ".calculators.parvi",
    "ParVISampler": ".sampling.sampler",
    "sample": ".sampling.sampler",
    # downstream: a start run at rest (BISPH or LAMMPS)
    "settle": ".flows.settle",
    # the core
    "SphrelaxWarning": ".checks",
    "Kernel": ".kernels",
    "get_kernel": ".kernels",
    "NeighborList": ".neighbors",
    "fill": ".build",
    "periodic_box": ".build",
    "Box": ".domains",
    "Circle": ".domains",
    "Sphere": ".domains",
    "Polygon": ".domains",
    "Mesh": ".domains",
    "Union": ".domains",
    "Intersection": ".domains",
    "Difference": ".domains",
}
__all__ = list(_WHERE) + list(_SUBMODULES) + ["__version__"]
__getattr__, __dir__ = lazy_exports(globals(), _WHERE, _SUBMODULES)
