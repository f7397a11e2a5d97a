"""Seeded random problems across the physical range, shared by the reliability tests and benchmark."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import pamjax
from pamjax import presets

NUMERICAL_SETTINGS = ("edge_width", "velocity_width", "slack_width", "end_stops")


def random_pwm_problem(seed, spread=0.2):
    """The MAS-10 system with the smooth PWM valve, every physical parameter scaled by a seeded factor in
    [1 − spread, 1 + spread], and a constant duty in [0.2, 0.8]."""
    rng = np.random.default_rng(seed)
    system = presets.mas10_system("pwm")
    params, static = eqx.partition(system, eqx.is_inexact_array)
    leaves, treedef = __import__("jax").tree_util.tree_flatten(params)
    scaled = [np.asarray(x) * rng.uniform(1 - spread, 1 + spread, size=np.shape(x)) for x in leaves]
    system = eqx.combine(treedef.unflatten([jnp.asarray(x) for x in scaled]), static)
    # keep quantities with hard physical bounds valid: ratios in (0, 1), polytropic index in [1, 1.4]
    system = eqx.tree_at(lambda s: s.polytropic_index, system, jnp.clip(system.polytropic_index, 1.0, 1.4))
    system = eqx.tree_at(lambda s: s.air.heat_capacity_ratio, system, jnp.asarray(1.4))
    return system, pamjax.Constant(rng.uniform(0.2, 0.8))
