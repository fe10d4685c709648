"""The sampler configuration every stored SPH-ParVI study was run with, pinned ("classic").

The defaults of :func:`ase_sphrelax.sampling.sample` / :class:`~ase_sphrelax.sampling.sampler.ParVISampler` change
with issue 18 (``time_step="local", friction="critical", score_every="adaptive", n_neighbours=12,
hold_max="scaled"``). The scripts of ``reproductions/parvi-*`` pass :data:`CLASSIC` under their own keywords
(``ParVISampler(..., **classic(n=m, steps=s, **options))``), so that they keep making the stored results:
:data:`CLASSIC` is every keyword default of ``ParVISampler.__init__`` as of git 7e290ea (the data arguments
``log_density, score, dim, n, x0, seed, progress`` excepted), and ``check=False``: the verdict's check against the
target (``sampling/verdict.py``), which came later, can restart a run from missed modes and so change its samples.

:func:`run_benchmark` runs a script of ``benchmarks/`` (``bench_sampling``, ``bench_sampling_theory``) with its
``ParVISampler`` replaced by :class:`PinnedSampler` (the same sampler, :data:`CLASSIC` under the caller's keywords); for
``bench_sampling`` the stored NUTS reference of the logistic posterior is restored first (``parvi_reference.py``)
and found there (``bench_sampling.OUT``; give ``--out``)::

    python reproductions/lib/parvi_pinned.py bench_sampling --quick --out /tmp/quick
"""
import importlib
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: ``ParVISampler``'s keyword defaults before issue 18's configuration became the default.
CLASSIC = dict(formulation="force", eos="isothermal", alpha=1.0, c0=None, rho0=None, gamma=7.0, kernel="wendland_c2",
               h="adaptive", h_schedule="constant", h_end=None, n_neighbours=None, viscosity="linear",
               viscosity_alpha=0.1, nu=0.05, regularisation=0.0, density="summation", diffusion=0.1, eps=1e-10,
               steps=600, dt=None, courant=None, friction=None, rule="final", init_scale=None, record_every=10,
               max_steps=None, whiten=None, whiten_every=50, whiten_until=0.5, time_step="global", friction_every=50,
               friction_ramp=1.0, neighbours="kernel", k=None, coarse_to_fine=None, coarse_share=0.5, score_every=1,
               hold_tolerance=0.02, hold_max=4, finish=None, finish_steps=200,
               check=False)  # no verdict check (and no restart from missed modes): the samples the studies stored


def classic(**own):
    """:data:`CLASSIC` with the caller's keywords on top (the caller's win)."""
    return dict(CLASSIC, **own)


def pinned_sampler_class():
    """A ``ParVISampler`` subclass whose keyword defaults are :data:`CLASSIC`."""
    from ase_sphrelax.sampling.sampler import ParVISampler

    class PinnedSampler(ParVISampler):
        def __init__(self, log_density=None, score=None, **kwargs):
            super().__init__(log_density, score, **classic(**kwargs))

    return PinnedSampler


def run_benchmark(name, argv, out=None):
    """Run ``benchmarks/<name>.py``'s ``main`` with :data:`CLASSIC` pinned (and its ``OUT`` set to ``out``)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    module = importlib.import_module(name)
    module.ParVISampler = pinned_sampler_class()
    if out is not None:
        module.OUT = Path(out)
    return module.main(argv) if argv is not None else module.main()


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] not in ("bench_sampling", "bench_sampling_theory"):
        raise SystemExit("usage: parvi_pinned.py {bench_sampling,bench_sampling_theory} [args]")
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "reproductions"))
    if sys.argv[1] == "bench_sampling_theory":  # no arguments; its OUT is the only option: --out DIR
        out = sys.argv[sys.argv.index("--out") + 1] if "--out" in sys.argv else None
        run_benchmark("bench_sampling_theory", None, out)
    else:  # the logistic posterior's stored NUTS draws: bench_sampling looks for them in OUT (and --out)
        from lib.parvi_reference import PATH, logistic_reference

        if "logistic" in sys.argv or "--targets" not in sys.argv:
            logistic_reference()
        run_benchmark("bench_sampling", sys.argv[2:], out=PATH.parent)
