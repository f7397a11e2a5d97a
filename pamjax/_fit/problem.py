"""A fit's two compiled functions and their host side: the residuals at θ and (r, ∂r/∂θ) in forward mode, compiled
once per problem structure (`ProgramCache` when the CLI's persistent cache is on), called with NumPy in and out
(`Problem`); `fit`, `profile` and `design` use them (the fit's public contract with the layers above). The optimiser
sees them as an optimistix `fn(y, args)`: on the host for pamjax's own solver (`Problem.objective`), or through host
callbacks for any other (`Problem.traced`)."""

import functools
import math
import threading
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import device_array
from .._core.cache import program_cache
from .._core.errors import PamjaxInputError
from .._core.private import equinox_errors_as_nan
from .._core.xla_cpu import batched_options, compiled_with
from .._physics.muscle import AbstractMuscle
from .predictions import predict_all


def _residual_vector(space, theta, exps):
    """Residuals of every sample (identification and validation parts; the host selects); NaN where θ's model
    breaks a check that ties parameters together (`breaks_a_check`), so that the step is refused as a failed one."""
    model = space.model(theta)
    preds = predict_all(model, exps)
    r = jnp.concatenate([e.residuals_of(p, "all") for e, p in zip(exps, preds)])
    return jnp.where(breaks_a_check(model), jnp.nan, r)


def breaks_a_check(model):
    """Whether (traced or concrete) a muscle's volume is ≤ 0 somewhere on its stroke
    (`AbstractMuscle.smallest_volume`), which no parameter's own bound prevents (V = v0 + v1 x with v0, v1 > 0 is
    negative at a stroke's stretched end x < 0 when v0 < −v1 x). A solve is unharmed where the recorded motion never
    goes, so a trial step there would be accepted, and the fit's result then fail `Muscle`'s checks in the joint fit
    that starts from it (found on an unseen rig whose stage 2 ended there: benchmarks/RESULTS.md, identify,
    rig1102)."""
    muscles = [c for c in jax.tree_util.tree_leaves(model, is_leaf=lambda c: isinstance(c, AbstractMuscle))
               if isinstance(c, AbstractMuscle)]
    return functools.reduce(jnp.logical_or, [m.smallest_volume() <= 0 for m in muscles], jnp.asarray(False))


@eqx.filter_jit
def residuals_at(space, theta, exps):
    """The residuals at θ (module level, `space` an argument: fits of one problem structure from different start
    models share this compilation)."""
    return _residual_vector(space, theta, exps)


@eqx.filter_jit
def residuals_and_jacobian(space, theta, exps):
    """(r, ∂r/∂θ) at θ, forward mode: one pass of the solves with a tangent per free parameter."""

    def f(t):
        r = _residual_vector(space, t, exps)
        return r, r

    jac, r = jax.jacfwd(f, has_aux=True)(theta)
    return r, jac


_JACOBIAN_PROGRAMS = {}  # compile options (a sorted tuple) → `residuals_and_jacobian` jitted with them


def _jacobian_options():
    """The compile options of the Jacobian's program: its solves carry one tangent per free parameter side by side,
    a batch that 512-bit vectors speed up on an AVX-512 CPU (`pamjax._core.xla_cpu.batched_options`; the
    20-parameter fit of benchmarks/fit.py: its fit 25 % shorter). None elsewhere, and for the residuals' program (one
    trajectory per experiment, which gains nothing from them)."""
    device = jax.config.jax_default_device
    platform = getattr(device, "platform", device) or jax.default_backend()
    return batched_options(str(platform))


def _jacobian_program(options):
    if options is None:
        return residuals_and_jacobian
    return compiled_with(_JACOBIAN_PROGRAMS, eqx.filter_jit, residuals_and_jacobian.__wrapped__, options)


@eqx.filter_jit
def physical_and_jacobian(space, theta):
    """The physical values at θ and d(values)/dθ, compiled (run eagerly, each operation compiles on its own)."""
    return space.physical(theta), jax.jacfwd(space.physical)(theta)


def solve_failure(exp, model):
    """Why experiment `exp`'s solve fails at the concrete `model`: (the cause: what stopped it, where, with which
    max_steps; a step budget that would finish the run, or None where the budget is not the cause), or None where it
    succeeds. The experiment's solve again, as `simulate` runs it with its settings (`throw=False`), on the way to an
    error only: its residuals are NaN and its forward-mode Jacobian exact zeros (a failed solve's outputs are NaN
    whatever the parameters), which say nothing of the cause."""
    from .._solve.simulate import simulate  # (here: only a failed start pays for the import)
    from .._solve.trajectory import result_message
    from .experiment import Experiment

    if not isinstance(exp, Experiment):  # static and force-map experiments have no solve of their own
        return None
    try:  # a diagnosis must not raise in place of the failure it explains
        import diffrax as dfx

        system = exp.system_for(model)
        key = exp.batch_key(model)
        stepping = "adaptive" if key is None else key[0]
        settings = (dict(solver=dfx.Tsit5(), rtol=exp.rtol, atol=exp.atol, max_steps=exp.max_steps, dt0=exp.dt0)
                    if stepping == "adaptive" else dict(substeps=exp.substeps))  # Tsit5: `Experiment.predict`'s
        ts = np.asarray(exp.times, dtype=float)
        traj = simulate(system, exp.signal, ts, y0=exp.start_for(system, model), t0=exp.span[0], stepping=stepping,
                        throw=False, **settings)
        code, steps = int(traj.result), int(traj.num_steps)
        if code == 0:
            return None
        states = np.stack([np.ravel(np.asarray(x)) for x in jax.tree_util.tree_leaves(traj.state)], axis=-1)
        finite = np.flatnonzero(np.all(np.isfinite(states.reshape(len(ts), -1)), axis=1))
    except Exception:  # noqa: BLE001
        return None
    t0, t1 = exp.span
    reached = float(ts[finite[-1]]) if finite.size else t0
    cause = result_message(code).split(" Try increasing")[0].rstrip(".")  # the remedy is the caller's
    cause = cause[:1].lower() + cause[1:]
    where = f"it stopped at t = {reached:.4g} s of {t1:.4g} s"
    if stepping != "adaptive" or steps < exp.max_steps:
        return f"{cause} ({where}, {stepping} stepping)", None
    if reached <= t0:  # not one sample after the start: no rate of steps to scale the budget by
        return f"{cause}: max_steps={exp.max_steps} ({where})", int(2 ** math.ceil(math.log2(10 * exp.max_steps)))
    needed = steps * (t1 - t0) / (reached - t0)
    budget = int(2 ** math.ceil(math.log2(2 * needed)))  # 2×: the rate of steps varies along a run (as `simulate`)
    return (f"{cause}: max_steps={exp.max_steps} ({where}; the whole run needs about {needed:,.0f} steps at "
            f"rtol={exp.rtol:g})"), budget


def failed_solves(space, theta, exps, residuals, remedy=None):
    """What non-finite residuals come from: for each experiment of `exps` (bound) whose block of `residuals` (the
    identification samples `Problem.mask` keeps, in order) is not all finite at θ, a phrase "experiment 'E3': its
    solve fails: ...: raise its max_steps ..." (`solve_failure`; `remedy` in place of the advice on max_steps, for
    runs that have no such setting), joined by "; ". "" where all are finite."""
    values = None
    phrases, k = [], 0
    residuals = np.asarray(residuals)
    for e in exps:
        size = int(sum(np.count_nonzero(used & ident) for _, _, _, used, ident in e.layout()))
        block, k = residuals[k:k + size], k + size
        if np.all(np.isfinite(block)):
            continue
        if values is None:
            values = np.asarray(physical_and_jacobian(space, device_array(theta))[0])  # compiled, not op by op
        failure = solve_failure(e, space.with_values(values))
        if failure is None:
            phrases.append(f"experiment {e.name!r}: its predictions are not finite though its solve alone succeeds "
                           "(a parameter outside its physical range, e.g. a muscle volume <= 0 on the stroke)")
            continue
        cause, budget = failure
        fix = (": check its parameters and initial state" if budget is None else f": {remedy}" if remedy else
               f": raise its max_steps (e.g. max_steps = {budget}) or shorten the run")
        phrases.append(f"experiment {e.name!r}: its solve fails: {cause}{fix}")
    return "; ".join(phrases)


class Problem:
    """The host side of the two compiled functions: NumPy in, NumPy out, the identification samples selected; a
    failed solve's residuals are None."""

    def __init__(self, space, exps):
        self.space, self.exps = space, exps
        self.mask = np.concatenate([used & ident for e in exps for _, _, _, used, ident in e.layout()])
        self.seconds = {"residuals": [], "jacobian": []}  # wall time of every call, the first with compilation
        self.preload_s = 0.0  # wall time of `preload`

    def _timed(self, kind, fn, *args):
        t = time.perf_counter()
        with equinox_errors_as_nan():
            out = jax.block_until_ready(fn(*args))
        self.seconds[kind].append(time.perf_counter() - t)
        return out

    def _call(self, kind, fn, theta, ready=None):
        """A compiled function of (space, θ, experiments); with the CLI's persistent cache on, traced once per
        problem structure for all runs (`ProgramCache`; `ready` as its `call`'s, else called at once)."""
        programs = program_cache()
        args = (self.space, device_array(theta), self.exps)
        options = _jacobian_options() if kind == "jacobian" else None
        if programs is None:
            if ready is not None:
                ready()
            return self._timed(kind, _jacobian_program(options) if kind == "jacobian" else fn, *args)
        return self._timed(kind, programs.call, f"fit_{kind}", fn.__wrapped__, args, ready, options)

    def cached(self, theta):
        """Whether both programs of this problem are already traced on disk (a second run: nothing to compile)."""
        programs = program_cache()
        args = (self.space, device_array(theta), self.exps)
        return programs is not None and all(programs.has(f"fit_{kind}", args, _jacobian_options() if kind == "jacobian"
                                                         else None) for kind in ("residuals", "jacobian"))

    def all_residuals(self, theta):
        return np.asarray(self._call("residuals", residuals_at, theta))

    def residuals(self, theta):
        r = self.all_residuals(theta)[self.mask]
        return r if np.all(np.isfinite(r)) else None

    def jacobian(self, theta, ready=None):
        r, j = self._call("jacobian", residuals_and_jacobian, theta, ready)
        return np.asarray(r)[self.mask], np.asarray(j)[self.mask]

    def preload(self, theta):
        """Load the problem's compiled programs kept by the CLI's program cache, if any (a second run), the
        residuals' in a second thread: the first Jacobian then starts at once. The loading releases Python's lock,
        so a thread importing optimistix meanwhile (`fit`) goes on. `preload_s`: its wall time (0 if nothing was
        loaded: no cache)."""
        programs = program_cache()
        if programs is None:
            return
        t0 = time.perf_counter()
        args = (self.space, device_array(theta), self.exps)
        side = threading.Thread(target=programs.preload, args=("fit_residuals", args), daemon=True)
        side.start()
        programs.preload("fit_jacobian", args, _jacobian_options())
        programs.preload("fit_physical", args[:2])
        side.join()
        self.preload_s = time.perf_counter() - t0

    def physical(self, theta):
        """(physical values, d(values)/dθ) at θ as NumPy arrays (`physical_and_jacobian`; through the CLI's program
        cache when it is on, so that a warm run does not trace it)."""
        programs = program_cache()
        args = (self.space, device_array(theta))
        if programs is None:
            out = physical_and_jacobian(*args)
        else:
            out = programs.call("fit_physical", physical_and_jacobian.__wrapped__, args)
        return tuple(np.asarray(a) for a in out)

    def start(self, theta):
        """The start point's residuals and Jacobian. The residual function (for trial steps) is compiled at the
        same time in a second thread, on the second core when there is one, started once the Jacobian's Python
        work (tracing) is done, so as not to slow it; `compile_seconds` is then the wall time until both are ready,
        less one evaluation of each. The statistics' parameter transform (a small program) is compiled here once
        the Jacobian is, while the residual function may still be compiling."""
        t0 = time.perf_counter()
        side = threading.Thread(target=self.all_residuals, args=(theta,), daemon=True)

        def ready():
            if side.ident is None:
                side.start()

        out = self.jacobian(theta, ready)  # an error or Ctrl-C here leaves the (daemon) side thread unwaited for
        ready()
        self.physical(theta)  # compiled now for the statistics at the end
        side.join()
        self.ready_s = time.perf_counter() - t0
        return out

    def compile_seconds(self):
        """Compilation time: the wall time until both compiled functions were ready, less their steady evaluation
        times (the medians of their later calls; the whole time when a fit ended after its first evaluation)."""
        steady = sum(float(np.median(t[1:])) for t in self.seconds.values() if len(t) >= 2)
        return max(getattr(self, "ready_s", 0.0) - steady, 0.0)

    def objective(self, started=False):
        """The fit's `fn(y, args)` for pamjax's `LevenbergMarquardt` run from the host: NumPy residuals (non-finite
        where the solve fails) and `fn.jacobian`. Its first Jacobian is `start`'s (both programs compiled side by
        side), and a start whose simulation fails is refused there; `started`: a resumed fit's (no such start)."""
        return _Objective(self, started)

    def traced(self, evaluated=None):
        """The fit's residuals as a JAX function `fn(y, args)` for `optimistix.least_squares` with any solver: its
        value and its forward-mode derivative (J·t, the Jacobian from the second program) are the two compiled
        programs, called back on the host (`jax.pure_callback`; a custom JVP rule), so that the solver's own loop
        is the only new program. `evaluated(r)` is told every evaluation's residuals."""
        m, n = int(np.count_nonzero(self.mask)), self.space.size
        r_shape = jax.ShapeDtypeStruct((m,), jnp.float64)
        j_shape = jax.ShapeDtypeStruct((m, n), jnp.float64)

        def value(theta):
            r = self.all_residuals(np.asarray(theta))[self.mask]
            if evaluated is not None:
                evaluated(r)
            return r

        def both(theta):
            r, j = self.jacobian(np.asarray(theta))
            if evaluated is not None:
                evaluated(r)
            return r, j

        @jax.custom_jvp
        def residuals(theta):
            return jax.pure_callback(value, r_shape, theta)

        @residuals.defjvp
        def _(primals, tangents):
            r, j = jax.pure_callback(both, (r_shape, j_shape), primals[0])
            return r, j @ tangents[0]

        return _Traced(residuals)


class _Traced(eqx.Module):
    """`fn(y, args)` → residuals, for optimistix (a module: one compilation of its loop per fit)."""

    residuals: object = eqx.field(static=True)

    def __call__(self, y, args):
        return self.residuals(y)


class _Objective:
    """`fn` for pamjax's solver on the host (`Problem.objective`)."""

    def __init__(self, problem, started):
        self.problem, self.started = problem, started

    def __call__(self, theta, args):
        return self.problem.all_residuals(theta)[self.problem.mask], None

    def jacobian(self, theta, args):
        if self.started:
            return self.problem.jacobian(theta)
        self.started = True
        r, j = self.problem.start(theta)
        if not np.all(np.isfinite(r)) or not np.all(np.isfinite(j)):  # the experiments' own causes where known
            named = failed_solves(self.problem.space, theta, self.problem.exps, r)
            raise PamjaxInputError("the start model's simulation fails (non-finite residuals or Jacobian): " + (
                named or "check the start values and the experiments' initial states"))
        return r, j
