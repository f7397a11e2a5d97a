"""The unchecked, traceable cores of the checked entry points, for your own `jit`, `vmap` and `grad` loops.

`pamjax.simulate`, `pamjax.simulate_closed_loop` and `pamjax.simulate_joint_control` check their arguments in Python
(a `PamjaxInputError` naming the argument before any solve) and so need concrete values. The functions here do no
such checks: bad input gives a failed solve or NaN, not a message. Use them only inside a transformation, with
arguments the checked entry point has accepted once.

- `solve`: the core of `simulate` (`num_periods` gives its static count of PWM periods; `default_solver` the solver
  `simulate` picks);
- `run_closed_loop`, `run_joint_control`: the cores of `simulate_closed_loop` and `simulate_joint_control`;
- `discrete_step`: one step of paper 000's discrete-time model (eq. 18-21), the core of `simulate_discrete`.
"""

from ._control.closed_loop import run_closed_loop as run_closed_loop
from ._control.joint import run_joint_control as run_joint_control
from ._solve.discrete import discrete_step as discrete_step
from ._solve.simulate import default_solver as default_solver, solve as solve
from ._solve.synchronous import num_periods as num_periods
