"""An antagonistic pair of DMSP-40 muscles, each fed by its own VPPM regulator (ISO 6358 flow limits), drives
an ankle joint along a gait-like trajectory (paper 001's future work) at stride frequencies in the human gait band
(0.125-1.5 Hz). Feed-forward only: at each instant the static map gives the pressure pair that holds the reference
angle at a fixed pressure sum (co-contraction, which sets the stiffness); each regulator's inverse calibration (1.01
bar/V by default) turns them into reference voltages (`run`). Command line: `fits/ankle.py`; in the gallery:
`p001_04_ankle`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import pamjax as pj

VOLTAGE_RANGE = (0.0, 10.0)  # V, the VPPM's reference input (paper 001, Sect. 2)


def gait_angle(t, f):
    """A gait-like ankle angle [rad]: plantarflexion push-off and dorsiflexion swing (two harmonics, ±≈15°)."""
    w = 2 * np.pi * f * t
    return 0.18 * np.sin(w) + 0.08 * np.sin(2 * w + 1.0)


# Compiled once per joint structure and array shape (the joint, angles, pressure sum and pressures are arguments,
# not constants of the program): eager calls compile every operation of the static map and of eq. 9's stiffness
# anew, and a `jax.jit(lambda ...)` built inside `run` compiles again on every call.
@eqx.filter_jit
def _pressures_for(joint, angles, pressure_sum):
    """The static map's pressure pair holding each angle of `angles` at the gauge `pressure_sum`."""
    return jax.vmap(lambda a: joint.pressures_for(a, pressure_sum))(angles)


@eqx.filter_jit
def _voltages(joint, p_flexor, p_extensor):
    """Each regulator's reference voltage [V] for its ABSOLUTE pressures [Pa] (its inverse calibration)."""
    p_atm = joint.air.atmospheric_pressure
    return (joint.flexor_regulator.calibration.inverse(p_flexor - p_atm),
            joint.extensor_regulator.calibration.inverse(p_extensor - p_atm))


@eqx.filter_jit
def _initial_state(joint, p_flexor, p_extensor):
    return joint.initial_state(p_flexor, p_extensor)


@eqx.filter_jit
def _stiffness(joint, angle, p_flexor, p_extensor):
    return jax.vmap(joint.stiffness)(angle, p_flexor, p_extensor)


def check_run(joint, f, pressure_sum):
    """`run`'s arguments, concretely, before anything is compiled (inside `run`'s compiled static map the joint's
    own checks cannot run): `f` [Hz] a finite number > 0; `pressure_sum` [Pa] a GAUGE sum that holds the gait's
    extreme angles (`AntagonisticJoint.pressures_for`, called with concrete values: a sum in bar, negative, or too
    small for the angle is refused, the range it holds named) without asking either regulator for more than its
    `max_gauge_pressure` (beyond it the voltage would be clipped silently). Raises `PamjaxInputError`."""
    if not (np.ndim(f) == 0 and np.isfinite(f) and f > 0):
        raise pj.PamjaxInputError(f"f (the stride frequency) must be a finite number > 0 [Hz], got {f!r}")
    if not (np.ndim(pressure_sum) == 0 and np.isfinite(pressure_sum)):
        raise pj.PamjaxInputError(f"pressure_sum must be one finite GAUGE pressure sum [Pa], got {pressure_sum!r}")
    theta = gait_angle(np.linspace(0.0, 1.0, 2001), 1.0)  # one stride: its shape does not depend on f
    regulators = (joint.flexor_regulator, joint.extensor_regulator)
    limits = [r.max_gauge_pressure(joint.air) for r in regulators]
    if any(limit is None for limit in limits):
        raise pj.PamjaxInputError("the ankle run needs regulators with a VoltageCalibration (ISO6358Regulator, "
                                  f"LinearRegulator), got {[type(r).__name__ for r in regulators]}")
    p_max = float(min(limits))
    p_atm = float(joint.air.atmospheric_pressure)
    for angle in (float(theta.min()), float(theta.max())):
        highest = max(float(p) - p_atm for p in joint.pressures_for(angle, float(pressure_sum)))
        if highest > p_max:
            raise pj.PamjaxInputError(
                f"pressure_sum {float(pressure_sum):g} Pa asks for a gauge pressure of {highest:.4g} Pa at "
                f"{angle:.3f} rad, above the regulators' {p_max:.4g} Pa (their 10 V and their supply): the voltage "
                "would be clipped and the angle missed; take a smaller sum")


def run(joint, f, pressure_sum, rate=200.0, solver=None):
    """Feed-forward along `gait_angle` at stride frequency `f` [Hz] (one stride below 0.3 Hz, two above) with the
    gauge `pressure_sum` [Pa], sampled at `rate` [Hz]: a dict of the times, reference, simulated angle, pressures,
    closed-chamber stiffness and the angle RMSE [rad]. The arguments are checked first (`check_run`)."""
    check_run(joint, f, pressure_sum)
    cycles = 1.0 if f < 0.3 else 2.0
    t = np.arange(0.0, cycles / f, 1.0 / rate)
    theta = gait_angle(t, f)
    pressures = _pressures_for(joint, jnp.asarray(theta), jnp.asarray(pressure_sum, dtype=float))
    volts = [np.clip(np.asarray(v), *VOLTAGE_RANGE) for v in _voltages(joint, *pressures)]
    pressures = [np.asarray(p) for p in pressures]
    signal = pj.VoltagePair(
        pj.Sampled(jnp.asarray(t), jnp.asarray(volts[0])), pj.Sampled(jnp.asarray(t), jnp.asarray(volts[1]))
    )
    y0 = _initial_state(joint, pressures[0][0], pressures[1][0])
    traj = pj.simulate(joint, signal, jnp.asarray(t), y0=y0, max_steps=500_000, solver=solver)
    angle = np.asarray(traj.angle)
    pressure = np.asarray(traj.pressure)
    stiffness = np.asarray(_stiffness(joint, traj.angle, pressure[:, 0], pressure[:, 1]))
    rmse = float(np.sqrt(np.mean((angle - theta) ** 2)))
    return dict(t=t, reference=theta, angle=angle, pressure=pressure, stiffness=stiffness, rmse=rmse)
