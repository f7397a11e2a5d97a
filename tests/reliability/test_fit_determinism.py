"""Determinism of `fit` (issue 7, item 6): the same inputs give the same fit, bitwise; a fit stopped after k
iterations with its state checkpointed and then resumed ends bitwise where an uninterrupted fit ends.

Problem: the synthetic MAS-10 static force map (9 lengths × 7 pressures, 2 N noise), 7 free parameters (F_max at
five nodes, k0, k1) from 30 % low: 8 Levenberg-Marquardt iterations, three of them rejected trial steps (so the
trust region's state matters on resume); a few seconds with compilation."""

import jax.numpy as jnp
import numpy as np
import pytest

import pamjax as pj
from pamjax import PamjaxInputError, presets

FREE = ["force_law.max_force_coefficients", "force_law.k0", "force_law.k1"]


def _problem(seed=0):
    muscle = presets.mas10_muscle()
    x, p = np.meshgrid(np.linspace(-0.01, 0.07, 9), 101325.0 + np.linspace(0.5e5, 6e5, 7), indexing="ij")
    x, p = x.ravel(), p.ravel()
    f = np.asarray(muscle.static_force(jnp.asarray(x), jnp.asarray(p), pj.Air()))
    f = f + 2.0 * np.random.default_rng(seed).standard_normal(f.shape)
    exp = pj.ForceMapExperiment(x, p, np.maximum(f, 0.0), scale=2.0)
    space = pj.ParameterSpace(muscle, FREE)
    start = space.with_values(np.asarray(space.initial_values()) * 0.7)
    return start, exp


def _fields(res):
    """Every stored field except wall times, for exact (bitwise for floats) comparison."""
    d = res.to_dict()
    del d["fit_s"], d["compile_s"]
    return d


@pytest.fixture(scope="module")
def reference():
    start, exp = _problem()
    return pj.fit(start, [exp], FREE, max_steps=30, progress=False)


def test_same_inputs_same_fit_bitwise(reference):
    start, exp = _problem()  # rebuilt from the same seed
    again = pj.fit(start, [exp], FREE, max_steps=30, progress=False)
    assert reference.converged and reference.iterations > 6, reference.status
    assert _fields(again) == _fields(reference)
    other = pj.fit(*_problem(seed=1), FREE, max_steps=30, progress=False)  # the comparison can fail
    assert _fields(other) != _fields(reference)


@pytest.mark.parametrize("stop_after", [1, 6])  # 6: inside the run of rejected steps
def test_interrupted_and_resumed_fit_ends_bitwise_where_uninterrupted_ends(reference, tmp_path, stop_after):
    start, exp = _problem()
    path = tmp_path / "fit_state.npz"
    part = pj.fit(start, [exp], FREE, max_steps=stop_after, progress=False, checkpoint=path)
    assert part.status == "max_steps" and part.iterations == stop_after and path.exists()
    assert part.history == reference.history[: stop_after + 1]
    # a fresh start model object (the checkpoint, not the model, carries the state), same problem
    start, exp = _problem()
    resumed = pj.fit(start, [exp], FREE, max_steps=30, progress=False, resume=path, checkpoint=path)
    assert resumed.iterations == reference.iterations
    assert resumed.cost == reference.cost and resumed.values == reference.values
    assert _fields(resumed) == _fields(reference)
    np.testing.assert_array_equal(resumed.model.force_law.max_force_coefficients,
                                  reference.model.force_law.max_force_coefficients)
    # resuming a finished fit changes nothing
    again = pj.fit(start, [exp], FREE, max_steps=30, progress=False, resume=path)
    assert _fields(again) == _fields(reference)


def test_checkpoint_is_never_silently_replaced(tmp_path):
    start, exp = _problem()
    path = tmp_path / "user_file.npz"
    path.write_bytes(b"not mine to replace")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        pj.fit(start, [exp], FREE, max_steps=1, progress=False, checkpoint=path)
    assert path.read_bytes() == b"not mine to replace"
    pj.fit(start, [exp], FREE, max_steps=1, progress=False, checkpoint=path, overwrite=True)
    assert path.read_bytes() != b"not mine to replace"


def test_resume_from_another_problem_is_named(tmp_path):
    start, exp = _problem()
    path = tmp_path / "state.npz"
    pj.fit(start, [exp], FREE, max_steps=1, progress=False, checkpoint=path)
    with pytest.raises(PamjaxInputError, match="resume: .* saved for parameters"):
        pj.fit(start, [exp], FREE[:2], max_steps=3, progress=False, resume=path)
    with pytest.raises(PamjaxInputError, match="resume: .* does not exist"):
        pj.fit(start, [exp], FREE, progress=False, resume=tmp_path / "missing.npz")
