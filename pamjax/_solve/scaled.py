"""The one scaled vector field: a system's named state as the flat vector z = ravel(y / scale) that every integrator
steps (diffrax in `simulate`, the fixed grids, the batched schemes of `sweep`, the stiffness estimates).

Integrating one (n,) array instead of a pytree of scalars cuts the solver's per-step overhead by about a third
(benchmarks/simulate.py), and scaling each state by its typical magnitude (`system.state_scale()`: pressure per
1e5 Pa, position per 1e-2 m, ...) lets one tolerance fit states of different units; the physics still sees the
named state.
"""

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import jax.tree_util as jtu
from jax.flatten_util import ravel_pytree


class Scaled(NamedTuple):
    """The map between a system's named state and its flat, scaled vector: `scale` (n,) and `unravel`."""

    scale: jax.Array
    unravel: Callable

    def state(self, z):
        """The named state y of the flat scaled vector z."""
        return self.unravel(z * self.scale)

    def vector(self, tree):
        """A state-shaped pytree (a state or its rate) as a flat scaled vector."""
        return ravel_pytree(tree)[0] / self.scale

    def field(self, system, t, z, command):
        """dz/dt: the system's vector field at time `t` [s] for `command`, in flat scaled units."""
        return self.vector(system.vector_field(t, self.state(z), command))


def scaled(system, y0):
    """`(z0, Scaled)`: the initial state `y0` of `system` as a flat scaled vector, and the map back."""
    y0 = jtu.tree_map(lambda a: jnp.asarray(a, dtype=float), y0)
    scale = jtu.tree_map(lambda s, a: jnp.broadcast_to(jnp.asarray(s, float), jnp.shape(a)), system.state_scale(), y0)
    flat_scale, _ = ravel_pytree(scale)
    z0, unravel = ravel_pytree(jtu.tree_map(lambda a, s: a / s, y0, scale))
    return z0, Scaled(flat_scale, unravel)
