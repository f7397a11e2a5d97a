"""Bench tests that are not time series: constant-velocity friction runs, ISO 6358 flow-curve tests and force maps
with their hysteresis loop. Each is an experiment `pamjax.fit` takes beside `Experiment` and `ForceMapExperiment`,
and each comes with the reduction that turns a raw bench record into its data points.

- `FrictionCurveExperiment` (paper 000, Fig. 6, eq. 9): friction force against constant sliding velocity; the model's
  friction at steady sliding (`steady_friction_force`). `constant_velocity_point` reduces one run to (v, F).
- `FlowCurveExperiment` (paper 000, eq. 10-11, Table 1, Fig. 7; paper 001, eq. 1-2): mass flow through one valve path
  against upstream and downstream pressure, as ISO 6358-1 measures it (upstream held, downstream throttled);
  `flow_curve` gives a restriction's curve.
- `ForceMapExperiment`: static isometric forces F(x, p) compared with `muscle.static_force`; slack points (measured
  0 N) only penalise a positive model force.
- `LoopForceMapExperiment` (paper 000, Figs. 3 and 5, eq. 8-9): direction-dependent static forces, F = F_static(x, p)
  − F_friction(ẋ); `loop_average` gives the averaged map (Fig. 4) and the loop widths (paper: 32 N).
- `HysteresisLoopExperiment` (paper 000, Figs. 3 and 5): the same loop read as a path, in the order measured, with a
  stateful friction's state carried along it, so that a friction whose force moves between the branches after a
  reversal (`BoucWenFriction`) is compared point by point.

All pressures are ABSOLUTE [Pa]; x is the muscle's shortening [m] and ẋ its rate (positive = contracting).
"""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.custom_types import (
    BoolTableLike,
    FloatArray,
    FloatVector,
    RealArrayLike,
    RealScalarLike,
    RealVectorLike,
    TableLike,
)
from .._core.errors import PamjaxInputError
from .._physics.friction import AbstractFriction
from .._physics.gas import AbstractRestriction, Air
from .._physics.muscle import AbstractMuscle
from .._systems.base import AbstractMuscleSystem, AbstractSystem
from .experiment import AbstractExperiment
from .static_checks import (
    check_absolute,
    check_decimals,
    check_flow_curve,
    check_kind,
    check_loaded_above_atmosphere,
    check_map,
    check_moving,
    check_path,
    check_scale,
    check_stroke,
    check_unit,
    columns,
    component_path,
    numbers,
    set_data,
    slack_points,
)


class Component(eqx.Module):
    """The part of a model an experiment looks at, by attribute path: `Component("valve.inflate")`,
    `Component("friction")`; `Component("")` is the model itself. The path is the user's (a parameter path's
    prefix), walked generically, and what it ends at is checked against the contract `kind` it must keep."""

    path: str = eqx.field(static=True)

    def __call__(self, model, kind=object, experiment="experiment"):
        """The component of `model`; a `PamjaxInputError` naming `experiment` unless it is a `kind`."""
        for name in filter(None, self.path.split(".")):
            if not hasattr(model, name):
                raise PamjaxInputError(f"{experiment}: the model ({type(model).__name__}) has no {name!r} on the path "
                                       f"{self.path!r}")
            model = getattr(model, name)
        if not isinstance(model, kind):
            where = f"the model's {self.path!r}" if self.path else "the model"
            raise PamjaxInputError(f"{experiment}: {where} is {type(model).__name__}; a {kind.__name__} is needed")
        return model


def _air(model):
    """The system's air; the standard air for a component on its own (a muscle, a restriction, a friction)."""
    return model.air if isinstance(model, AbstractSystem) else Air()


def steady_friction_force(friction: AbstractFriction, velocity: RealArrayLike) -> FloatArray:
    """Friction force [N] at steady sliding with constant `velocity` [m/s] ≠ 0 (paper 000 eq. 9: F_c sign(v) + C_f v;
    at v = 0 the friction's at rest: 0 N for a Bouc–Wen one, whose `steady_state(0)` is its rest state, and for a
    bristle one, whose state stays undeflected there).

    Memoryless frictions are evaluated directly; a hybrid (stick-slip) friction in its sliding mode sign(v); a friction
    with its own state (bristles) at the state where that state is at rest (Newton on `state_rate(v, z) = 0`)."""
    check_kind(friction, AbstractFriction, "friction", "a friction model, e.g. pj.KarnoppFriction()")
    velocity = jnp.asarray(velocity, dtype=float)
    return friction.force(velocity, sliding_state(friction, velocity))


def sliding_state(friction: AbstractFriction, velocity):
    """The friction's state at steady sliding with constant `velocity` [m/s] ≠ 0 (None for a memoryless friction):
    the sliding mode sign(v) of a hybrid one, the friction's own `steady_state(v)` where it gives one, else Newton on
    `state_rate(v, z) = 0` from the initial state."""
    velocity = jnp.asarray(velocity, dtype=float)
    z = friction.initial_state()
    if z is None:
        return None
    if friction.hybrid:
        return jnp.sign(velocity)
    steady = friction.steady_state(velocity)
    if steady is not None:
        return steady
    z = jnp.zeros_like(velocity) + z
    for _ in range(4):  # state_rate is affine in z for the bristle model: the first step is exact
        rate, slope = jax.jvp(lambda q: friction.state_rate(velocity, q), (z,), (jnp.ones_like(z),))
        # at v = 0 the bristle's rate is 0 for every z (slope 0): the state stays at rest, where a step 0/0 made the
        # force and its gradient NaN; the slope kept off 0 on both branches of `where`, so the gradient stays finite
        flat = slope == 0
        z = z - jnp.where(flat, 0.0, rate / jnp.where(flat, 1.0, slope))
    return z


def constant_velocity_point(t: TableLike, position: TableLike, force: TableLike) -> tuple[float, float, float]:
    """One constant-velocity friction run reduced to (velocity [m/s], mean force [N], its standard error [N]).

    The velocity is the least-squares slope of `position` [m] over `t` [s]; the force is the mean of `force` [N] (the
    cylinder's chamber-pressure difference times area, or the load cell; paper 000, Fig. 6 procedure). Pass only the
    part of the run at constant velocity."""
    t, x, f = (numbers(name, a) for name, a in (("t", t), ("position", position), ("force", force)))
    if not (t.ndim == x.ndim == f.ndim == 1 and t.size == x.size == f.size and t.size >= 3):
        raise PamjaxInputError(f"t, position, force must be 1-D of one length >= 3: {t.shape}, {x.shape}, {f.shape}")
    for name, a in (("t", t), ("position", x), ("force", f)):
        if not np.all(np.isfinite(a)):
            raise PamjaxInputError(f"{name} must be finite, NaN/inf at row {int(np.argmin(np.isfinite(a)))}")
    if np.ptp(t) == 0:  # (no slope to fit: NumPy's least squares fails with a LinAlgError)
        raise PamjaxInputError(f"t must span a time (the velocity is the slope of position over t), all are {t[0]:g}")
    velocity = float(np.polyfit(t, x, 1)[0])
    return velocity, float(np.mean(f)), float(np.std(f, ddof=1) / np.sqrt(f.size))


def flow_curve(restriction: AbstractRestriction, upstream_pressure: RealScalarLike, ratios: RealVectorLike,
               air: Air) -> FloatVector:
    """Mass flow [kg/s] through `restriction` from `upstream_pressure` [Pa abs] to `ratios` × that pressure: the
    ISO 6358-1 flow curve (upstream held, downstream throttled). The ratios lie in [0, 1]; each argument is checked
    (`check_flow_curve`) as `FlowCurveExperiment` checks its columns."""
    check_kind(restriction, AbstractRestriction, "restriction", "a restriction, e.g. a valve's inflate path")
    check_kind(air, Air, "air", "the air, e.g. pj.Air()")
    check_flow_curve(upstream_pressure, ratios)
    p1 = jnp.asarray(upstream_pressure, dtype=float)
    return jax.vmap(lambda r: restriction.mass_flow(p1, r * p1, air))(jnp.asarray(ratios, dtype=float))


class ForceMapExperiment(AbstractExperiment):
    """Static force map: measured muscle forces [N] at positions x [m] and ABSOLUTE pressures [Pa].

    Residual (F_model − F) / scale at loaded points; at slack points (measured F ≤ `slack_force`, default 0 N) only a
    positive model force counts: max(F_model, 0) / scale ("force ≤ 0 → 0", the muscle cannot push).

    **Arguments:** `positions` [m] (the contraction L0 − L, within the muscle's stroke: `check` refuses a length L),
    `pressures` [Pa abs] (a loaded point at or below one atmosphere is refused: gauge pressures), `forces` [N] (at
    least one above `slack_force`), `scale` [N] (default 1 % of the force range), `slack_force` [N], `name`. The
    model is a muscle system (its `muscle`) or a muscle.
    """

    positions: jax.Array
    pressures: jax.Array
    forces: jax.Array
    slack: jax.Array
    scale: float = eqx.field(static=True)
    name: str = eqx.field(static=True)
    channels: tuple = eqx.field(static=True, default=("force",))

    def __init__(self, positions: TableLike, pressures: TableLike, forces: TableLike,
                 scale: RealScalarLike | None = None, slack_force: RealScalarLike = 0.0, name: str = "force_map"):
        x, p, f = columns(("positions", "pressures", "forces"), (positions, pressures, forces))
        check_map(x, p)  # pressures above half an atmosphere: a vented muscle reads about 101325 Pa absolute
        self.positions, self.pressures, self.forces = jnp.asarray(x), jnp.asarray(p), jnp.asarray(f)
        self.slack = slack_points(f, slack_force)  # and a map with no loaded point refused
        check_loaded_above_atmosphere(p, f, self.slack)  # gauge pressures once the slack (0 N) rows are dropped
        self.scale = check_scale(f, scale, "N")  # as the other bench tests' (`set_data`)
        self.name = str(name)
        self.channels = ("force",)

    @property
    def noise_channels(self):
        return ()  # `scale` is not declared the noise level: the diagnostics estimate it from the residuals

    @property
    def split_time(self):
        return None  # no time axis: every point is fitted

    @staticmethod
    def _muscle(model):
        return model.muscle if isinstance(model, AbstractMuscleSystem) else model

    def check(self, model):
        if not isinstance(self._muscle(model), AbstractMuscle):
            raise PamjaxInputError(f"{self.name}: the model has no muscle (needs model.muscle or a Muscle)")
        check_stroke(self.name, self.positions, self._muscle(model))

    def predict(self, model):
        muscle, air = self._muscle(model), _air(model)
        return {"force": jax.vmap(lambda x, p: muscle.static_force(x, p, air))(self.positions, self.pressures)}

    def layout(self):
        ones = np.ones(self.forces.shape, dtype=bool)
        return [("force", self.scale, np.asarray(self.forces), ones, ones)]

    def residuals_of(self, pred, part="identification"):
        del part
        return jnp.where(self.slack, jnp.maximum(pred["force"], 0.0), pred["force"] - self.forces) / self.scale


class AbstractStaticExperiment(AbstractExperiment):
    """A fit experiment without a time axis: `predict(model)` gives one channel at the data points, the residual is
    (model − data)/scale, every point is compared and none is held out (the fitter's `layout`)."""

    @property
    def noise_channels(self):
        return ()  # `scale` is not declared the noise level: the diagnostics estimate it from the residuals

    @property
    def split_time(self):
        return None  # no time axis: every point is fitted

    @abc.abstractmethod
    def predict(self, model):
        """{channel: the model's values at the data points} (traceable)."""

    needs_muscle_system = False  # the force maps: the model must have a muscle and a friction, and their positions
    # must lie within the muscle's stroke (`check_stroke`)

    def check(self, model):
        if self.needs_muscle_system and not isinstance(model, AbstractMuscleSystem):
            raise PamjaxInputError(f"{self.name}: the model needs a 'muscle' and a 'friction' (a muscle system, e.g. "
                                   f"MuscleSystem), got {type(model).__name__}")
        if self.needs_muscle_system:
            check_stroke(self.name, self.positions, model.muscle)
        pred = eqx.filter_eval_shape(self.predict, model)  # shapes only: no compilation, nothing computed
        (channel,) = self.channels
        if channel not in pred or np.shape(pred[channel]) != np.shape(self.data[channel]):
            raise PamjaxInputError(f"{self.name}: the model does not predict {channel!r} at the data points")

    def layout(self):
        (channel,) = self.channels
        data = np.asarray(self.data[channel])
        every = np.ones(data.shape, dtype=bool)
        return [(channel, self.scale, data, every, every)]

    def residuals_of(self, pred, part="identification"):
        del part
        (channel,) = self.channels
        return (pred[channel] - self.data[channel]) / self.scale


class FrictionCurveExperiment(AbstractStaticExperiment):
    """Friction force measured at constant sliding velocities (paper 000, Fig. 6: a cylinder driven at constant
    velocities, the friction from its chamber pressures; muscle + cylinder from the load cell).

    Residual: (`steady_friction_force(friction, v)` − F) / scale.

    **Arguments:** `velocities` [m/s] (≠ 0; sign = direction), `forces` [N] (the friction force, positive opposing
    positive velocity), `scale` [N] (noise level; default 1 % of the force range), `friction`: the component path
    (default "friction"; "" when the model is the friction itself), `name`.
    """

    velocities: jax.Array
    data: dict
    scale: float = eqx.field(static=True)
    friction: Component
    name: str = eqx.field(static=True)
    channels: tuple = eqx.field(static=True)

    def __init__(self, velocities: TableLike, forces: TableLike, scale: RealScalarLike | None = None,
                 friction: str = "friction", name: str = "friction_curve"):
        v, f = columns(("velocities", "forces"), (velocities, forces))
        check_moving(v, "sliding")
        self.velocities = jnp.asarray(v)
        self.friction = Component(component_path(friction, "friction", "friction"))
        set_data(self, "force", f, scale, "N", name)

    def predict(self, model):
        return {"force": steady_friction_force(self.friction(model, AbstractFriction, self.name), self.velocities)}


class FlowCurveExperiment(AbstractStaticExperiment):
    """Mass flow through one valve path measured at pairs of upstream/downstream pressures: ISO 6358-1's test (paper
    000: three upstream pressures 0.5/0.6/0.7 MPa per path, C_v and b_v of eq. 11 fitted, Table 1, Fig. 7).

    Residual: (restriction.mass_flow(p_up, p_down) − ṁ) / scale.

    **Arguments:** `upstream_pressures`, `downstream_pressures` [Pa abs], `mass_flows` [kg/s], `scale` [kg/s]
    (default 1 % of the flow range), `restriction`: the component path (e.g. "valve.inflate", "valve.exhaust";
    "" when the model is the restriction), `name`.
    """

    upstream_pressures: jax.Array
    downstream_pressures: jax.Array
    data: dict
    scale: float = eqx.field(static=True)
    restriction: Component
    name: str = eqx.field(static=True)
    channels: tuple = eqx.field(static=True)

    def __init__(self, upstream_pressures: TableLike, downstream_pressures: TableLike, mass_flows: TableLike,
                 scale: RealScalarLike | None = None, restriction: str = "valve.inflate", name: str = "flow_curve"):
        p1, p2, m = columns(("upstream_pressures", "downstream_pressures", "mass_flows"),
                             (upstream_pressures, downstream_pressures, mass_flows))
        check_absolute("upstream_pressures", p1)
        check_absolute("downstream_pressures", p2)
        check_unit("mass_flow", m, "mass_flows")  # g/s (a flow meter's display) refused as `Recording` refuses it
        self.upstream_pressures, self.downstream_pressures = jnp.asarray(p1), jnp.asarray(p2)
        self.restriction = Component(component_path(restriction, "restriction", "valve.inflate"))
        set_data(self, "mass_flow", m, scale, "kg/s", name)

    def predict(self, model):
        restriction, air = self.restriction(model, AbstractRestriction, self.name), _air(model)
        flow = jax.vmap(lambda p1, p2: restriction.mass_flow(p1, p2, air))
        return {"mass_flow": flow(self.upstream_pressures, self.downstream_pressures)}


class LoopForceMapExperiment(AbstractStaticExperiment):
    """A force map with its hysteresis loop (paper 000, Figs. 3 and 5): the muscle moved slowly in and out at fixed
    pressures, the force read with the direction of motion. Model (eq. 8-9): F = F_static(x, p) − F_f(ẋ), F_f the
    friction at steady sliding (F_c sign(ẋ) + C_f ẋ): lower while contracting, higher while stretched.

    Slack points (measured F ≤ `slack_force`, 0 N by default) only penalise a positive model force, as in
    `ForceMapExperiment`.

    **Arguments:** `positions` x [m] (shortening L0 − L, within the muscle's stroke), `pressures` [Pa abs],
    `velocities` ẋ [m/s] (≠ 0; sign = direction), `forces` [N], `scale` [N] (default 1 % of the force range),
    `slack_force` [N], `name`. The model is a
    muscle system (`muscle`, `friction`, `air`).
    """

    positions: jax.Array
    pressures: jax.Array
    velocities: jax.Array
    slack: jax.Array
    data: dict
    scale: float = eqx.field(static=True)
    name: str = eqx.field(static=True)
    channels: tuple = eqx.field(static=True)

    def __init__(self, positions: TableLike, pressures: TableLike, velocities: TableLike, forces: TableLike,
                 scale: RealScalarLike | None = None, slack_force: RealScalarLike = 0.0, name: str = "loop_force_map"):
        x, p, v, f = columns(("positions", "pressures", "velocities", "forces"),
                              (positions, pressures, velocities, forces))
        check_map(x, p, v)
        self.positions, self.pressures, self.velocities = jnp.asarray(x), jnp.asarray(p), jnp.asarray(v)
        self.slack = slack_points(f, slack_force)
        set_data(self, "force", f, scale, "N", name)  # slack points: see `residuals_of`

    needs_muscle_system = True

    def predict(self, model):
        air = _air(model)
        static = jax.vmap(lambda x, p: model.muscle.static_force(x, p, air))(self.positions, self.pressures)
        return {"force": static - steady_friction_force(model.friction, self.velocities)}

    def residuals_of(self, pred, part="identification"):
        del part
        return jnp.where(self.slack, jnp.maximum(pred["force"], 0.0), pred["force"] - self.data["force"]) / self.scale


def loop_average(positions: TableLike, pressures: TableLike, velocities: TableLike, forces: TableLike,
                 decimals: int = 9) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Average the two branches of a hysteresis loop (paper 000, Fig. 4) and measure its width (paper: 32 N).

    Points with equal (x, p) measured in both directions (sign of ẋ) are paired. Returns (x [m], p [Pa], mean force
    [N], width [N] = F(stretching) − F(contracting)) for each pair, sorted by pressure then position."""
    check_decimals(decimals)
    x, p, v, f = columns(("positions", "pressures", "velocities", "forces"),
                          (positions, pressures, velocities, forces))
    keys = {}
    for xi, pi, vi, fi in zip(np.round(x, decimals), np.round(p, 3), np.sign(v), f):
        keys.setdefault((pi, xi), {}).setdefault(vi, []).append(fi)
    rows = [(xi, pi, 0.5 * (np.mean(d[1.0]) + np.mean(d[-1.0])), np.mean(d[-1.0]) - np.mean(d[1.0]))
            for (pi, xi), d in sorted(keys.items()) if 1.0 in d and -1.0 in d]
    if not rows:
        raise PamjaxInputError("no (position, pressure) point was measured in both directions")
    return tuple(np.array(c) for c in zip(*rows))


def path_friction_force(friction: AbstractFriction, positions: TableLike, velocities: TableLike,
                        starts: BoolTableLike, substeps: int = 4) -> FloatVector:
    """Friction force [N] at each sample of a quasi-static path: x = `positions` [m] in the order travelled, ẋ =
    `velocities` [m/s] (≠ 0), `starts` (bool) where a sweep begins.

    A memoryless or hybrid friction is evaluated at steady sliding (as `LoopForceMapExperiment`). A friction with a
    state of its own starts each sweep in its sliding state for the sweep's first velocity (the muscle has travelled
    that way before the sweep), then carries the state from sample to sample: between samples k−1 and k it moves at
    sign(x_k − x_{k−1}) · ½(|ẋ_{k−1}| + |ẋ_k|) for the time that takes, integrated by `substeps` RK4 steps. Each
    stage's state is kept within the sliding states ±z_s of that speed, which bound the state of a friction that
    saturates there (bristle, Bouc–Wen): where a transition is shorter than a sub-step (stiff), RK4 then lands on the
    branch instead of overshooting it.

    Checked as `HysteresisLoopExperiment` checks its path (`check_path`), concrete values before anything is computed:
    one NaN position made every force after it NaN, `substeps=0` carried no state past a reversal, `starts[0]` False
    began in the virgin state z = 0 instead of on a branch."""
    check_path(positions, velocities, starts, substeps)
    x, v = jnp.asarray(positions, dtype=float), jnp.asarray(velocities, dtype=float)
    if friction.initial_state() is None or friction.hybrid:
        return steady_friction_force(friction, v)
    dx = jnp.diff(x, prepend=x[:1])
    speed = 0.5 * (jnp.abs(v) + jnp.abs(jnp.concatenate([v[:1], v[:-1]])))
    step_velocity = jnp.sign(dx) * speed
    h = jnp.abs(dx) / speed / substeps
    at_start = jax.vmap(lambda w: sliding_state(friction, w))(v)
    bound = jnp.abs(jax.vmap(lambda w: sliding_state(friction, w))(step_velocity + (dx == 0) * v))

    def rk4(z, u, h, zmax):
        clip = lambda q: jnp.clip(q, -zmax, zmax)  # noqa: E731
        k1 = friction.state_rate(u, z)
        k2 = friction.state_rate(u, clip(z + 0.5 * h * k1))
        k3 = friction.state_rate(u, clip(z + 0.5 * h * k2))
        k4 = friction.state_rate(u, clip(z + h * k3))
        return clip(z + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4))

    def sample(z, inputs):
        u, hk, start, z_start, vk, zmax = inputs
        for _ in range(substeps):
            z = rk4(z, u, hk, zmax)
        z = jnp.where(start, z_start, z)
        return z, friction.force(vk, z)

    z0 = jnp.zeros_like(at_start[0])
    _, force = jax.lax.scan(sample, z0, (step_velocity, h, jnp.asarray(starts), at_start, v, bound))
    return force


class HysteresisLoopExperiment(AbstractStaticExperiment):
    """A force–displacement hysteresis loop read as a path (paper 000, Figs. 3 and 5): the muscle moved slowly in and
    out at fixed pressures, the force read with the direction of motion, the samples IN THE ORDER MEASURED. Model:
    F = F_static(x, p) − F_f, the friction F_f carried along the path (`path_friction_force`), so that the force
    after a reversal follows the friction's own transition between the branches. For a memoryless friction (eq. 8-9)
    it predicts what `LoopForceMapExperiment` does.

    Slack points (measured F ≤ `slack_force`) only penalise a positive model force, as in `ForceMapExperiment`.

    **Arguments:** `positions` x [m] (shortening L0 − L, within the muscle's stroke), `pressures` [Pa abs],
    `velocities` ẋ [m/s] (≠ 0; sign = direction), `forces` [N], in the order travelled; `scale` [N] (default 1 % of
    the force range); `slack_force` [N]; `starts`: bool per sample, True where a new sweep begins (default: the
    first sample and every change of pressure); `substeps`: RK4 steps per sample interval (4); `name`. The model is a
    muscle system (`muscle`, `friction`, `air`).
    """

    positions: jax.Array
    pressures: jax.Array
    velocities: jax.Array
    starts: jax.Array
    slack: jax.Array
    data: dict
    scale: float = eqx.field(static=True)
    name: str = eqx.field(static=True)
    channels: tuple = eqx.field(static=True)
    substeps: int = eqx.field(static=True)

    def __init__(self, positions: TableLike, pressures: TableLike, velocities: TableLike, forces: TableLike,
                 scale: RealScalarLike | None = None, slack_force: RealScalarLike = 0.0,
                 starts: BoolTableLike | None = None, substeps: int = 4, name: str = "hysteresis_loop"):
        x, p, v, f = columns(("positions", "pressures", "velocities", "forces"),
                              (positions, pressures, velocities, forces))
        check_map(x, p, v)
        if starts is None:
            starts = np.concatenate([[True], p[1:] != p[:-1]])
        check_path(x, v, starts, substeps)
        self.positions, self.pressures, self.velocities = jnp.asarray(x), jnp.asarray(p), jnp.asarray(v)
        self.starts = jnp.asarray(starts)
        self.slack = slack_points(f, slack_force)
        self.substeps = int(substeps)  # static: a Python int (a NumPy integer hashes as another program)
        set_data(self, "force", f, scale, "N", name)

    needs_muscle_system = True

    def predict(self, model):
        air = _air(model)
        static = jax.vmap(lambda x, p: model.muscle.static_force(x, p, air))(self.positions, self.pressures)
        friction = path_friction_force(model.friction, self.positions, self.velocities, self.starts, self.substeps)
        return {"force": static - friction}

    def residuals_of(self, pred, part="identification"):
        del part
        return jnp.where(self.slack, jnp.maximum(pred["force"], 0.0), pred["force"] - self.data["force"]) / self.scale
