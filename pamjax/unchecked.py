"""The unchecked, traceable cores of the checked entry points, for your own `jit`, `vmap` and `grad` loops.

`pamjax.simulate`, `pamjax.simulate_closed_loop` and `pamjax.simulate_joint_control` check their arguments in Python
(a `PamjaxInputError` naming the argument before any solve) and so need concrete values. The functions here check
nothing: input in the wrong units or out of range gives wrong numbers silently, with a successful result (`result`
0). A duty of 50 (percent) or 1.5 runs as a valve held open, a start pressure of 6.0 (bar) as 6 Pa: plausible-looking
pressures, no message. Check your arguments with the public functions first (`pamjax.simulate` on the same system,
signal and start state), then use these inside a transformation.

- `solve`: the core of `simulate` (`num_periods` gives its static count of PWM periods; `default_solver` the solver
  `simulate` picks). Its defaults give `simulate`'s answer, except where `simulate` needs concrete times: an
  `OnOffValve(mode="exact")` traced under jit is refused (use mode="smooth" or stepping="pwm"), and a continuous
  valve's command jumps (`Step`, `Sampled`) need `jump_ts` (the signal's `jump_times()` inside (t0, ts[-1]));
- `run_closed_loop`, `run_joint_control`: the cores of `simulate_closed_loop` and `simulate_joint_control`;
- `discrete_step`: one step of paper 000's discrete-time model (eq. 18-21), the core of `simulate_discrete`.
"""

from ._control.closed_loop import run_closed_loop as run_closed_loop
from ._control.joint import run_joint_control as run_joint_control
from ._solve.discrete import discrete_step as discrete_step
from ._solve.simulate import default_solver as default_solver, solve as solve
from ._solve.synchronous import num_periods as num_periods
