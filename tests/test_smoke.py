"""End-to-end smoke test: the presets simulate and stay physical."""

import jax.numpy as jnp
import numpy as np

import pamjax
from pamjax import presets


def test_tank_inflation_stays_between_atmosphere_and_supply():
    system = presets.mas10_tank_system()
    traj = pamjax.simulate(system, pamjax.Constant(0.5), jnp.linspace(0.0, 1.0, 51))
    p = np.asarray(traj.pressure)
    assert p[0] == 101325.0
    assert np.all(p >= 101325.0 - 1.0) and np.all(p <= presets.SUPPLY_PRESSURE + 1.0)
    assert p[-1] > 3e5  # half duty charges well above atmosphere within 1 s
