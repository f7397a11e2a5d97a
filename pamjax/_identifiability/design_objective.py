"""The objective of `pamjax.design_experiment`: the information a PWM duty signal gives about named parameters, and
the bench's constraints, as one compiled function of the signal's coefficients.

For a recording of channels y_c with Gaussian noise of standard deviation σ_c, the Fisher information about the
fit's scaled parameters θ (`pamjax.ParameterSpace`) is

    F(u) = F_prior + (f_rec / f_design) Σ_samples J_iᵀ J_i,      J_i = ∂(y_c(t_i; θ, u) / σ_c) / ∂θ,

with J one forward-mode Jacobian through the solve (the fit's own residual function, `pamjax._fit.problem`), F_prior the
information of the experiments already in hand, f_rec the recording's sample rate and f_design the (coarser) rate
at which the objective samples the run. Its inverse is the Cramér-Rao bound on the covariance of θ̂. The criteria,
on a subset S of the parameters (all by default), are minimised:

    D: log det (F⁻¹)_SS        (D_s-optimal; −log det F when S is every parameter)
    A: log tr (F⁻¹)_SS         (A-optimal, in the scaled coordinates: relative errors for positive parameters)

The duty of PWM period k is u_k = lo + (hi − lo) clip₀₁(z_k), clip₀₁ a softplus clip of width `CLIP_WIDTH`, with
z = Φ c: one coefficient per period (Φ = I), or the "envelope" parametrisation z_k = m(t_k) + s(t_k) ξ_k, where m
and s are cubic B-splines of K coefficients each and ξ a fixed pseudo-random multilevel carrier (the gradient sets
where the run dwells, m, and how hard it is excited there, s).

Constraints enter as quadratic penalties on their violation (the optimiser also refuses steps that leave a feasible
point): the stroke within the end stops less a margin, the pressure below a limit, |u_k − u_{k−1}| below a rate
limit, the muscle's static force (eq. 7, before the slack) above a margin where the payload hangs free and above
0 N where it rests on the lower stop (`force_floor`; penalised from `FORCE_BUFFER` above it), and, when a baseline is
given, each named parameter's variance below the baseline experiment's. (The duty's distance from the valve's
switching thresholds is kept exactly, by the band `lo`, `hi` of the clip.)
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import device_array
from .._fit.predictions import predict_all
from .._physics.smooth import smooth_relu

CLIP_WIDTH = 0.02  # width of the soft clip of z to [0, 1] (2 % of the duty band): a sharp band, nonzero gradient
STROKE_UNIT = 1e-3  # m: a stroke violation is penalised in mm
PRESSURE_UNIT = 1e3  # Pa: a pressure violation in kPa
STEP_UNIT = 0.01  # duty: a rate-limit violation in duty percent
FORCE_UNIT = 1.0  # N: a violation of the muscle's force margin in newtons
FORCE_BUFFER = 5.0  # N: the force penalty acts from min_force + 5 N, the limit itself from min_force: the search sees
# the limit's gradient before it reaches it (a step may not cross it, so without one it crawls along it), and the
# PWM ripple between the objective's samples (≈ 4 N on the MAS-10 example: `design.VERIFY_TOLERANCE`) stays above it
STOP_TOLERANCE = 1e-6  # m: a payload within 1 µm of the lower stop rests on it (the stop holds it at its position)
PENALTY = 100.0  # weight of a squared violation of one unit per second of run (stroke, pressure) or per period
FLOOR_PENALTY = 1000.0  # weight of a squared excess of a log variance over the baseline's (~0.5 % slack)


def clip01(z):
    """Soft clip of `z` to [0, 1] (`smooth_relu(z) − smooth_relu(z − 1)`, width `CLIP_WIDTH`): exactly inside
    (0, 1), within `CLIP_WIDTH · log 2` of the sharp clip."""
    return smooth_relu(z, CLIP_WIDTH) - smooth_relu(z - 1.0, CLIP_WIDTH)


@jax.jit
def clip01_and_slope(z):
    """`clip01(z)` and its derivative, elementwise, compiled as one program (run eagerly, each of their operations
    compiles on its own: a dozen programs per shape)."""
    return clip01(z), jax.vmap(jax.grad(clip01))(z)


def unclip01(d):
    """The inverse of `clip01` for d in (0, 1) (a few Newton steps from the sharp clip)."""
    d = np.clip(np.asarray(d, dtype=float), 1e-6, 1.0 - 1e-6)
    z = d.copy()
    for _ in range(50):
        value, slope = (np.asarray(a) for a in clip01_and_slope(device_array(z)))
        z = z - (value - d) / np.maximum(slope, 1e-12)
    return z


def bspline_basis(times, start, end, count):
    """Values (len(times), count) of `count` clamped uniform cubic B-splines on [start, end] (Cox-de Boor)."""
    if count < 4:
        raise ValueError("count must be >= 4 for cubic B-splines")
    inner = np.linspace(start, end, count - 2)
    knots = np.concatenate([[start] * 3, inner, [end] * 3])
    t = np.clip(np.asarray(times, dtype=float), start, end - 1e-12 * max(1.0, abs(end)))
    basis = np.array([(knots[i] <= t) & (t < knots[i + 1]) for i in range(len(knots) - 1)], dtype=float)
    for degree in range(1, 4):
        new = np.zeros((len(knots) - 1 - degree, t.size))
        for i in range(new.shape[0]):
            left = knots[i + degree] - knots[i]
            right = knots[i + degree + 1] - knots[i + 1]
            if left > 0:
                new[i] += (t - knots[i]) / left * basis[i]
            if right > 0:
                new[i] += (knots[i + degree + 1] - t) / right * basis[i + 1]
        basis = new
    return basis.T


def envelope_basis(times, duration, knots, carrier):
    """Φ = [B, B ξ] of the envelope parametrisation: z = B c_m + (B c_s) ξ."""
    b = bspline_basis(times, 0.0, duration, knots)
    return np.concatenate([b, b * np.asarray(carrier)[:, None]], axis=1)


def multilevel_carrier(count, hold, seed):
    """A pseudo-random multilevel sequence in [−1, 1], each level held `hold` periods (seeded)."""
    rng = np.random.default_rng(seed)
    return np.repeat(rng.uniform(-1.0, 1.0, count // hold + 1), hold)[:count]


class DesignProblem(eqx.Module):
    """Everything the compiled objective needs; fields marked static fix the compiled program's structure, so
    designs of one structure (same system, parameters, duration, parametrisation) share one compilation."""

    space: eqx.Module  # ParameterSpace at the design point
    theta: jax.Array
    experiment: eqx.Module  # Experiment whose signal is a Sampled duty (values replaced per evaluation)
    basis: jax.Array | None  # (periods, p); None: one coefficient per period
    prior: jax.Array  # (n, n) information already in hand
    weight: jax.Array  # f_rec / f_design
    band: jax.Array  # (lo, hi) duty
    windows: jax.Array | None  # (k, 2): duty windows (θ − m, θ + m) around switching thresholds inside the band
    stroke: jax.Array | None  # (lo, hi) allowed positions [m], margin included; None: no position channel/limit
    max_pressure: jax.Array | None  # Pa abs
    max_step: jax.Array | None  # per PWM period
    min_force: jax.Array | None  # N, eq. 7's force kept above it (−inf: no limit); None: the system has no muscle
    floor: jax.Array | None  # (n,) baseline variances of θ (inf where not constrained)
    subset: tuple = eqx.field(static=True)
    criterion: str = eqx.field(static=True)
    offset: jax.Array | None = None  # (periods,): z's fixed part beside basis @ c (a given start the envelope cannot
    # represent, `design_setup.start_offset`); None: none

    def duty(self, c):
        z = c if self.basis is None else self.basis @ c
        z = z if self.offset is None else z + self.offset
        u = self.band[0] + (self.band[1] - self.band[0]) * clip01(z)
        return u if self.windows is None else skip_windows(u, self.windows)


def skip_windows(u, windows):
    """Each duty inside a window (lo, hi) moved to the window's nearer end: no period sits within the margin of a
    switching threshold. The valve's flow already jumps where a duty crosses the threshold (a period opens it or not);
    this moves the jump to the window's middle and widens it to the window, and the duty's derivative is 0 inside."""
    for i in range(windows.shape[0]):
        lo, hi = windows[i, 0], windows[i, 1]
        u = jnp.where((u > lo) & (u < hi), jnp.where(u < 0.5 * (lo + hi), lo, hi), u)
    return u


def _criterion(cov, subset, criterion):
    block = cov[jnp.asarray(subset)][:, jnp.asarray(subset)]
    if criterion == "D":
        return jnp.linalg.slogdet(block)[1]
    return jnp.log(jnp.trace(block))


def on_lower_stop(position, lower_stop):
    """Whether the payload rests on the lower stop at each sample (within `STOP_TOLERANCE`)."""
    return position <= lower_stop + STOP_TOLERANCE


def force_floor(position, lower_stop, min_force, xp=jnp):
    """The force eq. 7 must keep at each sample: `min_force` where the payload hangs free; where it rests on the lower
    stop, only tension (0 N, or `min_force` if lower): the stop carries the payload there, so the force law is not
    seen (the payload stays until the muscle pulls its weight, far above the limit), but the muscle's geometry is,
    through its volume, which the volume law gives only while the muscle is taut."""
    return xp.where(on_lower_stop(position, lower_stop), xp.minimum(min_force, 0.0), min_force)


def evaluate(c, problem: DesignProblem):
    """(objective, aux): the criterion plus the penalties at coefficients `c`; aux holds the criterion, the
    penalties, the largest violations (stroke [m], pressure [Pa], duty step, force [N]), the duty, and the predicted
    position, pressure and eq. 7 force at the design samples."""
    duty = problem.duty(c)
    exp = eqx.tree_at(lambda e: e.signal.values, problem.experiment, duty)

    def scaled(theta):
        pred = predict_all(problem.space.model(theta), (exp,))[0]
        return exp.residuals_of(pred, "all"), pred

    jac, pred = jax.jacfwd(scaled, has_aux=True)(problem.theta)
    info = problem.prior + problem.weight * (jac.T @ jac)
    cov = jnp.linalg.inv(info)
    crit = _criterion(cov, problem.subset, problem.criterion)
    dt = exp.times[1] - exp.times[0]
    zero = jnp.zeros(())
    pen_stroke = pen_pressure = pen_step = pen_floor = pen_force = zero
    worst_stroke = worst_pressure = worst_step = worst_force = zero
    force = None
    if problem.stroke is not None:
        x = pred["position"]
        over = jnp.maximum(x - problem.stroke[1], 0.0) + jnp.maximum(problem.stroke[0] - x, 0.0)
        pen_stroke = PENALTY * dt * jnp.sum((over / STROKE_UNIT) ** 2)
        worst_stroke = jnp.max(over)
    if problem.max_pressure is not None:
        over = jnp.maximum(pred["pressure"] - problem.max_pressure, 0.0)
        pen_pressure = PENALTY * dt * jnp.sum((over / PRESSURE_UNIT) ** 2)
        worst_pressure = jnp.max(over)
    if problem.max_step is not None:
        over = jnp.maximum(jnp.abs(jnp.diff(duty)) - problem.max_step, 0.0)
        pen_step = PENALTY * jnp.sum((over / STEP_UNIT) ** 2)
        worst_step = jnp.max(over)
    if problem.min_force is not None:
        system = exp.system_for(problem.space.model(problem.theta))
        force = system.muscle.static_force(pred["position"], pred["pressure"], system.air)
        floor = force_floor(pred["position"], system.muscle.min_position, problem.min_force)
        near = jnp.maximum(floor + FORCE_BUFFER - force, 0.0)
        pen_force = PENALTY * dt * jnp.sum((near / FORCE_UNIT) ** 2)
        worst_force = jnp.max(jnp.maximum(floor - force, 0.0))
    if problem.floor is not None:
        excess = jnp.where(jnp.isfinite(problem.floor), jnp.log(jnp.diag(cov)) - jnp.log(problem.floor), 0.0)
        pen_floor = FLOOR_PENALTY * jnp.sum(jnp.maximum(excess, 0.0) ** 2)
    total = crit + pen_stroke + pen_pressure + pen_step + pen_force + pen_floor
    aux = dict(criterion=crit, penalty=pen_stroke + pen_pressure + pen_step + pen_force + pen_floor,
               floor_penalty=pen_floor, worst_stroke=worst_stroke, worst_pressure=worst_pressure, worst_step=worst_step,
               worst_force=worst_force, duty=duty, position=pred.get("position"), pressure=pred.get("pressure"),
               force=force, information=info)
    return total, aux


@eqx.filter_jit
def value(c, problem):
    """The objective and its aux (module level: designs of one structure share the compilation)."""
    return evaluate(c, problem)


@eqx.filter_jit
def forward_gradient(c, problem):
    """d objective / dc in forward mode (one tangent per coefficient): for a few dozen coefficients."""
    return jax.jacfwd(lambda q: evaluate(q, problem)[0])(c)


@eqx.filter_jit
def reverse_gradient(c, problem):
    """d objective / dc in reverse mode (a reverse pass over the forward-mode Jacobian): for one coefficient per
    PWM period. Memory and time grow with the run (about 50× a Jacobian on a 2-core CPU for 33 s)."""
    return jax.grad(lambda q: evaluate(q, problem)[0])(c)
