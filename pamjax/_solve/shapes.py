"""Parameters that hold several values where a system takes one (`payload_mass = [9.6, 9.6]` in a model file, or a
batch built with `eqx.tree_at`): found before any solve, named by their path.

A system's state leaves hold one value each (a pressure, a position, ...). A parameter array with a leading axis too
many broadcasts into the state's rate (the accelerations of two payloads are two), and the solve then fails deep
inside JAX ("scan body function carry input and carry output must have equal types"). Shapes alone tell (one
`jax.eval_shape` of the vector field at the system's `state_scale`, a state of constants: ~20 ms, nothing compiled
or run): the rate has the state's shape, or it does not, and then the parameter whose first entry alone restores it
is the one. Batches of models are what `jax.vmap` and `pamjax.sweep` are for.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._systems.base import AbstractSystem


def _name(path):
    return ".".join(str(getattr(k, "name", getattr(k, "key", getattr(k, "idx", k)))) for k in path)


def _fine(system, command):
    """Whether `system`'s vector field keeps the shape of its state (its `state_scale`, a state of constants), by
    shape inference only (~20 ms)."""
    scale = system.state_scale()
    rate = jax.eval_shape(lambda s, y: s.vector_field(jnp.zeros(()), y, command), system, scale)
    return [np.shape(x) for x in jax.tree_util.tree_leaves(scale)] == [x.shape for x in jax.tree_util.tree_leaves(rate)]


def batched_parameters(system):
    """[(path, shape, the shape it fits with)] of the array parameters of `system` with axes too many (several
    values where the system takes one): with each one's first entry alone (along one leading axis, or more) the
    vector field keeps the state's shape. Empty for a system whose vector field keeps it (the usual case: one shape
    inference), and for anything that is not a system."""
    if not isinstance(system, AbstractSystem):
        return []
    lo, hi = (float(np.min(b)) for b in system.command_range)
    command = jnp.asarray(0.5 * (lo + hi) if np.isfinite(lo + hi) else 0.0)
    try:
        if _fine(system, command):
            return []
    except Exception:  # noqa: BLE001 - the shapes do not even combine (any error of shape inference)
        pass
    dynamic, static = eqx.partition(system, eqx.is_array)
    flat, treedef = jax.tree_util.tree_flatten_with_path(dynamic)
    leaves = [leaf for _, leaf in flat]
    found = []
    for k, leaf in enumerate(leaves):
        for axes in range(1, np.ndim(leaf) + 1):  # the first entry along one, two, ... leading axes
            if 0 in np.shape(leaf)[:axes]:
                break
            trial = list(leaves)
            trial[k] = leaf[(0,) * axes]
            try:
                fine = _fine(eqx.combine(jax.tree_util.tree_unflatten(treedef, trial), static), command)
            except Exception:  # noqa: BLE001 - this parameter's first entry alone does not fit either
                continue
            if fine:
                found.append((_name(flat[k][0]), tuple(np.shape(leaf)), tuple(np.shape(trial[k]))))
                break
    return found


def describe_batched(found):
    """The sentence naming `batched_parameters`' findings."""
    def one(path, shape, wanted):
        wanted = "one number" if not wanted else f"shape {wanted}"
        return f"parameter {path!r} has shape {shape} where the model takes {wanted}"

    return ("; ".join(one(*f) for f in found) + ": it would make the state hold several values too, and the solve "
            "fail; give the value the model takes (a batch of models is simulated with jax.vmap over simulate, or "
            "pamjax.sweep)")
