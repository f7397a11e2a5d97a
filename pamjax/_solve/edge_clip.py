"""The step-size controllers of an adaptive solve: `FirstStepToEnd`, diffrax's PID controller whose first step ends
on t1 as diffrax ends every later one, and `EdgeClipController`, steps that end either side of every smoothed switching
edge (a module of its own so that importing the solve layer does not import diffrax; `pamjax/_solve/edges.py` holds
the rest of what an adaptive solve sees of a switching valve)."""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp

from .._physics.signals import AbstractSignal
from .._physics.valves.base import AbstractControlElement


class FirstStepToEnd(dfx.PIDController):
    """`diffrax.PIDController` whose first step, where it ends within 100 eps·|t1| (100-200 ULP) short of t1, ends on
    t1, as diffrax ends every later step within 100 ULP of t1 (`_clip_to_end`, diffrax/_integrate.py): diffrax only
    takes the first one to min(t0 + dt0, t1). With `dt0=None` that first step is a fixed 0.01 s (diffrax's initial
    step heuristic runs on `ODETerm`s only, and `diffeqsolve` hands it its terms wrapped), so a solve over
    [0.06, 0.07] stepped to 0.06 + 0.01 = 0.06999999999999999, one ULP short, then took a 1.4e-17 s sliver to t1,
    which dtmin (`_controller` of pamjax/_solve/simulate.py) took for a failure: a closed loop at a 10 ms period
    (period ends t + T·n/n, a rounding above t + T) failed from t = 0.06 s. Only the first proposal changes, by at
    most 200 ULP, and nothing is added to a step."""

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        tnext, state = super().init(terms, t0, t1, y0, dt0, args, func, error_order)
        close = t1 - tnext < 100 * jnp.finfo(jnp.result_type(tnext)).eps * jnp.abs(t1)
        return jnp.where(close, t1, tnext), state


class EdgeClipController(dfx.AbstractAdaptiveStepSizeController):
    """A step-size controller (wrapping `controller`) whose steps end either side of every smoothed switching edge
    of `valve` (its `next_edge_step`): the next boundary is computed from the PWM period and the duty latched at its
    start, in constant time per step (diffrax's `ClipStepSizeController` with an array of all boundaries compares
    each step against the whole array: 3x the run time of a 25 s PWM run)."""

    controller: dfx.AbstractAdaptiveStepSizeController
    valve: AbstractControlElement
    signal: AbstractSignal

    @property
    def atol(self):
        return self.controller.atol

    @property
    def rtol(self):
        return self.controller.rtol

    @property
    def norm(self):
        return self.controller.norm

    def wrap(self, direction):
        return eqx.tree_at(lambda c: c.controller, self, self.controller.wrap(direction))

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        t1, state = self.controller.init(terms, t0, t1, y0, dt0, args, func, error_order)
        return jnp.minimum(t1, self._edge(t0)), state

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order, controller_state):
        keep, next_t0, next_t1, made_jump, state, result = self.controller.adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, controller_state
        )
        next_t1 = jnp.minimum(next_t1, self._edge(next_t0))
        return keep, next_t0, next_t1, made_jump, state, result

    def _edge(self, t):
        """The next edge's step boundary after `t`, not differentiated: where the steps end is the solver's choice,
        as diffrax's own controllers hold their step sizes out of the gradient. (Differentiated, a gradient with
        respect to the PWM frequency of a 2 s run came out -4e267: each boundary moves with t·f, and the solution's
        dependence on where its steps end compounded over the run.)"""
        return jax.lax.stop_gradient(self.valve.next_edge_step(self.signal, t))
