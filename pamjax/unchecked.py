"""The unchecked, traceable cores of the checked entry points, for your own `jit`, `vmap` and `grad` loops.

`pamjax.simulate`, `pamjax.simulate_closed_loop` and `pamjax.simulate_joint_control` check their arguments in Python
(a `PamjaxInputError` naming the argument before any solve) and so need concrete values. The functions here check
nothing: input in the wrong units or out of range gives wrong numbers silently, with a successful result (`result`
0). A duty of 50 (percent) or 1.5 runs as a valve held open, a start pressure of 6.0 (bar) as 6 Pa: plausible-looking
pressures, no message. Check your arguments with the public functions first (`pamjax.simulate` on the same system,
signal and start state), then use these inside a transformation.

- `solve`: the core of `simulate` (`num_periods` gives its static count of PWM periods; `default_solver` the solver
  `simulate` picks, which `solve` takes too where `solver=None`). Its defaults give `simulate`'s answer, except where
  `simulate` needs concrete times: an `OnOffValve(mode="exact")` traced under jit is refused (use mode="smooth" or
  stepping="pwm"), and a continuous valve's command jumps (`Step`, `Sampled`) need `jump_ts` (the signal's
  `jump_times()` inside (t0, ts[-1]));
- `run_closed_loop`, `run_joint_control`: the cores of `simulate_closed_loop` and `simulate_joint_control`;
- `discrete_step`: one step of paper 000's discrete-time model (eq. 18-21), the core of `simulate_discrete`.
"""

# The annotations' modules under private names: this namespace's public names are the cores alone.
import typing as _typing

import equinox as _eqx

from ._control.closed_loop import run_closed_loop as run_closed_loop
from ._control.joint import run_joint_control as run_joint_control
from ._core import custom_types as _types
from ._physics import signals as _signals
from ._solve import simulate as _simulate, trajectory as _trajectory
from ._solve.discrete import discrete_step as discrete_step
from ._solve.simulate import default_solver as default_solver
from ._solve.synchronous import num_periods as num_periods
from ._systems import base as _base

if _typing.TYPE_CHECKING:  # annotations only: importing diffrax costs ~0.4 s that fixed-grid work never needs
    import diffrax as dfx


def solve(system: _base.AbstractSystem, signal: _signals.AbstractSignal, ts: _types.TimesLike, y0: _eqx.Module | None,
          t0: _types.RealScalarLike, *, solver: "dfx.AbstractSolver | None" = None,
          **options: _typing.Any) -> _trajectory.Trajectory:
    """The unchecked, traceable core of `simulate` (vmap- and grad-safe; no Python-side validation), with
    `simulate`'s solver: `solver=None` is `default_solver(system)`, `Rodas5()` for a continuous valve, `Tsit5()` for
    a switching one. (The core's own default is `Tsit5()` whatever the valve, which the closed loops rely on: an
    averaged valve's 25 s MAS-10 triangle took 3,170 steps here against `simulate`'s 809, a few Pa apart.)

    `options`: the core's keywords, with its defaults: `rtol`, `atol` (1e-6 each, `atol` in scaled state units),
    `max_steps` (200,000), `dt0`, `adjoint` (reverse mode), `jump_ts`, `throw` (False), `stepping` ("adaptive"),
    `substeps` (16), `num_periods`, `grid_step` (1 ms), `starts_off` (True); each as documented below.

    """
    solver = default_solver(system) if solver is None else solver
    return _simulate.solve(system, signal, ts, y0, t0, solver=solver, **options)


solve.__doc__ += _simulate.solve.__doc__
