"""`Trajectory`: what `simulate` returns, the system's named outputs at the requested times, and its result codes."""

import equinox as eqx
import jax.numpy as jnp
import jax.tree_util as jtu

from .._core.custom_types import Array, Float, Int, PyTreeLike, Real, Series
from .._core.errors import PamjaxInputError
from .._core.private import diffrax_result_message

RESULT_NONFINITE = 101  # a fixed-grid integration (or an adaptive one) produced a non-finite state
RESULT_NONPHYSICAL = 102  # a state left the physical range (absolute pressure ≤ 0)
# The order channels are listed in (the muscle systems' outputs first, as earlier versions had them as fields), and
# the names that read None on a system without them (a tank's `traj.position`).
_ORDER = ("pressure", "mass_flow", "position", "velocity", "force", "friction_force", "volume")


class Trajectory(eqx.Module):
    """The result of `simulate`: the system's named outputs at the requested times.

    - `t` [s]; `state`: the state pytree at each time (absolute pressures); `command`: the command used.
    - `outputs`: {name: array} of the system's channels (`system.output_names`): `pressure` [Pa abs] and
      `mass_flow` [kg/s into the chamber] for every system; `position` [m], `velocity` [m/s], `force` [N] (muscle),
      `friction_force` [N], `volume` [m³] for a muscle; `angle` [rad], `angular_velocity` [rad/s] for the joint.
      Each is also an attribute (`traj.pressure`, `traj.angle`); `position`, `velocity`, `force`, `friction_force`
      and `volume` read None on a system without them.
    - `num_steps`, `num_accepted_steps`, `num_rejected_steps`: solver statistics.
    - `result`: diffrax result code, or `RESULT_NONFINITE` / `RESULT_NONPHYSICAL` (0 = success); `succeeded`.
    """

    t: Series
    state: PyTreeLike
    command: Real[Array, " times *command"]
    outputs: dict[str, Float[Array, " times *channel"]]
    num_steps: Int[Array, ""]
    num_accepted_steps: Int[Array, ""]
    num_rejected_steps: Int[Array, ""]
    result: Int[Array, ""]

    def __getattr__(self, name):
        outputs = self.__dict__.get("outputs")
        if outputs is not None and name in outputs:
            return outputs[name]
        if name in _ORDER:
            return None
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def succeeded(self):
        return self.result == 0

    def channel(self, name):
        """A channel by name ('pressure', 'position', 'command', ...); a clear error for one this system lacks."""
        if name == "command":
            return self.command
        if name not in self.outputs:
            raise PamjaxInputError(f"unknown or absent channel {name!r}; this trajectory has {self.channels()}")
        return self.outputs[name]

    def channels(self):
        """The channels' names: the outputs (muscle channels first, in their usual order) and "command"."""
        first = [c for c in _ORDER if c in self.outputs]
        return [*first, *(c for c in self.outputs if c not in first), "command"]


def result_message(code):
    """Human-readable reason for a `Trajectory.result` code."""
    if code == 0:
        return "successful"
    if code == RESULT_NONFINITE:
        return "the state became non-finite (NaN or inf)"
    if code == RESULT_NONPHYSICAL:
        return (
            "an absolute pressure fell to or below 0 (unstable integration, or parameters far outside the physical "
            "range)"
        )
    message = diffrax_result_message(code)
    return "unknown failure" if message is None else message


def fixed_grid_trajectory(ts, states, commands, outs, num_steps, finite):
    """The `Trajectory` of a fixed-grid solve (its steps all accepted; failed where its states are not finite)."""
    zero = jnp.zeros((), dtype=num_steps.dtype)
    return trajectory(ts, states, commands, outs, num_steps, num_steps, zero, jnp.where(finite, 0, RESULT_NONFINITE))


def trajectory(ts, states, commands, outs, num_steps, num_accepted, num_rejected, result):
    """The `Trajectory` of a solve: a state with an absolute pressure ≤ 0 marks it failed, and a failed solve's
    outputs are NaN (never plausible-looking numbers)."""
    pressure = getattr(states, "pressure", None)
    if pressure is not None:  # an absolute pressure ≤ 0 means an unstable integration, never a result
        result = jnp.where((result == 0) & jnp.any(pressure <= 0), RESULT_NONPHYSICAL, result)
    failed = result != 0
    outs = jtu.tree_map(lambda a: jnp.where(failed, jnp.nan, a), dict(outs))
    return Trajectory(t=ts, state=states, command=commands, outputs=outs, num_steps=num_steps,
                      num_accepted_steps=num_accepted, num_rejected_steps=num_rejected, result=result)
