"""Why a legal simulation failed, and the setting that fixes it: the step budget `simulate` gives a run by default
(it grows with the horizon), and the diagnosis behind its `PamjaxSolveError` messages — a horizon longer than the
step budget, or a stiff system (its fastest mode far quicker than an explicit solver's stable step) — naming the
parameter that makes it so where the system says. Workflow only: the physics is asked, never restated."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._systems.base import AbstractMuscleSystem
from .scaled import scaled

BASE_MAX_STEPS = 200_000  # the budget of runs up to ~60 s with a 50 Hz PWM valve (Tsit5 takes ~31 steps per period)
STEPS_PER_PWM_PERIOD = 64  # budget per period of a switching valve: 2× the ~31 Tsit5 takes on paper 000's runs
STEPS_PER_SECOND = 1000  # budget per second of a continuous valve (Rodas5 ~32/s, Tsit5 ~130/s on paper 000's runs)
EXPLICIT_STABILITY = 3.5  # |h λ| an explicit Runge-Kutta method (Tsit5, RK4: 2.8) stays stable up to on λ < 0
_MAX_STEPS_REACHED = "maximum number of solver steps"


def _pwm_period(valve):
    """The PWM period [s] of a switching valve, None for a continuous one."""
    # 1/f on the host: the valve's `period` of a concrete frequency would compile a one-operation program
    return 1.0 / float(valve.pwm_frequency) if valve.switches else None


def default_max_steps(system, t0, t1):
    """The step budget of a run over [t0, t1] [s]: 200,000, or the horizon's share (64 per PWM period of a switching
    valve, 1,000 per second otherwise) rounded up to 200,000 × a power of two, so that few budgets (each a separate
    compilation) occur. 200,000 where the PWM frequency is traced (`jax.grad` of a loss with respect to the whole
    system traces it too, and the budget is static)."""
    if system.valve.switches and isinstance(system.valve.pwm_frequency, jax.core.Tracer):
        return BASE_MAX_STEPS
    period = _pwm_period(system.valve)
    horizon = max(float(t1) - float(t0), 0.0)
    rate = STEPS_PER_PWM_PERIOD / period if period is not None else STEPS_PER_SECOND
    needed = rate * horizon
    if needed <= BASE_MAX_STEPS:
        return BASE_MAX_STEPS
    return BASE_MAX_STEPS * 2 ** math.ceil(math.log2(needed / BASE_MAX_STEPS))


@eqx.filter_jit
def _start_jacobian(system, signal, t0, y0):
    """(Jacobian of the scaled vector field at the start state, the start state: `y0`, or the system's own when None),
    compiled as one program: run eagerly, the initial state and the Jacobian compile ~90 one-operation programs
    (~7 s on a slow CPU) on every failed solve."""
    y0 = system.initial_state() if y0 is None else y0
    z0, scaled_state = scaled(system, y0)
    command = signal(system.valve.command_time(t0))
    return jax.jacfwd(lambda z: scaled_state.field(system, t0, z, command))(z0), y0


def _fastest_mode(system, signal, t0, y0):
    """(largest |Re λ| [1/s] of the Jacobian of the scaled vector field at the initial state (`y0`, or the system's
    own when None), name of the state it mostly moves)."""
    jac, y0 = _start_jacobian(system, signal, jnp.asarray(float(t0)), y0)
    jac = np.asarray(jac)
    if not np.all(np.isfinite(jac)):
        return float("nan"), "?"
    values, vectors = np.linalg.eig(jac)
    k = int(np.argmax(np.abs(values.real)))
    names = [jax.tree_util.keystr(path).strip(".") for path, _ in jax.tree_util.tree_flatten_with_path(y0)[0]]
    state = names[int(np.argmax(np.abs(vectors[:, k])))] if len(names) == jac.shape[0] else "?"
    return float(abs(values[k].real)), state


def _stiffness_cause(system):
    """A phrase naming the parameters behind a stiff payload, for systems that carry them."""
    if not isinstance(system, AbstractMuscleSystem):
        return ""
    mass, force, width = system.payload_mass, system.friction.coulomb_force, system.friction.smoothing_width()
    if width is None:
        return ""
    rate = float(force) / (float(width) * float(mass))
    return (f"; here the payload's motion: Coulomb friction F_c = {float(force):g} N smoothed over velocity_width = "
            f"{float(width):g} m/s acts on payload_mass = {float(mass):g} kg, a rate F_c/(w·M) = {rate:.3g} 1/s (a "
            "heavier payload or a wider velocity_width makes it milder)")


def failure_hint(system, signal, ts, t0, y0, traj, max_steps, solver, message):
    """A sentence on why the solve behind `traj` failed and what fixes it (see the module docstring)."""
    ts = np.asarray(ts, dtype=float)
    t0, t1 = float(t0), float(ts[-1])
    horizon = t1 - t0
    states = np.stack([np.ravel(np.asarray(x)) for x in jax.tree_util.tree_leaves(traj.state)], axis=-1)
    finite = np.all(np.isfinite(states.reshape(len(ts), -1)), axis=1)
    reached = float(ts[np.flatnonzero(finite)[-1]]) if finite.any() else t0
    steps = int(traj.num_steps)
    rate, state = _fastest_mode(system, signal, t0, y0)
    explicit = type(solver).__name__ not in ("Rodas5", "Kvaerno5", "Kvaerno4", "Kvaerno3", "ImplicitEuler")
    where = f"it reached t = {reached:.4g} s of {t1:.4g} s after {steps:,} steps"
    # Stiff: the explicit solver's stable step is far below the step the run needs anyway (a switching valve's cap,
    # or 1/1000 of the horizon), so stiffness, not the horizon, uses up the steps.
    usual_step = system.valve.max_step() or horizon / 1000.0
    if explicit and np.isfinite(rate) and EXPLICIT_STABILITY / rate < 0.1 * usual_step:
        needed = rate * horizon / EXPLICIT_STABILITY
        return (f"{where}. The system is stiff: its fastest mode (mostly the {state}) decays in {1 / rate:.2g} s, so "
                f"the explicit solver {type(solver).__name__} needs steps below ~{EXPLICIT_STABILITY / rate:.2g} s, "
                f"about {needed:,.0f} for this {horizon:g} s run{_stiffness_cause(system)}. Pass "
                "solver=pamjax.Rodas5() (implicit, L-stable: its steps are not limited by stiffness)")
    if _MAX_STEPS_REACHED in message and reached > t0:
        needed = steps * horizon / (reached - t0)
        period = _pwm_period(system.valve)
        per_period = f" ({steps * period / (reached - t0):.0f} per PWM period)" if period is not None else ""
        fix = (" or stepping='pwm' (fixed RK4 steps on the PWM grid, ~18 per period, for any horizon)"
               if period is not None else "")
        # 2×: the rate of steps varies along a run; a plain integer, as Python and a TOML config both read it
        budget = int(2 ** math.ceil(math.log2(2 * needed)))
        return (f"{where}{per_period}: the whole run needs about {needed:,.0f}; pass max_steps={budget}{fix}")
    inflow = negative_inflow(system, signal, t0, y0)
    if inflow is not None:
        return f"{where}: {inflow}"
    if "minimum step size" in message:
        return (f"{where}, where the step size fell below the solver's minimum: the state or its rate became "
                "non-finite or discontinuous there (parameters far outside the physical range?); simulate with "
                "throw=False and look at the trajectory up to that time")
    return (f"{where}. Common causes: parameters far outside the physical range, or too tight tolerances; pass "
            "throw=False to get the partial result with status instead")


RK4_STABILITY = 2.8  # |h λ| classical RK4 stays stable up to on λ < 0
MOVING_SPEED = 0.5  # m/s: a fast PAM stroke (the MAS-10-300's 75 mm in 0.15 s), where a friction state's rate is read


@eqx.filter_jit
def _start_inflow(system, signal, t0, y0, command):
    """The mass flow into the chamber [kg/s] at the start state with the valve held at `command`."""
    y0 = system.initial_state() if y0 is None else y0
    return system.outputs(t0, y0, command).get("mass_flow")


def negative_inflow(system, signal, t0, y0):
    """A sentence naming negative inflow, or None: the valve at the signal's largest command takes air OUT of a
    chamber that starts at or below atmospheric pressure, so the pressure falls to zero and the state turns
    non-finite whatever the solver or its step (e.g. a flow coefficient with its sign flipped in a model file)."""
    try:
        lo, hi = signal.bounds()
        y = system.initial_state() if y0 is None else y0
        pressure = getattr(y, "pressure", None)
        if pressure is None or float(np.max(np.asarray(pressure))) > float(system.air.atmospheric_pressure) + 1.0:
            return None  # a chamber above atmospheric empties legitimately
        flow = _start_inflow(system, signal, jnp.asarray(float(t0)), y0, jnp.asarray(float(hi)))
        flow = None if flow is None else float(np.min(np.asarray(flow)))
    except Exception:  # noqa: BLE001 - a diagnosis must not raise in place of the failure it explains
        return None
    if flow is None or not flow < -1e-12:
        return None
    return (f"the valve takes air OUT of the chamber at the start (mass flow {flow:.3g} kg/s at {float(pressure):g} Pa "
            f"abs with the command at {hi:g}, where a valve fills it): negative inflow drives the pressure below zero "
            "whatever the solver or its step. Check the signs of the valve's flow parameters (e.g. "
            "valve.coefficients of an AveragedValve: a coefficient with its sign flipped)")


def fixed_step_hint(system, signal, t0, y0, stepping, step=None):
    """What fixes an unstable fixed-grid run ("pwm": substeps per PWM period; "grid": grid_step): the step its
    fastest mode needs, or an implicit adaptive solve when that step is impractically small. When the run's step
    `step` [s] is already below what its fastest mode needs, a smaller step cannot help: the cause is named
    (negative inflow) or the parameters are blamed, never a step the run already takes."""
    inflow = negative_inflow(system, signal, t0, y0)
    if inflow is not None:
        return inflow
    rate, state = _fastest_mode(system, signal, float(t0), y0)
    if system.hybrid:  # a run that starts stuck also slides: the sliding mode's rates (c/M: the viscous friction)
        y = system.initial_state() if y0 is None else y0
        if getattr(y, "friction", None) is not None:
            sliding = eqx.tree_at(lambda s: s.friction, y, jnp.ones_like(jnp.asarray(y.friction)))
            rate_sliding, state_sliding = _fastest_mode(system, signal, float(t0), sliding)
            if np.isfinite(rate_sliding) and rate_sliding > rate:
                rate, state = rate_sliding, f"{state_sliding}, once the payload slides"
    y = system.initial_state() if y0 is None else y0
    if not system.hybrid and getattr(y, "friction", None) is not None and getattr(y, "velocity", None) is not None:
        # a friction state (bristle, Bouc-Wen) relaxes at a rate that grows with the speed (bristles: σ0|v|/F_c),
        # which a start at rest does not show: the modes at MOVING_SPEED too
        moving = eqx.tree_at(lambda s: s.velocity, y, jnp.full_like(jnp.asarray(y.velocity), MOVING_SPEED))
        rate_moving, state_moving = _fastest_mode(system, signal, float(t0), moving)
        if np.isfinite(rate_moving) and rate_moving > rate:
            rate, state = rate_moving, f"{state_moving}, once the payload moves at {MOVING_SPEED:g} m/s"
    if not np.isfinite(rate):
        return ("the state's rate is not finite at the start already: a step size cannot help; check the model's "
                "parameters and the initial state (values far outside their physical range)")
    if rate == 0:
        return ("the state does not move at the start, so its stability limit cannot be named; check the model's "
                "parameters (values far outside their physical range, a sign flipped)")
    stable = RK4_STABILITY / rate
    if step is not None and step <= stable:
        return (f"not a step-size problem: the step ({step:.2g} s) is already below the {stable:.2g} s its fastest "
                f"mode (mostly the {state}) needs, so the state left the physical range for another reason: check "
                "the model's parameters (values far outside their physical range, a sign flipped)")
    # a hybrid system (stick-slip friction) has no adaptive solve: only a finer fixed grid helps it
    implicit = None if system.hybrid else ("use stepping='adaptive' with solver=pamjax.Rodas5() (implicit: not "
                                           "limited by stiffness)")
    period = _pwm_period(system.valve)
    if stepping == "pwm" and period is not None:
        needed = math.ceil(period / stable)
        finer = f"pass substeps={max(needed, 2):,} or more"
        advice = (f"substeps >= {needed:,} would be stable, too many: {implicit}" if needed > 256 and implicit
                  else finer + (f", or {implicit}" if implicit else ""))
    else:
        shown = float(f"{stable:.2g}")
        shown = shown if shown <= stable else float(f"{stable * 0.95:.2g}")  # never a step above the limit
        advice = f"pass grid_step={shown:g} or less" + (f", or {implicit}" if implicit else "")
    cause = _stiffness_cause(system)
    return (f"the fixed RK4 step is beyond the stability limit of this system: its fastest mode (mostly the {state}) "
            f"needs RK4 steps below {stable:.2g} s{cause}; {advice}")
