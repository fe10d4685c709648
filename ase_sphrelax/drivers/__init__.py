"""Drivers: the papers' own update rules as ASE optimisers, and scale-aware ASE optimisers.

Names are imported on first use (ASE's optimisers load scipy): add one line to ``_WHERE``.
"""
from ..lazy import lazy_exports

_WHERE = {
    "FanRelaxation": ".fan_relaxation",
    "BIPIPacker": ".bipi_packer",
    "make_optimizer": ".optimizers",
    "OPTIMIZERS": ".optimizers",
    "KeepInDomain": ".keep_inside",
    "NothingRelaxedWarning": ".step_scale",
    "SPHScaleWarning": ".optimizers",
    "ALARICDynamics": ".alaric_dynamics",
    "WVTRelaxation": ".wvt",
    "AFCRelaxation": ".afc",
    "limit_blas_in_steps": ".blas",
}
__all__ = list(_WHERE)
__getattr__, __dir__ = lazy_exports(globals(), _WHERE)
