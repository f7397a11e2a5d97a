"""How a fit drives its optimistix solver: pamjax's `LevenbergMarquardt` from the host (`run_on_host`, its state as
checkpoint arrays, `levenberg_marquardt` for a problem of one's own), any other optimistix solver through
`optimistix.least_squares` on the fit's two compiled programs (`run_optimistix`), and the `Outcome` both give
`fit`'s statistics."""

import dataclasses
import time
from collections.abc import Callable

import numpy as np
import optimistix as optx

from .._core.arrays import device_array
from .._core.custom_types import ArrayLike, RealVectorLike
from .._core.errors import PamjaxInputError, check_count
from .escape import hair_off
from .solver import CRAWL_STEPS, PROBED_MINIMUM, REASONS, Damping, LevenbergMarquardt, State


@dataclasses.dataclass
class Outcome:
    """Where an iteration stopped: `theta`, `residual`, `jacobian`, `cost`, `step` (iterations), `accepted`, `done`,
    `reason` (a sentence starting "converged", "stalled", "failed" (residuals not finite at the start), or "" when
    the step budget ran out), `history` (per row [step, cost at the current point, damping λ, accepted]), `scale`
    (Moré's D), `damping`, `restarts`, `escapes` (moves to a lower valley: `pamjax._fit.escape`)."""

    theta: np.ndarray
    residual: np.ndarray
    jacobian: np.ndarray
    cost: float
    step: int
    accepted: int
    done: bool
    reason: str
    history: list
    scale: np.ndarray
    damping: float = float("nan")
    restarts: int = 0
    escapes: int = 0

    @classmethod
    def of(cls, y, state, history):
        return cls(np.asarray(y), state.residual, state.jacobian, float(state.cost), int(state.step),
                   int(state.accepted), bool(state.done), REASONS[int(state.reason)], history, state.factors.scale,
                   float(state.search.damping), int(state.restarts), int(state.escapes))


def history_rows(state):
    """The history rows the last `init` or `step` added: [step, cost, damping, accepted]."""
    return [[int(s), float(c), float(d), bool(a)] for s, c, d, a in np.asarray(state.last_rows) if np.isfinite(s)]


def run_on_host(solver, fn, y, state=None, history=None, *, max_steps, args=None, on_step=None):
    """Drive `solver` (pamjax's `LevenbergMarquardt`) from Python: `init` at `y` (unless a `state` is given, e.g. a
    checkpoint's), then `step` until `terminate` says done or `max_steps` iterations in all. `fn` as `init`'s host
    mode wants it (NumPy residuals; `fn.jacobian`). `on_step(y, state, history)` after each step. Returns
    (y, state, history)."""
    y = np.asarray(y, dtype=float)
    if state is None:
        state = solver.init(fn, y, args, {}, None, None, frozenset())
        history = history_rows(state)
        if on_step is not None:
            on_step(y, state, history)
    done = bool(state.done)
    while not done and int(state.step) < max_steps:
        y, state, _ = solver.step(fn, y, args, {}, state, frozenset())
        history = history + history_rows(state)
        done, _ = solver.terminate(fn, y, args, {}, state, frozenset())
        if on_step is not None:
            on_step(y, state, history)
    return y, state, history


def state_arrays(y, state, history):
    """The iteration's state as a flat dict of arrays (a checkpoint: every array exactly)."""
    return dict(theta=np.asarray(y), residual=state.residual, jacobian=state.jacobian,
                scalars=np.asarray([state.cost, state.search.damping, state.search.growth, state.initial_cost],
                                   dtype=float),
                scale=state.factors.scale,
                counters=np.asarray([state.step, state.accepted, state.rejected_in_row, int(state.done), state.restarts,
                                     state.reason, state.rows, state.escapes], dtype=np.int64),
                recent=state.recent, history=np.asarray(history, dtype=float).reshape(-1, 4))


def state_from_arrays(solver, a):
    """(θ, state, history) from `state_arrays`' dict — or from a checkpoint of pamjax ≤ 2026-11 (format 2: the
    host Levenberg-Marquardt's, which this solver continues)."""
    history = [[int(s), float(c), float(z), bool(acc)] for s, c, z, acc in np.asarray(a["history"])]
    residual, jacobian = np.asarray(a["residual"], dtype=float), np.asarray(a["jacobian"], dtype=float)
    scalars = [float(v) for v in a["scalars"]]
    counters = [int(v) for v in a["counters"]]
    if "recent" in a:
        cost, damping, growth, initial = scalars
        step, accepted, rejected, done, restarts, reason, rows, *more = counters
        escapes = more[0] if more else 0  # a checkpoint written before the escapes (2026-11-27)
        recent = np.asarray(a["recent"], dtype=float)
    else:  # format 2: the reason as text, no crawl buffer (rebuilt from the history)
        (cost, damping, growth), initial = scalars[:3], history[0][1]
        step, accepted, rejected, done, *rest = counters
        restarts, rows, escapes = (rest[0] if rest else 0), len(history), 0
        text = str(a["reason"])
        reason = REASONS.index(text) if text in REASONS else (REASONS.index("stalled") if text else 0)
        costs = [row[1] for row in history[-(CRAWL_STEPS + 1):]]
        recent = np.asarray([np.nan] * (CRAWL_STEPS + 1 - len(costs)) + costs)
    last = np.full((2, 4), np.nan)
    last[0] = history[-1]
    state = State(residual=residual, jacobian=jacobian, cost=np.float64(cost), initial_cost=np.float64(initial),
                  factors=solver.descent.factor(residual, jacobian, np.asarray(a["scale"], dtype=float)),
                  search=Damping(np.float64(damping), np.float64(growth)), step=np.int64(step),
                  accepted=np.int64(accepted), rejected_in_row=np.int64(rejected), restarts=np.int64(restarts),
                  escapes=np.int64(escapes),
                  done=np.bool_(done), reason=np.int64(reason), rows=np.int64(rows), recent=recent, last_rows=last,
                  aux=None)
    return np.asarray(a["theta"], dtype=float), state, history


def jacobian_check(outcome, residuals, directions=3):
    """Relative disagreement between J·d and the central difference of r along the steepest-descent direction and
    the first right singular vectors: ~1e-6 for a correct Jacobian of a smooth cost; O(1) where the cost is not
    what the Jacobian describes (a discontinuity, or a wrong derivative). `residuals(θ)` → r, or None where the
    model fails."""
    scale, jac, theta = outcome.scale, outcome.jacobian, outcome.theta
    scaled = jac / scale
    _, _, vt = np.linalg.svd(scaled, full_matrices=False)
    grad = scaled.T @ outcome.residual
    worst = 0.0
    for d in [grad / (np.linalg.norm(grad) or 1.0)] + list(vt[: directions - 1]):
        d = d / scale
        predicted = jac @ d
        size = float(np.linalg.norm(predicted))
        if size == 0:
            continue
        eps = 1e-6 * max(float(np.linalg.norm(theta * scale)), 1.0) / float(np.linalg.norm(d * scale))
        up, down = residuals(theta + eps * d), residuals(theta - eps * d)
        if up is None or down is None:
            return np.inf
        worst = max(worst, float(np.linalg.norm((up - down) / (2.0 * eps) - predicted)) / size)
    return worst


def statistics_jacobian(outcome, jacobian):
    """(Jacobian, residuals) for a fit's statistics (covariance, identifiability): the end point's, except where the
    fit ended at a kink of its cost (a probed minimum, or stalled): there they are taken a hair off it
    (`pamjax._fit.escape.hair_off`: every θ component + `HAIR`, else − `HAIR`, where the cost is the end's to within
    `HAIR_COST` of it). At a kink a stick-slip event begins or ends exactly at the end point, and the Jacobian there
    can be that of the event's edge: on an unseen rig (benchmarks/RESULTS.md, identify, Session 47: rig1001) the
    force law's columns were ~1e10 at the point and ~1e5 a hair off it (condition 1e9 against 7e3), and the point's
    covariance gave standard errors 100× too small and called seven parameters non-identifiable. `jacobian(θ)` →
    (r, J) as `Problem.jacobian`."""
    if outcome.reason not in (PROBED_MINIMUM, "stalled"):
        return outcome.jacobian, outcome.residual
    off = hair_off(outcome.theta, outcome.cost, jacobian)
    return (outcome.jacobian, outcome.residual) if off is None else (off[1], off[0])


class _Callables:
    """`fn` for the host loop from two callables: `residuals(θ)` → r or None (a failed model), `jacobian(θ)` →
    (r, J)."""

    def __init__(self, residuals, jacobian):
        self.residuals, self.jacobian_fn, self.size = residuals, jacobian, None

    def __call__(self, theta, args):
        r = self.residuals(theta)
        if r is None:
            return np.full(self.size, np.nan), None
        return np.asarray(r, dtype=float), None

    def jacobian(self, theta, args):
        r, jac = self.jacobian_fn(theta)
        r = np.asarray(r, dtype=float).ravel()
        self.size = r.size
        return r, jac


def levenberg_marquardt(residuals: Callable[[np.ndarray], ArrayLike | None],
                        jacobian: Callable[[np.ndarray], tuple[ArrayLike, ArrayLike]], theta0: RealVectorLike, *,
                        max_steps: int = 100, ftol: float | int = 1e-10, xtol: float | int = 1e-10,
                        gtol: float | int = 1e-10, stall_steps: int = 8, geodesic: bool = True,
                        solver: LevenbergMarquardt | None = None) -> Outcome:
    """Least squares min ½‖r(θ)‖² by the solver and host loop `pamjax.fit` uses, for a problem of your own.

    **Arguments:** `residuals(θ)` → r (NumPy, or None / non-finite where the model fails: that trial is rejected);
    `jacobian(θ)` → (r, ∂r/∂θ) (e.g. a jitted `jax.jacfwd` with the residuals as aux); `theta0` the start (1-D);
    the stopping settings as in `pamjax.fit`, or `solver`, a `pamjax.LevenbergMarquardt` (then they are its own).

    **Returns:** an `Outcome`: `theta`, `cost`, `residual`, `jacobian`, `step`, `accepted`, `done`, `reason`
    ("converged: …", "stalled", or "" after `max_steps`), `history`.
    """
    if solver is None:
        solver = LevenbergMarquardt(ftol, xtol, gtol, stall_steps, geodesic)
    elif not isinstance(solver, LevenbergMarquardt):
        raise PamjaxInputError(f"solver must be a pamjax.LevenbergMarquardt, got {type(solver).__name__} (any "
                               "optimistix solver runs in optimistix.least_squares)")
    check_count(max_steps, "max_steps")
    theta0 = np.asarray(theta0, dtype=float)
    if theta0.ndim != 1:
        raise PamjaxInputError(f"theta0 must be a 1-D array, got shape {theta0.shape}")
    y, state, history = run_on_host(solver, _Callables(residuals, jacobian), theta0, max_steps=max_steps)
    return Outcome.of(y, state, history)


# --- fit's runs ------------------------------------------------------------------------------------------------------
_OWN_DEFAULTS = dict(ftol=1e-10, xtol=1e-10, gtol=1e-10, stall_steps=8)  # fit's defaults: LevenbergMarquardt's


def choose_solver(solver, ftol, xtol, gtol, stall_steps, checkpoint, resume):
    """`fit`'s (solver, whether it is pamjax's own `LevenbergMarquardt`), checked before anything is solved."""
    if solver is None:
        return LevenbergMarquardt(ftol, xtol, gtol, stall_steps), True
    if not isinstance(solver, (optx.AbstractLeastSquaresSolver, optx.AbstractMinimiser)):
        raise PamjaxInputError(f"solver must be None, a pamjax.LevenbergMarquardt or an optimistix least-squares "
                               f"solver (e.g. optimistix.LevenbergMarquardt(rtol=1e-8, atol=1e-8)), got {solver!r}")
    given = {k: v for k, v in dict(ftol=ftol, xtol=xtol, gtol=gtol, stall_steps=stall_steps).items()
             if v != _OWN_DEFAULTS[k]}
    if given:
        raise PamjaxInputError(f"{', '.join(given)}: set by the solver passed as `solver` (its own settings), not "
                               "by fit's arguments")
    if isinstance(solver, LevenbergMarquardt):
        return solver, True
    if checkpoint is not None or resume is not None:
        raise PamjaxInputError(f"{'checkpoint' if checkpoint is not None else 'resume'}: checkpoints hold the state "
                               f"of pamjax's LevenbergMarquardt; a {type(solver).__name__} runs as one "
                               "optimistix.least_squares call (solver=None to checkpoint)")
    return solver, False


def run_fit(solver, problem, theta, max_steps, report, announce, start=None, save=None):
    """`fit` with pamjax's `LevenbergMarquardt`, driven from the host (`run_on_host`) around the fit's two compiled
    programs (`Problem.objective`): from θ, or from `start` = (θ, state, history) of a checkpoint; `save(y, state,
    history)` after every iteration. Returns the `Outcome`. A checkpoint past `max_steps` is refused
    (`check_resumed_steps`)."""
    if start is not None:
        check_resumed_steps(int(start[1].step), max_steps)
    fn = problem.objective(started=start is not None)
    if start is not None:
        y, state, history = start
    else:
        y = theta
        state = solver.init(fn, theta, None, {}, None, None, frozenset())  # the start's Jacobian: compiles
        history = history_rows(state)
        if announce:
            print(f"fit: compiled in {problem.compile_seconds():.1f} s", flush=True)
        if report is not None:
            report(0, float(state.cost), float(state.search.damping), True)

    def on_step(y, state, history):
        if report is not None:
            report(*history[-1])
        if save is not None:
            save(y, state, history)

    if save is not None and int(state.step) == 0 and bool(state.done):
        save(y, state, history)
    y, state, history = run_on_host(solver, fn, y, state, history, max_steps=max_steps, on_step=on_step)
    return Outcome.of(y, state, history)


def check_resumed_steps(steps, max_steps):
    """A resume ends where an uninterrupted fit with the same `max_steps` ends. A checkpoint already `steps` >
    `max_steps` iterations in holds only its last point, not the one that fit stops at: refused by name (it returned
    the checkpoint's iterations as if `max_steps` allowed them: 8 of max_steps = 3, status 'max_steps')."""
    if steps > max_steps:
        raise PamjaxInputError(
            f"max_steps = {max_steps}: the checkpoint resumed already holds {steps} iterations, and an uninterrupted "
            f"fit with max_steps = {max_steps} ends at an earlier point the checkpoint does not keep; resume with "
            f"max_steps >= {steps} (pamjax fit: raise [fit] max_steps), or fit again without resume")


def run_optimistix(solver, problem, theta, max_steps, report, announce):
    """Any other optimistix solver: `optimistix.least_squares` on the fit's two programs (`Problem.traced`).
    Returns (`solver.Outcome`, the seconds its loop took to trace and compile)."""
    r0, j0 = problem.objective().jacobian(theta, None)  # compiles both programs, refuses a failing start
    if announce:
        print(f"fit: compiled in {problem.compile_seconds():.1f} s", flush=True)
    cost0 = 0.5 * float(r0 @ r0)
    history, best = [[0, cost0, float("nan"), True]], [cost0]
    if report is not None:
        report(0, cost0, float("nan"), True)

    def evaluated(r):
        cost = 0.5 * float(r @ r) if np.all(np.isfinite(r)) else float("inf")
        history.append([len(history), cost, float("nan"), bool(cost < best[0])])
        best[0] = min(best[0], cost)
        if report is not None:
            report(*history[-1])

    fn, y0 = problem.traced(evaluated), device_array(theta)
    t0 = time.perf_counter()  # its loop, traced and compiled ahead of the run: the time is compilation
    solve = optx.least_squares.lower(fn, solver, y0, max_steps=max_steps, throw=False).compile()
    compile_s = time.perf_counter() - t0
    sol = solve(fn, solver, y0, max_steps=max_steps, throw=False)
    y = np.asarray(sol.value)
    r, jac = problem.jacobian(y)
    result = sol.result
    finished = result == optx.RESULTS.successful
    out_of_steps = result == optx.RESULTS.nonlinear_max_steps_reached
    name = type(solver).__name__
    if finished:
        reason = f"converged: optimistix {name} reports success (its own tests: {_settings(solver)})"
    elif out_of_steps:
        reason = ""
    else:
        reason = f"stalled: optimistix {name} reports: {optx.RESULTS[result].splitlines()[0]}"
    accepted = getattr(getattr(sol, "state", None), "num_accepted_steps", None)
    scale = np.linalg.norm(jac, axis=0)
    outcome = Outcome(y, r, jac, 0.5 * float(r @ r), int(sol.stats["num_steps"]),
                      int(accepted) if accepted is not None else sum(1 for row in history[1:] if row[3]),
                      not out_of_steps, reason, history, np.where(scale > 0, scale, 1.0))
    return outcome, compile_s


def _settings(solver):
    shown = [f"{k}={getattr(solver, k)!r}" for k in ("rtol", "atol") if isinstance(getattr(solver, k, None), float)]
    return ", ".join(shown) or "its defaults"
