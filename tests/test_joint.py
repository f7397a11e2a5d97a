"""Antagonistic joint: angle follows the pressure difference, stiffness the pressure sum (paper 001, Sect. 7)."""

import re

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import initial_state

import pamjax
from pamjax._physics.regulator import ISO6358Regulator
from pamjax._systems.joint import AntagonisticJoint, VoltagePair
from pamjax.presets import dmsp40_muscle

P_ATM = 101325.0


@pytest.fixture(scope="module")
def joint():
    m = dmsp40_muscle()
    return AntagonisticJoint(ISO6358Regulator(), ISO6358Regulator(), m, m, foot_mass=0.0)


@eqx.filter_jit
def _equilibrium(joint, pf, pe):
    angle = joint.equilibrium_angle(pf, pe)
    return angle, joint.stiffness(angle, pf, pe)


def _state(joint, total, difference):
    pf, pe = P_ATM + 0.5 * (total + difference), P_ATM + 0.5 * (total - difference)
    angle, stiffness = _equilibrium(joint, jnp.asarray(pf), jnp.asarray(pe))
    return float(angle), float(stiffness)


def _equilibrium_angle(joint, pf, pe):
    """`joint.equilibrium_angle` through the jitted `_equilibrium` (eagerly, each call re-traces and compiles its
    bisection loop); the pressures go in as arrays of Python floats, so every test shares the one program."""
    return float(_equilibrium(joint, jnp.asarray(float(pf)), jnp.asarray(float(pe)))[0])


# The chambers' volumes, the torque and the static inverse jitted likewise (eagerly, each of their operations compiles a
# program of its own), the angles and pressures as array arguments (Python floats would be constants of the program).
@eqx.filter_jit
def _volumes(joint, angle):
    xf, xe = joint.contractions(angle)
    return joint.flexor.volume(xf), joint.extensor.volume(xe)


_torque = eqx.filter_jit(lambda joint, angle, pf, pe: joint.torque(angle, pf, pe))
_pressures_for = eqx.filter_jit(lambda joint, angle, total: joint.pressures_for(angle, total))


def test_angle_follows_difference_and_stiffness_follows_sum(joint):
    sums = [3e5, 5e5, 7e5]
    diffs = [-0.4e5, 0.0, 0.4e5, 0.8e5]
    angle = np.array([[_state(joint, s, d)[0] for d in diffs] for s in sums])
    stiff = np.array([[_state(joint, s, d)[1] for d in diffs] for s in sums])
    np.testing.assert_allclose(angle[:, 1], 0.0, atol=1e-12)  # equal pressures: θ = 0 whatever the sum
    assert np.all(np.diff(angle, axis=1) > 0)  # angle rises with the difference at every sum
    assert np.all(np.diff(stiff, axis=0) > 0)  # stiffness rises with the sum at every difference
    # the sum sets stiffness far more than the difference does: relative spread across sums vs across differences
    across_sums = (stiff[-1] - stiff[0]) / stiff.mean(axis=0)
    across_diffs = np.abs(stiff[:, -1] - stiff[:, 1]) / stiff.mean(axis=1)
    assert across_sums.min() > 3 * across_diffs.max()


def test_joint_stiffness_is_minus_torque_slope_with_closed_chambers(joint):
    pf, pe = P_ATM + 3e5, P_ATM + 2e5
    # the equilibrium angle and joint.stiffness at that angle, both from the jitted `_equilibrium`
    a, stiffness = (float(v) for v in _equilibrium(joint, jnp.asarray(pf), jnp.asarray(pe)))
    h = 1e-6
    vf, ve = (float(v) for v in _volumes(joint, np.asarray(a)))

    def tau(angle):  # closed isothermal chambers: p V = const
        vf2, ve2 = (float(v) for v in _volumes(joint, np.asarray(angle)))
        return float(_torque(joint, np.asarray(angle), np.asarray(pf * vf / vf2), np.asarray(pe * ve / ve2)))

    fd = -(tau(a + h) - tau(a - h)) / (2 * h)
    assert stiffness == pytest.approx(fd, rel=1e-6)


def test_simulated_joint_settles_at_static_equilibrium(joint):
    y0 = initial_state(joint, flexor_pressure=np.asarray(P_ATM + 2e5), extensor_pressure=np.asarray(P_ATM + 2e5))
    sig = VoltagePair(pamjax.Constant(3.0), pamjax.Constant(1.5))
    traj = pamjax.simulate(joint, sig, jnp.linspace(0.0, 1.0, 11), y0=y0)
    pf, pe = (float(p) for p in np.asarray(traj.pressure)[-1])
    # each regulator delivers its calibrated pressure (1.01 bar/V) ...
    assert pf == pytest.approx(P_ATM + 3.0 * 1.01e5, abs=300)
    assert pe == pytest.approx(P_ATM + 1.5 * 1.01e5, abs=300)
    # ... and the joint rests where the static torque vanishes
    angle = np.asarray(traj.angle)
    assert float(angle[-1]) == pytest.approx(_equilibrium_angle(joint, pf, pe), abs=1e-3)
    assert float(angle[-1]) > 0.1


def test_pressures_for_inverts_the_static_map(joint):
    pf, pe = (float(p) for p in _pressures_for(joint, np.asarray(0.15), np.asarray(5e5)))
    assert float(pf + pe - 2 * P_ATM) == pytest.approx(5e5, rel=1e-9)
    assert _equilibrium_angle(joint, pf, pe) == pytest.approx(0.15, abs=1e-6)


def test_joint_command_shape_is_checked(joint):
    with pytest.raises(pamjax.PamjaxInputError, match="shape \\(2,\\)"):
        joint.vector_field(0.0, initial_state(joint), jnp.asarray(3.0))


def test_equilibrium_angle_refuses_pressures_that_hold_no_angle_in_its_range(joint):
    """The torque keeps one sign over [−0.6, 0.6] rad: refused with the torques at both ends (it returned 1.04 rad,
    where 57.7 N m remained, from an unguarded Newton step); initial_state says so too. Traced, the angle stays in the
    range (the Newton step is clamped to it)."""
    with pytest.raises(pamjax.PamjaxInputError, match=r"flexor_pressure 800000 Pa and extensor_pressure 101325 Pa "
                                                      r"hold the joint at no angle in \[−0.6, 0.6\] rad .* the static "
                                                      r"torque is 253.6 N m at −0.6 rad and 88.42 N m at 0.6 rad"):
        joint.equilibrium_angle(8e5, P_ATM)
    with pytest.raises(pamjax.PamjaxInputError, match=r"AntagonisticJoint.initial_state: flexor_pressure 800000 Pa .* "
                                                      r"or give the start `angle`"):
        joint.initial_state(8e5, P_ATM)
    assert _equilibrium_angle(joint, 8e5, P_ATM) == pytest.approx(0.6, abs=1e-12)
    assert _equilibrium_angle(joint, P_ATM, 8e5) == pytest.approx(-0.6, abs=1e-12)


@pytest.mark.parametrize("call, match", [
    (lambda j: j.equilibrium_angle(3.5, 3.0), "flexor_pressure is 3.5 Pa at most: that looks like bar"),
    (lambda j: j.equilibrium_angle(3e5, 3e4), "extensor_pressure is 30000 Pa at most.*GAUGE"),
    (lambda j: j.equilibrium_angle(np.nan, 3e5), "flexor_pressure must be finite"),
    (lambda j: j.initial_state(3.0, 3.0), "flexor_pressure is 3 Pa at most: that looks like bar"),
    (lambda j: j.initial_state(3e5, 0.0, angle=0.0), "extensor_pressure is 0 Pa at most"),
    (lambda j: j.pressures_for(0.1, 5.0), r"pressure_sum must be a GAUGE pressure sum >= 1000 Pa .* looks like bar"),
    (lambda j: j.pressures_for(0.1, -5e5), r"pressure_sum must be .* got -500000.0: negative"),
    (lambda j: j.pressures_for(np.nan, 5e5), "angle must be finite"),
])
def test_pressures_in_bar_or_gauge_and_bad_sums_are_named(joint, call, match):
    """Refused by name before anything is computed (each was accepted: bar gave an angle, a negative sum a negative
    absolute pressure, NaN a NaN)."""
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        call(joint)


def test_pressures_for_refuses_an_angle_its_sum_cannot_hold(joint):
    """A 1 bar sum holds at most ±0.245 rad: 0.3 rad is refused with that range (it returned (201325, 101325) Pa,
    which hold 0.245 rad); reachable angles still invert the static map."""
    with pytest.raises(pamjax.PamjaxInputError, match=r"angle 0.3 rad cannot be held with pressure_sum 100000 Pa: that "
                                                      r"sum holds the joint from -0.245 rad .* to 0.245 rad"):
        joint.pressures_for(0.3, 1e5)
    pf, pe = (float(p) for p in joint.pressures_for(0.2, 1e5))
    assert _equilibrium_angle(joint, pf, pe) == pytest.approx(0.2, abs=1e-6)


_M = dmsp40_muscle()
_R = ISO6358Regulator


@pytest.mark.parametrize("build, match", [
    (lambda: AntagonisticJoint(_R(), _R(), _M, _M, polytropic_index=0.0),
     r"AntagonisticJoint\.polytropic_index must be in the open interval \(0\.99, 1\.41\), got 0"),
    (lambda: AntagonisticJoint(_R(), _R(), _M, _M, polytropic_index=-1.0), r"polytropic_index .*got -1"),
    (lambda: AntagonisticJoint(_R(), _R(), _M, _M, pulley_radius=30.0),
     r"AntagonisticJoint\.pulley_radius = 30 m: more than 0\.5 m .*looks like mm"),
    (lambda: AntagonisticJoint(_R(), _R(), _M, _M, gravity=np.nan), r"AntagonisticJoint\.gravity must be finite"),
    (lambda: AntagonisticJoint(_R(), _R(), _M, _M, foot_arm=np.nan), r"AntagonisticJoint\.foot_arm must be finite"),
    (lambda: AntagonisticJoint(_R(), _R(), _M, _M, foot_arm=60.0), r"AntagonisticJoint\.foot_arm = 60 m"),
    (lambda: AntagonisticJoint(_R(), _R(), _M, _M, pre_contraction=0.5),
     r"AntagonisticJoint\.pre_contraction = 0\.5 m lies outside the flexor's stroke \[-0\.02, 0\.1\] m"),
    (lambda: AntagonisticJoint(_M, _M, _R(), _R()),
     r"AntagonisticJoint\.flexor_regulator must be a pressure regulator .*got Muscle; the arguments are"),
    (lambda: AntagonisticJoint(_R(), _R(), None, _M), r"AntagonisticJoint\.flexor must be a Muscle .*got NoneType"),
    (lambda: VoltagePair(3.0, 2.0), r"VoltagePair\.flexor must be a pamjax signal .*got float"),
])
def test_a_joint_with_a_bad_part_or_parameter_is_refused_by_name(build, match):
    """Each was accepted: n = -1 drove a pressure to -5.4 bar absolute, a 30 m pulley (mm) gave 2.1e8 N m/rad, NaN
    gravity a NaN stiffness, a pre-contraction outside the stroke was blamed on the pressures later, swapped or
    missing parts and a VoltagePair of numbers ended in raw AttributeErrors at the solve."""
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        build()


@pytest.mark.parametrize("call, match", [
    (lambda j: j.equilibrium_angle(np.array([4e5, 3e5]), np.array([3e5, 4e5])),
     r"equilibrium_angle takes one number each for flexor_pressure, extensor_pressure .*jax\.vmap"),
    (lambda j: j.pressures_for(np.array([0.1, 0.2]), 5e5), r"pressures_for takes one number each for angle"),
    (lambda j: j.pressures_for(0.1, np.array([4e5, 5e5])),
     r"pressures_for takes one number each .*pressure_sum \(2,\)"),
    (lambda j: j.initial_state(3e5, 3e5, angle=20.0),
     r"angle = 20 rad lies outside the joint's range \[-1, 1\] rad .*looks like degrees \(20° = 0\.3491 rad"),
    (lambda j: j.initial_state(3e5, 3e5, angle=np.nan), r"angle must be finite"),
])
def test_one_operating_point_and_a_start_angle_in_range_are_asked_for(joint, call, match):
    """Arrays of pressures or sums ended in a JAX scan-carry TypeError or NumPy's ambiguous truth value; a start angle
    of 20 (degrees) ran into the solve's "minimum step size". Named, before anything is computed."""
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        call(joint)
    assert joint.angle_range() == pytest.approx((-1.0, 1.0))
    assert float(joint.initial_state(3e5, 3e5, angle=0.5).angle) == 0.5


def test_fits_ankle_refuses_bad_frequencies_and_sums_before_any_run(tmp_path, capsys):
    """`fits/ankle.py --frequencies 0` divided by zero, -0.5 gave a traceback, `--sum-bar 0.01` ran silently to an 18.8°
    RMSE and wrote ankle.json, 14 was clipped by the regulators, -3 gave a traceback: each is an argparse error naming
    the option before any run (no output folder); the gallery procedure refuses them too."""
    import importlib.util
    import pathlib

    from pamjax.gallery.procedures import ankle

    path = pathlib.Path(__file__).resolve().parents[1] / "fits" / "ankle.py"
    spec = importlib.util.spec_from_file_location("fits_ankle_under_test", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    out = tmp_path / "out"
    for args, match in ((["--frequencies", "0"], r"--frequencies must be finite stride frequencies > 0"),
                        (["--frequencies", "0.5", "-0.5"], r"--frequencies .*got \[-0\.5\]"),
                        (["--sum-bar", "0.01"], r"--sum-bar 0\.01 .*cannot be held with pressure_sum 1000 Pa"),
                        (["--sum-bar", "14"], r"--sum-bar 14 .*above the regulators' 5\.987e\+05 Pa"),
                        (["--sum-bar", "-3"], r"--sum-bar -3 .*negative")):
        with pytest.raises(SystemExit) as exit_info:
            script.main([*args, "--out", str(out)])
        assert exit_info.value.code == 2
        err = capsys.readouterr().err
        assert re.search(match, err), err
    assert not out.exists()
    joint = AntagonisticJoint(_R(), _R(), _M, _M)
    with pytest.raises(pamjax.PamjaxInputError, match=r"f \(the stride frequency\) must be a finite number > 0"):
        ankle.run(joint, 0.0, 5e5)
