"""An antagonistic pair of DMSP-40 muscles, each fed by its own VPPM regulator (ISO 6358 flow limits), drives
an ankle joint along a gait-like trajectory (paper 001's future work) at stride frequencies in the human gait band
(0.125-1.5 Hz). Feed-forward only: at each instant the static map gives the pressure pair that holds the reference
angle at a fixed pressure sum (co-contraction, which sets the stiffness); the calibration (1.01 bar/V) turns them
into reference voltages (`run`). Command line: `fits/ankle.py`; in the gallery: `p001_04_ankle`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import pamjax as pj

P_ATM = 101325.0
GAIN = 1.01e5  # Pa/V, eq. 6 static gain


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
def _initial_state(joint, p_flexor, p_extensor):
    return joint.initial_state(p_flexor, p_extensor)


@eqx.filter_jit
def _stiffness(joint, angle, p_flexor, p_extensor):
    return jax.vmap(joint.stiffness)(angle, p_flexor, p_extensor)


def run(joint, f, pressure_sum, rate=200.0, solver=None):
    cycles = 1.0 if f < 0.3 else 2.0
    t = np.arange(0.0, cycles / f, 1.0 / rate)
    theta = gait_angle(t, f)
    pressures = _pressures_for(joint, jnp.asarray(theta), jnp.asarray(pressure_sum, dtype=float))
    pressures = [np.asarray(p) for p in pressures]
    volts = [np.clip((p - P_ATM) / GAIN, 0.0, 10.0) for p in pressures]
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
