"""`BraidVolume` (`pamjax._physics.muscle`, paper 000 eq. 3) against a NumPy transcription of eq. 1-3, the virtual-work
identity eq. 4 → eq. 5 by autodiff, the datasheet construction, finite-difference gradients and bad input."""

import equinox as eqx
import jax
import numpy as np
import pytest
from helpers import central_difference, flat_parameters, np_chou_hannaford

import pamjax as pj

B, N, L0 = 0.39, 7.9, 0.3  # m, turns, m: the MAS-10-300 braid (BraidVolume.from_datasheet(0.3, 0.01, 0.25))

# The volume and its derivative jitted once per shape, the positions as array arguments: called eagerly, every
# operation would compile a program of its own.
_volume = eqx.filter_jit(lambda volume, x: volume.volume(x))
_volumes = eqx.filter_jit(lambda volume, x: jax.vmap(volume.volume)(x))
_volume_slopes = eqx.filter_jit(lambda volume, x: jax.vmap(jax.grad(volume.volume))(x))


def np_eq3(x, b, n, length0):
    """Paper 000 eq. 3 with eq. 1: V = b³/(4π n²) cos θ sin²θ, cos θ = L/b, L = L0 − x."""
    cos = (length0 - np.asarray(x)) / b
    return b**3 / (4 * np.pi * n**2) * cos * (1 - cos**2)


def test_matches_eq3():
    x = np.linspace(-0.02, 0.075, 11)
    got = np.asarray(_volumes(pj.BraidVolume(B, N, L0), x))
    np.testing.assert_allclose(got, np_eq3(x, B, N, L0), rtol=1e-13)  # same formula, rearranged: round-off only


def test_virtual_work_gives_eq5():
    """Eq. 4: F = −p dV/dL = p_g dV/dx for x = L0 − L; with eq. 3 this is eq. 5 (Chou-Hannaford), exactly."""
    volume = pj.BraidVolume(B, N, L0)
    x = np.linspace(-0.02, 0.075, 9)
    p_gauge = 4e5
    virtual = p_gauge * np.asarray(_volume_slopes(volume, x))
    np.testing.assert_allclose(virtual, np_chou_hannaford(x, p_gauge, B, N, L0), rtol=1e-12, atol=1e-9)


def test_from_datasheet():
    """V(0) is the datasheet's cylinder π D² L0/4, and eq. 5 on the same braid vanishes at the maximum contraction."""
    volume = pj.BraidVolume.from_datasheet(0.3, 0.01, 0.25)
    assert float(_volume(volume, np.asarray(0.0))) == pytest.approx(np.pi / 4 * 0.01**2 * 0.3, rel=1e-12)
    force = pj.ChouHannafordForce(volume.strand_length, volume.turns, volume.nominal_length)
    static_force = eqx.filter_jit(lambda force, x, p: force.static_force(x, p))  # one program (eagerly: one per op)
    assert abs(float(static_force(force, np.asarray(0.25 * 0.3), np.asarray(6e5)))) < 1e-9
    assert float(volume.strand_length) == pytest.approx(0.3897, abs=1e-4)  # √3 · 0.75 · 0.3 m


def test_gradients_match_finite_differences():
    flat, rebuild = flat_parameters(pj.BraidVolume(B, N, L0))
    f = jax.jit(lambda v: rebuild(v).volume(0.03))  # one program for the gradient's points (eagerly: one per op)
    np.testing.assert_allclose(np.asarray(jax.jit(jax.grad(lambda v: f(v)))(flat)), central_difference(f, flat),
                               rtol=1e-6)


def test_usable_as_a_muscle_volume():
    muscle = pj.Muscle(pj.ChouHannafordForce(B, N, L0), pj.BraidVolume(B, N, L0), min_position=-0.02,
                       max_position=0.075)
    volume_slope = eqx.filter_jit(lambda muscle, x: muscle.volume_slope(x))  # one program (eagerly: one per op)
    assert float(volume_slope(muscle, np.asarray(0.0))) > 0  # the volume grows as the muscle contracts (θ < 54.7°)


def test_bad_input_is_named():
    with pytest.raises(pj.PamjaxInputError, match="strand_length"):
        pj.BraidVolume(0.29, N, 0.3)  # cos θ = L/b_s > 1
    with pytest.raises(pj.PamjaxInputError, match="turns"):
        pj.BraidVolume(B, -1.0, L0)
    with pytest.raises(pj.PamjaxInputError, match="max_contraction"):
        pj.BraidVolume.from_datasheet(0.3, 0.01, 0.5)  # above 1 − 1/√3: no braid reaches it
