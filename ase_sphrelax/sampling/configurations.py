"""SPH-ParVI's named configurations: the default, the classic one and the ``--variant`` tokens.

Constants only (no numba, no model), so that ``sphrelax sample --help`` can list the tokens without loading the
sampler; :mod:`~ase_sphrelax.sampling.sampler` uses and re-exports them.
"""
from __future__ import annotations

__all__ = ["DEFAULTS", "CLASSIC", "VARIANT_TOKENS", "VARIANT_NUMBERS", "VARIANT_INTEGERS", "HOLD_TOLERANCE", "HOLD_MAX",
           "AUTO_NEIGHBOURS_2D", "LOCAL_COURANT", "LOCAL_GROWTH"]

#: ``score_every="adaptive"``: the defaults of ``hold_tolerance`` and ``hold_max`` (see :class:`ParVISampler`).
HOLD_TOLERANCE, HOLD_MAX = 0.02, 4  # measured: reproductions/parvi-adaptive-hold/
#: The default ``n_neighbours`` ("auto") in 2D, where it was measured (reproductions/parvi-rest-vs-time/); in other
#: dimensions "auto" is the model's own default (12 is below the kernel's self-weight bound from 4-D on).
AUTO_NEIGHBOURS_2D = 12

#: The default configuration (issue 31): score force, isothermal EOS with alpha = c0^2 (stationary density p), local
#: time steps, the critical friction, the per-particle score hold lengthened with M, ``n_neighbours="auto"`` (12 in
#: 2D) and a fixed budget of ``steps = 1000`` score evaluations per particle: the configuration that met every 2D
#: goal (reproductions/parvi-rest-vs-time/: <= 0.94x i.i.d. at M = 500 on six 2D targets, 3 seeds). The API's
#: :func:`sample` / :class:`ParVISampler` and ``sphrelax sample`` share it, length included.
DEFAULTS = dict(formulation="force", eos="isothermal", alpha=1.0, h="adaptive", viscosity="linear",
                viscosity_alpha=0.1, friction="critical", steps=1000, courant=0.5, rule="final", time_step="local",
                score_every="adaptive", hold_max="scaled", n_neighbours="auto")

#: The configuration that was the default before issue 31 (global CFL step, friction 1 / the target's scale, the
#: score at every step, the model's default neighbour number, 600 steps): ``ParVISampler(..., **CLASSIC)`` or
#: ``--variant classic`` reproduces those runs bit for bit (``check=False`` also restores the old meaning of
#: ``converged``, the fluid at rest, without the verdict's evidence; CLASSIC leaves the check on).
CLASSIC = dict(time_step="global", friction=None, score_every=1, hold_max=HOLD_MAX, n_neighbours=None, steps=600)

#: ``courant`` of ``time_step="local"`` (measured: 0.5 lets the funnel's mouth burst, 0.25 settles it).
LOCAL_COURANT = 0.25
#: ``time_step="local"``: None, or the factor by which a particle's step may grow per step (it may shrink at
#: once). An experiment (reproductions/parvi-steps/): 1.05 removes the kinetic-energy bursts of the banana
#: but did not lower the energy distances at 1000 steps; off by default.
LOCAL_GROWTH = None


#: The named ingredients of the issue-18 variants, joined by "+" in :func:`variant_options`.
VARIANT_TOKENS = dict(default={}, classic=CLASSIC, whiten=dict(whiten="covariance"), local=dict(time_step="local"),
                      critical=dict(friction="critical"), coarse=dict(coarse_to_fine=4, score_every=1),
                      knn=dict(neighbours="knn"),
                      **{"score_every=adaptive": dict(score_every="adaptive")},
                      **{"hold_max=scaled": dict(hold_max="scaled")},
                      **{"knn-ratio": dict(neighbours="knn-ratio")}, mala=dict(finish="mala"),
                      radial=dict(finish="radial"))
#: Numeric options a variant may set as ``name=value`` tokens.
VARIANT_NUMBERS = ("friction", "courant", "whiten_every", "whiten_until", "friction_every", "friction_ramp",
                   "coarse_to_fine", "coarse_share", "score_every", "k", "hold_tolerance", "hold_max", "n_neighbours",
                   "finish_steps")
#: Numeric variant options that are integers.
VARIANT_INTEGERS = ("whiten_every", "friction_every", "coarse_to_fine", "score_every", "k", "hold_max",
                    "finish_steps")
