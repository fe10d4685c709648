"""The resting-variance check the SPH-ParVI variant tests share (not part of the package)."""
import pytest

from ase_sphrelax.sampling.theory import predicted_gaussian_moments


def assert_rests_at_the_predicted_variance(variant, reference, dim):
    """A variant keeps the stationary density: on the unit Gaussian its resting variance (mean over the axes) is
    the predicted one (theory.py) within 5 % and the reference run's (K = 1, the default) within 3 %."""
    predicted = predicted_gaussian_moments("force", "isothermal", dim)["variance"]
    var_variant, var_reference = (res.samples.var(axis=0).mean() for res in (variant, reference))
    assert var_variant == pytest.approx(predicted, rel=0.05)
    assert var_variant == pytest.approx(var_reference, rel=0.03)
