"""What `equilibrium` and `linearise` (`pamjax._solve.linearise`) check in their answers and operating points: a
converged state the system can reach (not a spurious root of a flow law) and, for a hybrid system (stick-slip
friction, `KarnoppFriction`), a mode that holds there.

A stuck payload's rates (ẋ, ẍ) are exactly 0 at every position, so Newton's method keeps the guess's position: from
`presets.mas10_system("averaged", friction="karnopp")`'s guesses at 4e5 and 2.5e5 Pa, duty 0.5 converged at
26.96 and 16.85 mm, where the net force on the payload is 45.7 and 96.7 N, beyond the F_c = 16 N that holds it
(`simulate` from there moved it to 35.2 mm). Such a state is refused, not returned; a stuck state has no small-signal
model (three poles at 0: nothing moves until the net force reaches F_c), so `linearise` refuses it.
"""

import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._core.errors import PamjaxInputError, PamjaxSolveError, concrete_values
from .._core.units import MAX_ABSOLUTE_PA
from .._physics.regulator import AbstractRegulator
from .._physics.valves.base import AbstractValve
from .._systems.base import AbstractMuscleSystem
from .checks import START_STROKE_MARGIN

# Pressures and positions admitted beyond the bounds `equilibrium` checks (`check_reachable`), as a fraction of the
# bounds' span: a regulator settles its hysteresis and droop (25 and 50 mbar of its 6 bar) beyond its set pressure.
REACH_MARGIN = 0.05


def check_reachable(system, y, t):
    """A `PamjaxSolveError` for a converged `y` the system cannot reach, a spurious root (eq. 13's polynomial in p has
    one at 2.52 MPa abs for the MAS-10 at duty 0.1, 4x its 0.65 MPa supply; `simulate` settles at 0.131 MPa): a
    pressure ≤ 0 or outside [atmosphere, the highest one its elements feed] where each says one (a continuous valve:
    where its flow stops at every command, in 2.5 kPa steps; a regulator with a flow law into its chamber: its highest
    set pressure), or a position beyond its stroke by more than `START_STROKE_MARGIN`. A traced `y` is not checked."""
    if any(concrete_values(leaf) is None for leaf in jtu.tree_leaves(y)):
        return
    air, tops, atmosphere = system.air, [], float(system.air.atmospheric_pressure)
    for element in system.actuators.values():
        if isinstance(element, AbstractValve):
            gauge, (lo, hi) = np.arange(0.0, MAX_ABSOLUTE_PA + 1.0, 2.5e3), element.command_range
            flow = element.mass_flow(t, jnp.linspace(lo, hi, 51)[:, None], atmosphere + gauge, air)
            filling = np.asarray(flow) > 0
            tops.append(None if np.any(np.all(filling, axis=1)) else np.max(gauge[np.argmax(~filling, axis=1)]))
        else:
            flow_law = isinstance(element, AbstractRegulator) and element.needs_volume
            tops.append(element.max_gauge_pressure(air) if flow_law else None)
    top = None if any(h is None for h in tops) else float(np.max(np.asarray(tops, dtype=float)))
    bounds = (0.0, np.inf) if top is None else (atmosphere - REACH_MARGIN * top, atmosphere + (1 + REACH_MARGIN) * top)
    limits = [(path, float(p), bounds, "Pa abs") for path, p in system.start_pressures(y).items()]
    for path, (x, stroke) in system.start_positions(y).items():
        lo, hi = (-np.inf, np.inf) if stroke is None else map(float, stroke)
        give = START_STROKE_MARGIN * (hi - lo)
        limits.append((path, float(x), (lo - give, hi + give), "m"))
    if found := [f"{path} = {v:.6g} {unit} lies outside [{lo:.6g}, {hi:.6g}] {unit}"
                 for path, v, (lo, hi), unit in limits if not lo < v <= hi]:
        raise PamjaxSolveError(
            f"equilibrium: Newton's method converged to a state the system cannot reach, a spurious root of its flow "
            f"law: {'; '.join(found)} (from the atmosphere it exhausts to up to the highest pressure its supply "
            f"feeds, and the stroke, {REACH_MARGIN:.0%} beyond admitted). Start from a guess nearer the expected "
            "state, or simulate to rest first (`pamjax.simulate` with a long horizon, or `pamjax.steady_state_map`) "
            "and pass its last state as the guess")


def _stick_slip(system, state):
    """(friction, whether `state` holds it stuck) of a muscle system with a hybrid friction (`AbstractFriction.hybrid`,
    its mode the state's `friction`: `is_stuck`), else None (a smooth system, a traced state)."""
    if not isinstance(system, AbstractMuscleSystem) or not system.friction.hybrid or state.friction is None:
        return None
    mode = concrete_values(state.friction)
    return None if mode is None else (system.friction, bool(np.all(np.asarray(system.friction.is_stuck(mode)))))


def _smooth_twin(friction):
    return (f"the smooth twin CoulombViscousFriction(coulomb_force={float(friction.coulomb_force):g}, "
            f"viscous_coefficient={float(friction.viscous_coefficient):g}) (eqx.tree_at(lambda s: s.friction, system, "
            "...); BristleFriction also holds a payload still, elastically)")


def check_not_stuck(system, state, name="state"):
    """`linearise`'s refusal of a stuck state of a stick-slip friction: the payload is held still whatever a small
    input does until the net force reaches F_c, so the position and velocity rates are 0 (poles at 0, no small-signal
    model). A sliding state (smooth within its mode) passes, as do smooth systems and traced states."""
    found = _stick_slip(system, state)
    if found is None or not found[1]:
        return
    friction = found[0]
    raise PamjaxInputError(
        f"linearise: {name} holds the payload stuck ({type(friction).__name__}'s stuck mode, {name}.friction = 0): "
        f"it does not move under any small input until the net force on it reaches F_c = "
        f"{float(friction.coulomb_force):g} N, so its position and velocity rates are 0 there whatever the input "
        f"(poles at 0): a stick-slip friction has no small-signal model at rest. Linearise the system with "
        f"{_smooth_twin(friction)}, about that system's equilibrium")


def check_guess_at_rest(system, guess):
    """`equilibrium`'s refusal, before Newton's method, of a guess of a stick-slip friction that is not at rest in the
    stuck mode: a sliding mode (every equilibrium is at rest, v = 0, where a sliding mode ends: the payload sticks or
    slides the other way; Newton's method moved its mode ±1 to 0.86 to balance the forces), or a stuck one with a
    velocity (the stuck mode's zero rates keep it: a 0.2 m/s "equilibrium")."""
    found = _stick_slip(system, guess)
    moving = None if found is None else concrete_values(guess.velocity)
    if found is None or moving is None:
        return
    friction, stuck = found
    speed = float(np.max(np.abs(moving)))
    if stuck and speed == 0:
        return
    mode = f"stuck (friction = 0) at velocity {speed:.3g} m/s" if stuck else f"sliding at velocity {speed:.3g} m/s"
    raise PamjaxInputError(
        f"equilibrium: guess is {mode} ({type(friction).__name__}'s mode): an equilibrium is at rest in the stuck "
        "mode (at rest a sliding mode ends: the payload sticks, or slides the other way). Pass a guess at rest: "
        f"system.initial_state(pressure=..., position=...) starts stuck; or use {_smooth_twin(friction)}")


def check_mode_holds(system, y, t, command):
    """`equilibrium`'s check of a converged state `y` of a hybrid system (its guess at rest and stuck:
    `check_guess_at_rest`): a `PamjaxSolveError` where the stuck mode does not hold there, the static friction that
    holds the payload (the `friction_force` output of the stuck mode: the net force on it) beyond ±F_c (a rounding's
    give, 1e-9 F_c); the stuck mode's zero rates otherwise made any position an "equilibrium". Smooth systems and
    traced states pass."""
    found = _stick_slip(system, y)
    if found is None:
        return
    friction, stuck = found
    kind = type(friction).__name__
    out = system.outputs(t, y, command)
    held, limit = float(out["friction_force"]), float(friction.coulomb_force)
    if stuck and abs(held) <= limit * (1.0 + 1e-9):
        return
    rest = system.initial_state(pressure=out["pressure"])  # friction-free: the payload's weight carried
    where, free = (f"{float(v) * 1e3:.6g} mm" for v in (out["position"], rest.position))
    what = (f"{kind} holds the payload stuck there, but the net force on it is {held:.4g} N, beyond F_c = {limit:g} N, "
            "so it slides away at once" if stuck else f"Newton's method left {kind}'s stuck mode (friction = "
            f"{float(y.friction):g})")
    raise PamjaxSolveError(
        f"equilibrium: no equilibrium at position = {where}: {what}. In the stuck mode the position and velocity "
        "rates are 0 at every position, so Newton's method keeps the guess's position; pass a guess whose position "
        f"the friction holds (at its pressure {float(out['pressure']):.6g} Pa the friction-free rest position {free} "
        f"is one), or the last state of a `simulate` to rest, or use {_smooth_twin(friction)} for a unique "
        "equilibrium")
