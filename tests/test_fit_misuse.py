"""`fit` misuse of battery section 7 (issue 33), refused by name before any solve: free entries that move one
element twice, and fewer residuals than free parameters (which ended "converged" with a finite standard error from
m − n = −1)."""

import numpy as np
import pytest

import pamjax
from pamjax import PamjaxInputError, presets


@pytest.mark.parametrize("free", [["valve.coefficients", "valve.coefficients[1,0]"],
                                  ["valve.coefficients[1,0]", "valve.coefficients"]])
def test_free_entries_that_overlap_are_refused(free):
    # the whole array frees m4 too: it was fitted twice, with the warning "parameter m4 has no effect on the data"
    with pytest.raises(PamjaxInputError, match=r"free names valve\.coefficients\[1,0\] twice"):
        pamjax.ParameterSpace(presets.mas10_system("averaged"), free)
    assert pamjax.ParameterSpace(presets.mas10_system("averaged"),
                                 ["valve.coefficients[1,0]", "valve.coefficients[2,0]"]).labels  # disjoint: fine


def test_fewer_residuals_than_free_parameters_is_refused():
    model = presets.mas10_system("averaged")
    rec = pamjax.synthetic_recording(model, pamjax.Constant(0.5), np.array([0.0, 0.05]),
                                     noise=dict(pressure=2e3, position=1e-4), seed=0)
    exp = pamjax.Experiment(rec, pamjax.Constant(0.5), channels=["pressure", "position"],
                            scales=dict(pressure=2e3, position=1e-4))
    free = ["friction.coulomb_force", "muscle.volume_law.v0", "muscle.volume_law.v1", "muscle.force_law.k0",
            "friction.viscous_coefficient"]
    with pytest.raises(PamjaxInputError, match=r"give 4 residuals .* for 5 free parameters"):
        pamjax.fit(model, [exp], free, progress=False)


def test_max_steps_takes_a_numpy_integer_and_refuses_a_bool():
    # `fit(max_steps=np.int64(3))` was refused as "max_steps must be a positive int, got 3"
    from pamjax._fit.fit import _validate

    exp = pamjax.Experiment(pamjax.Recording(np.linspace(0.0, 0.1, 5), {"pressure": np.full(5, 2e5)}),
                            pamjax.Constant(0.5))
    assert _validate([exp], np.int64(3), None, False, None, None) == [exp]
    for bad in (True, 0, 2.5):
        with pytest.raises(PamjaxInputError, match=r"max_steps must be a positive int"):
            _validate([exp], bad, None, False, None, None)
