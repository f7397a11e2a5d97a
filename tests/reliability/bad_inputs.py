"""A catalogue of distinct bad inputs, each paired with the name the error message must contain.

Each case is a zero-argument callable that must raise `pamjax.PamjaxInputError` (a ValueError) before any solve.
Shared by `test_bad_input_catalogue.py` and `benchmarks/reliability.py` (which reports how many are named).
"""

import jax.numpy as jnp
import numpy as np

import pamjax
from pamjax import presets


def _sim(system=None, signal=None, ts=None, **kwargs):
    system = presets.mas10_system("averaged") if system is None else system
    signal = pamjax.Constant(0.5) if signal is None else signal
    ts = jnp.linspace(0.0, 0.1, 3) if ts is None else ts
    return lambda: pamjax.simulate(system, signal, ts, **kwargs)


CORE_CASES = {
    # parameters (constructor checks)
    "negative payload mass": (
        lambda: pamjax.MuscleSystem(presets.mas10_valve(), presets.mas10_muscle(), -1.0),
        "payload_mass",
    ),
    "zero tank volume": (lambda: pamjax.TankSystem(presets.mas10_valve(), 0.0), "volume"),
    "negative orifice area": (lambda: pamjax.EllipseRestriction(0.36, 0.28, -3e-6), "area"),
    "critical ratio above 1": (lambda: pamjax.EllipseRestriction(0.36, 1.2), "critical_ratio"),
    "critical ratio 0": (lambda: pamjax.EllipseRestriction(0.36, 0.0), "critical_ratio"),
    "negative discharge coefficient": (lambda: pamjax.EllipseRestriction(-0.36, 0.28), "discharge_coefficient"),
    "ISO 6358 b out of range": (lambda: pamjax.ISO6358Restriction(7e-9, 1.5), "critical_ratio"),
    "ISO 6358 negative C": (lambda: pamjax.ISO6358Restriction(-7e-9, 0.5), "sonic_conductance"),
    "zero PWM frequency": (lambda: presets.mas10_valve(pwm_frequency=0.0), "pwm_frequency"),
    "negative switch delay": (lambda: presets.mas10_valve(switch_on_delay=-1e-3), "switch_on_delay"),
    "unknown valve mode": (lambda: presets.mas10_valve(mode="fast"), "mode"),
    "negative supply pressure": (lambda: presets.mas10_valve(supply_pressure=-6.5e5), "supply_pressure"),
    "NaN supply pressure": (lambda: presets.mas10_valve(supply_pressure=np.nan), "supply_pressure"),
    "averaged valve wrong shape": (lambda: pamjax.AveragedValve(jnp.zeros(9)), "coefficients"),
    "quartic with 4 coefficients": (
        lambda: pamjax.PolynomialForce(jnp.zeros(4), 1.0, 1.0, 1e5),
        "max_force_coefficients",
    ),
    "k2 zero": (lambda: pamjax.PolynomialForce(jnp.zeros(5), 1.0, 1.0, 0.0), "k2"),
    "negative v0": (lambda: pamjax.LinearVolume(-1e-5, 1e-4), "v0"),
    "stroke limits reversed": (
        lambda: pamjax.Muscle(presets.mas10_muscle().force_law, presets.mas10_muscle().volume_law, 0.1, -0.02),
        "max_position",
    ),
    "braid angle 100 degrees": (lambda: pamjax.TonduLopezForce(0.005, np.deg2rad(100.0), 0.3), "braid_angle"),
    "negative Coulomb force": (lambda: pamjax.CoulombViscousFriction(-16.0), "coulomb_force"),
    "zero friction width": (lambda: pamjax.CoulombViscousFriction(16.0, 250.0, 0.0), "velocity_width"),
    "polytropic index 2": (
        lambda: pamjax.TankSystem(presets.mas10_valve(), 5e-5, polytropic_index=2.0),
        "polytropic_index",
    ),
    "negative temperature": (lambda: pamjax.Air(temperature=-293.0), "temperature"),
    # signals
    "duty above 1": (_sim(signal=pamjax.Constant(1.2)), "signal"),
    "duty below 0 in triangle": (_sim(signal=pamjax.Triangle(-0.1, 0.9, 0.1)), "signal"),
    "sine leaving [0, 1]": (_sim(signal=pamjax.Sine(0.5, 0.6, 1.0)), "signal"),
    "NaN constant duty": (lambda: pamjax.Constant(np.nan), "Constant.value"),
    "triangle zero frequency": (lambda: pamjax.Triangle(0.05, 0.95, 0.0), "Triangle.frequency"),
    "sampled length mismatch": (lambda: pamjax.Sampled(jnp.linspace(0, 1, 5), jnp.zeros(4)), "Sampled.values"),
    "sampled times not increasing": (lambda: pamjax.Sampled(jnp.array([0.0, 0.2, 0.1]), jnp.zeros(3)), "Sampled.times"),
    # time grids and initial states
    "non-increasing ts": (_sim(ts=jnp.array([0.0, 0.2, 0.1])), "ts"),
    "NaN in ts": (_sim(ts=jnp.array([0.0, np.nan, 0.2])), "ts"),
    "2-D ts": (_sim(ts=jnp.zeros((2, 2))), "ts"),
    "t0 after ts[0]": (_sim(t0=0.5), "t0"),
    "zero rtol": (_sim(rtol=0.0), "rtol"),
    "negative atol": (_sim(atol=-1e-6), "atol"),
    "NaN first step": (_sim(dt0=np.nan), "dt0"),
    "negative absolute pressure in y0": (
        _sim(y0=pamjax.MuscleState(jnp.asarray(-1e5), jnp.asarray(0.0), jnp.asarray(0.0))),
        "y0.pressure",
    ),
    "NaN in y0": (_sim(y0=pamjax.MuscleState(jnp.asarray(1e5), jnp.asarray(np.nan), jnp.asarray(0.0))), "y0"),
    "not a system": (lambda: pamjax.simulate("MAS-10", pamjax.Constant(0.5), jnp.linspace(0, 1, 3)), "system"),
    "unknown preset valve": (lambda: presets.mas10_system(valve="proportional"), "valve"),
    "unknown preset friction": (lambda: presets.mas10_system(friction="stiction"), "friction"),
    "volume negative at full stretch": (
        lambda: pamjax.Muscle(presets.mas10_muscle().force_law, pamjax.LinearVolume(2e-6, 4e-4), -0.02, 0.075),
        "volume_law",
    ),
    "laminar ratio of 1 (ISO 6358)": (lambda: pamjax.ISO6358Restriction(4e-9, 0.3, laminar_ratio=1.0), "laminar_ratio"),
    "laminar ratio of 1 (nozzle)": (lambda: pamjax.NozzleRestriction(0.8, laminar_ratio=1.0), "laminar_ratio"),
}
