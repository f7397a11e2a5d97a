"""Linearisation of any pamjax system about an operating point, by autodiff: state space, transfer functions, Bode.

ẋ = f(t, x, u),  y = h(t, x, u)  →  δẋ = A δx + B δu,  δy = C δx + D δu,  with A = ∂f/∂x, B = ∂f/∂u, C = ∂h/∂x,
D = ∂h/∂u (`jax.jacfwd` through the system's `vector_field` and `outputs`). The inputs are the command plus, on
request, any array leaves of the system (e.g. `RegulatorSystem.outlet_flow`, eq. 5's Q_in). States are flattened in
pytree order (names in `state_names`), in SI units.
"""

import warnings
from collections.abc import Callable, Mapping, Sequence

import equinox as eqx
import jax
import jax.flatten_util as jfu
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._core.custom_types import ArrayLike, Float, Real, RealScalarLike
from .._core.errors import PamjaxInputError, PamjaxSolveError, check_count, check_finite, concrete_values
from .._core.fastjit import keyed_by_code
from .._systems.base import AbstractSystem
from .checks import check_parameters, check_positive_number, check_start_state
from .equilibrium_checks import check_guess_at_rest, check_mode_holds, check_not_stuck, check_reachable


class StateSpace(eqx.Module):
    """A linear(ised) model: `A` (n×n), `B` (n×m), `C` (p×n), `D` (p×m) as NumPy arrays, with names."""

    A: Float[np.ndarray, "n n"]
    B: Float[np.ndarray, "n m"]
    C: Float[np.ndarray, "p n"]
    D: Float[np.ndarray, "p m"]
    state_names: tuple[str, ...] = eqx.field(static=True)
    input_names: tuple[str, ...] = eqx.field(static=True)
    output_names: tuple[str, ...] = eqx.field(static=True)

    def __check_init__(self):  # a hand-built B of the wrong rows failed in NumPy's solve with a raw gufunc error
        n, m, p = len(self.state_names), len(self.input_names), len(self.output_names)
        shapes = {"A": (self.A, (n, n)), "B": (self.B, (n, m)), "C": (self.C, (p, n)), "D": (self.D, (p, m))}
        if bad := [f"{k} has shape {np.shape(x)}, expected {w}" for k, (x, w) in shapes.items() if np.shape(x) != w]:
            raise PamjaxInputError(f"StateSpace: {'; '.join(bad)} (A n×n, B n×m, C p×n, D p×m for its {n} state_names, "
                                   f"{m} input_names and {p} output_names)")

    def _index(self, names, name, kind):
        if isinstance(name, (int, np.integer)) and not isinstance(name, (bool, np.bool_)):
            if not 0 <= name < len(names):
                raise PamjaxInputError(f"{kind} index {name} is out of range: this model has {len(names)} {kind}s "
                                       f"(indices 0 to {len(names) - 1}): {list(names)}")
            return int(name)
        if name not in names:
            raise PamjaxInputError(f"unknown {kind} {name!r}; this model has {list(names)}")
        return names.index(name)

    def frequency_response(self, frequency, output=0, input=0):
        """G(j 2π f) = C (j2πf I − A)⁻¹ B + D for `frequency` [Hz] (a number or 1-D array, finite, ≥ 0), one
        output/input pair (names or indices); at f = 0 with a pole at 0 (a memory state), the limit G(0⁺) (`dc_gain`).
        **Raises:** `PamjaxInputError` for an unknown output or input, a frequency of another shape, negative or not
        finite, and where G is infinite: a pole at j2πf that this channel keeps (at f = 0: an integrator)."""
        i = self._index(self.output_names, output, "output")
        j = self._index(self.input_names, input, "input")
        f = np.atleast_1d(np.asarray(frequency, dtype=float))
        if f.ndim != 1:
            raise PamjaxInputError(f"frequency must be one number or a 1-D array [Hz], got shape {f.shape}")
        if not np.all(np.isfinite(f) & (f >= 0)):
            raise PamjaxInputError(f"frequency must be finite and >= 0 [Hz] (G at -f is the complex conjugate of G at "
                                   f"f), got {np.array2string(f, threshold=6)}")
        n, out, static = self.A.shape[0], np.empty(f.shape, dtype=complex), None
        for k, fk in enumerate(f):
            if fk == 0:
                out[k] = static = _static_gain(self, i, j) if static is None else static
                continue
            try:
                x = np.linalg.solve(2j * np.pi * fk * np.eye(n) - self.A, self.B[:, j])
            except np.linalg.LinAlgError:
                raise PamjaxInputError(
                    f"G(j2πf) is infinite at f = {fk} Hz: a pole of A lies on the imaginary axis there (an undamped "
                    f"mode; poles {np.array2string(self.poles(), precision=4, threshold=8)} 1/s); evaluate it at "
                    "other frequencies") from None
            out[k] = self.C[i] @ x + self.D[i, j]
        return out

    def dc_gain(self, output=0, input=0):
        """Static gain G(0) = D − C A⁻¹ B; with poles at 0 (a memory state: bristle or Bouc-Wen friction, a hysteresis,
        whose rate vanishes at rest whatever its value) the limit G(0⁺), finite where this channel cancels the pole
        (a hysteresis at rest: the mean of its rising and falling branches' gains, `linearise`). **Raises:**
        `PamjaxInputError` where the pole at 0 stays in this channel (an integrator), naming the states."""
        return float(np.real(self.frequency_response(0.0, output, input)[0]))

    def bode(self, frequency, output=0, input=0):
        """(magnitude [dB], phase [deg]) at `frequency` [Hz]."""
        g = self.frequency_response(frequency, output, input)
        return 20 * np.log10(np.abs(g)), np.degrees(np.unwrap(np.angle(g)))

    def bandwidth(self, output=0, input=0, drop_db=3.0, fmax=1e4):
        """Lowest frequency [Hz] where |G| falls `drop_db` (> 0: 3 for the −3 dB bandwidth) below |G(0)|, by bisection
        on a grid from 1e-4 Hz (lowered by decades to 1e-12 Hz while |G| is already below there: for τ = 4000 s the
        grid's first point came back) to `fmax` [Hz]. `PamjaxInputError` for a bad `drop_db` or `fmax`, an infinite
        G(0) (`dc_gain`), or |G| below already at 1e-12 Hz."""
        check_positive_number(drop_db, "drop_db")
        if check_positive_number(fmax, "fmax") <= 1e-4:
            raise PamjaxInputError(f"fmax must exceed 1e-4 Hz (the search grid's lowest frequency), got {fmax!r}")
        ref = 20 * np.log10(abs(self.dc_gain(output, input)))

        def below(f):
            return 20 * np.log10(abs(self.frequency_response(f, output, input)[0])) < ref - drop_db

        if (low := next((f for f in 10.0 ** -np.arange(4, 13) if not below(f)), None)) is None:
            raise PamjaxInputError(f"|G| is already {drop_db} dB below its static gain at 1e-12 Hz, the bandwidth "
                                   "search's floor: read frequency_response at the frequencies you need")
        grid = np.logspace(np.log10(low), np.log10(fmax), int(50 * np.log10(fmax / low)) + 1)  # 50 a decade, as before
        hit = [f for f in grid if below(f)]
        if not hit:
            raise PamjaxInputError(f"|G| stays within {drop_db} dB of its static gain up to {fmax} Hz")
        lo, hi = grid[max(np.searchsorted(grid, hit[0]) - 1, 0)], hit[0]
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if below(mid) else (mid, hi)
        return 0.5 * (lo + hi)

    def poles(self):
        """Eigenvalues of A [1/s]."""
        return np.linalg.eigvals(self.A)

    def transfer_function(self, output=0, input=0):
        """(numerator, denominator) polynomial coefficients in s, highest power first, of one channel:
        den = det(sI − A), num = det(sI − A + B_j C_i) − det(sI − A) + D_ij det(sI − A)."""
        i = self._index(self.output_names, output, "output")
        j = self._index(self.input_names, input, "input")
        den = np.poly(self.A)
        num = np.real(np.poly(self.A - np.outer(self.B[:, j], self.C[i])) - den + self.D[i, j] * den)
        num[np.abs(num) <= 1e-9 * np.max(np.abs(num), initial=0.0)] = 0.0  # cancellation round-off
        num = np.trim_zeros(num, "f")
        return (num if num.size else np.zeros(1)), np.real(den)

    def to_control(self):
        """A `control.StateSpace` (python-control, optional dependency `pamjax[control]`)."""
        try:
            import control
        except ImportError as e:  # pragma: no cover
            raise ImportError("python-control is needed: pip install 'pamjax[control]'") from e
        return control.ss(self.A, self.B, self.C, self.D)


# A pole with |λ| at or below this fraction of the largest |λ| is a pole at 0 (eigenvalues do not depend on the
# states' units). Measured: a memory state's pole is 1e-19 of the largest at `equilibrium`'s state and 1e-12 at the
# end of a 10 s `simulate` (Bouc-Wen MAS-10); the smallest physical pole met, 2e-4 (MAS-10, Coulomb friction).
ZERO_POLE_RTOL = 1e-9


def _balanced(A, B, C):
    """(T⁻¹AT, T⁻¹B, CT), T diagonal, each state's row and column of A of equal norms (Parlett and Reinsch): the same
    poles and transfer functions without the SI units' 1e10 spread (Pa against m), for the SVD's null directions."""
    A, B, C = (np.array(m, dtype=float) for m in (A, B, C))
    for _ in range(20):
        for k in range(A.shape[0]):
            column, row = (np.linalg.norm(np.delete(v, k)) for v in (A[:, k], A[k, :]))
            if column > 0 and row > 0:
                d = np.sqrt(row / column)
                A[:, k] *= d
                A[k, :] /= d
                B[k, :] /= d
                C[:, k] *= d
    return A, B, C


def _static_gain(ss, i, j):
    """G_ij(0⁺) = lim G_ij(s), s → 0. Without a pole at 0, D − C A⁻¹ B. With k poles at 0 (right and left null
    bases N, W of A, balanced): G(s) = C P₀ B / s + D − C A^# B + O(s), P₀ = N (WᵀN)⁻¹ Wᵀ the projector on the null
    space along A's range and A^# the group inverse, x = −A^# B solving [A N; Wᵀ 0] [x; λ] = [−B; 0]. The limit is
    finite where the residue C P₀ B vanishes (to rounding)."""
    poles = np.abs(np.linalg.eigvals(ss.A))
    zero = int(np.sum(poles <= ZERO_POLE_RTOL * np.max(poles, initial=0.0)))
    if zero == 0:
        return ss.C[i] @ np.linalg.solve(-ss.A, ss.B[:, j]) + ss.D[i, j]
    A, B, C = _balanced(ss.A, ss.B, ss.C)
    u, _, vt = np.linalg.svd(A)
    N, W = vt[-zero:].T, u[:, -zero:]
    try:
        projector = N @ np.linalg.solve(W.T @ N, W.T)
        bordered = np.block([[A, N], [W.T, np.zeros((zero, zero))]])
        x = np.linalg.solve(bordered, np.concatenate([-B[:, j], np.zeros(zero)]))[: A.shape[0]]
    except np.linalg.LinAlgError:  # WᵀN singular: a Jordan block at 0 (a double integrator)
        projector, x = None, None
    if projector is not None:
        residue = C[i] @ projector @ B[:, j]
        # against |C| |P₀| |B| (N and W orthonormal: |P₀| = |(WᵀN)⁻¹|): a cancelled pole leaves rounding only
        if abs(residue) <= 1e-8 * np.linalg.norm(C[i]) * np.linalg.norm(B[:, j]) * np.linalg.norm(
                np.linalg.inv(W.T @ N), 2):
            return C[i] @ x + ss.D[i, j]
    left = np.abs(W[:, -1])
    rows = [ss.state_names[k] for k in np.argsort(-left) if left[k] > 0.1 * np.max(left)]
    raise PamjaxInputError(
        f"the static gain G(0) of {ss.output_names[i]} / {ss.input_names[j]} (and a bandwidth measured from it) is "
        f"infinite: A has a pole at s = 0 (in the rates of {', '.join(rows)}) that this channel keeps, an integrator "
        "(a state whose rate vanishes at rest whatever its value, driven by this input and seen in this output): a "
        "constant input change makes the output ramp. Read |G| at f > 0 (frequency_response, bode; e.g. 1e-2 Hz), "
        "look at poles() and transfer_function(), or linearise a model without the integrating state")


def _names(tree, prefix):
    out = []
    for path, leaf in jtu.tree_flatten_with_path(tree)[0]:
        name = prefix + "".join(jtu.keystr((k,)) for k in path)
        size = int(np.prod(getattr(leaf, "shape", np.shape(leaf))))
        out.extend([name] if size == 1 else [f"{name}[{i}]" for i in range(size)])
    return tuple(out)


def linearise(system: AbstractSystem, state: eqx.Module, command: RealScalarLike | Real[ArrayLike, " m"], *,
              t: RealScalarLike = 0.0,
              inputs: Mapping[str, Callable[[AbstractSystem], Real[ArrayLike, "..."]]] | None = None,
              outputs: Sequence[str] = ("pressure",)) -> StateSpace:
    """Linearise `system` (any pamjax system with a continuous valve) about (`state`, `command`) at time `t`: a
    `StateSpace`. `state`: its state pytree (SI, ABSOLUTE pressures, as `simulate`'s `y0`); `command`: one number (a
    duty ratio, a voltage), or a vector for a system that takes one (an `AntagonisticJoint`'s (V_f, V_e): columns
    "command[0]", "command[1]"); `inputs`: extra inputs after the command in B and D, a dict name → function
    selecting an array leaf of the system (`{"outlet_flow": lambda s: s.outlet_flow}`); `outputs`: `system.outputs`
    channels. Transfer functions and Bode data are meaningful about an equilibrium (`equilibrium`). A state holding
    a `PressureHysteresis` branch warns (`UserWarning`): at rest the model averages its rising and falling branches.

    **Raises:** `PamjaxInputError`, before anything is computed, for what `simulate` refuses in the system and in a
    start state (a pressure in bar or gauge, a position in mm or outside the stroke), a switching (PWM) valve, a
    `state`, `command` or `t` not finite, a command of a shape the system does not take or outside its
    `command_range`, `inputs` that are no such dict, a stuck state of a stick-slip friction (`KarnoppFriction`: at
    rest nothing moves until the net force reaches F_c, poles at 0; its smooth twin `CoulombViscousFriction` named);
    `PamjaxSolveError` where a derivative is not finite (named)."""
    _check_inputs(system, command, state, "state", t)
    check_not_stuck(system, state)  # stick-slip at rest: poles at 0, no small-signal model
    if not isinstance(inputs, Mapping | None):  # a list of functions: a raw TypeError in dict() before
        raise PamjaxInputError(f"inputs must be a dict name → function selecting an array leaf of the system, e.g. "
                               f"{{'outlet_flow': lambda s: s.outlet_flow}}, got {type(inputs).__name__}")
    inputs, extra = dict(inputs or {}), []
    for name, where in inputs.items():  # an array leaf of the system itself (a sub-module: a raw TypeError before)
        try:
            extra.append(jnp.asarray(where(system), dtype=float))
            eqx.tree_at(where, system, extra[-1])  # not a number the function made up
        except (AttributeError, TypeError, ValueError, IndexError, KeyError) as e:
            raise PamjaxInputError(f"inputs[{name!r}] must select an array leaf of the system (e.g. lambda s: "
                                   f"s.outlet_flow): {type(e).__name__}: {e}") from None
    command = jnp.asarray(command, dtype=float)
    state = jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype=float), state)  # traced, whatever its leaves' types
    available = jax.eval_shape(lambda: system.outputs(t, state, command))  # names and shapes only
    for name in outputs:
        if name not in available or available[name] is None:
            raise PamjaxInputError(f"unknown output {name!r}; this system has {sorted(available)}")
    input_names = _names(command, "command") + tuple(n for name, leaf in zip(inputs, extra)
                                                         for n in _names(leaf, name))
    if len(set(input_names)) < len(input_names):  # an input named "command" was read as the command's column
        raise PamjaxInputError(f"inputs: names must differ from the command's ('command') and from each other, got "
                               f"input names {list(input_names)}; name each after its leaf, e.g. 'outlet_flow'")
    state_names = _names(state, "state")
    if any(n.rsplit(".", 1)[-1] == "hysteresis" for n in state_names):  # `ISO6358RegulatorState.hysteresis`'s branch
        warnings.warn("linearise: the state holds a PressureHysteresis branch: at rest its law's smoothed |dp_set/dt| "
                      "has zero slope, so the small-signal model averages the rising and falling branches (VPPM at 3 "
                      "V: dc_gain 0.51 bar/V; a small rise moves the outlet 1.01 bar/V, a fall under 50 mbar not at "
                      "all; docs/regulator.md); for one branch's gain, step the command in `simulate`", stacklevel=2)
    # one program per system structure, inputs and outputs (module level: a later call with other values, or another
    # operating point, reuses it; closures made here at every call compiled anew each time, ~0.25 s a call)
    wheres = tuple(map(keyed_by_code, inputs.values()))
    jacobians = _jacobians(system, jnp.asarray(t, dtype=float), state, (command, *extra), wheres, tuple(outputs))
    A, B, C, D = (np.asarray(m) for m in jacobians)
    output_names = tuple(n for name in outputs for n in _names(available[name], name))
    _refuse_non_finite((A, B, C, D), state_names, input_names, output_names)
    return StateSpace(A=A, B=B, C=C, D=D, state_names=state_names, input_names=input_names, output_names=output_names)


def _refuse_non_finite(matrices, state_names, input_names, output_names):
    """A `PamjaxSolveError` naming the rows and columns of (A, B, C, D) that are not finite: a NaN derivative at the
    operating point (a state outside the model's domain, a parameter that divides by zero) is not a linear model."""
    rows = {"A": state_names, "B": state_names, "C": output_names, "D": output_names}
    columns = {"A": state_names, "B": input_names, "C": state_names, "D": input_names}
    bad = []
    for name, m in zip("ABCD", matrices):
        if not np.all(np.isfinite(m)):
            r, c = (sorted(set(np.nonzero(~np.isfinite(m))[k].tolist())) for k in (0, 1))
            bad.append(f"{name}: ∂({', '.join(rows[name][i] for i in r)})/∂({', '.join(columns[name][j] for j in c)})")
    if bad:
        raise PamjaxSolveError(
            f"linearise: the derivatives are not finite (NaN or inf) at this operating point: {'; '.join(bad)}. The "
            "vector field or outputs are not differentiable there (a state outside the model's domain, e.g. a "
            "pressure or position beyond what the model takes, or a parameter that divides by zero)")


@eqx.filter_jit
def _jacobians(system, t, state, u0, wheres, outputs):
    """(A, B, C, D) of `linearise`: forward-mode Jacobians of the vector field and of the named outputs with respect
    to the flat state and the flat inputs (the command, then each `wheres` leaf of the system)."""
    x_flat, unravel_x = jfu.ravel_pytree(state)
    u_flat, unravel_u = jfu.ravel_pytree(u0)

    def with_inputs(u):
        cmd, *leaves = unravel_u(u)
        s = system
        for where, leaf in zip(wheres, leaves):
            s = eqx.tree_at(where, s, leaf)
        return s, cmd

    def f(x, u):
        s, cmd = with_inputs(u)
        return jfu.ravel_pytree(s.vector_field(t, unravel_x(x), cmd))[0]

    def h(x, u):
        s, cmd = with_inputs(u)
        out = s.outputs(t, unravel_x(x), cmd)
        return jnp.concatenate([jnp.ravel(out[name]) for name in outputs])

    return (*jax.jacfwd(f, argnums=(0, 1))(x_flat, u_flat), *jax.jacfwd(h, argnums=(0, 1))(x_flat, u_flat))


def _check_inputs(system, command, state, state_name, t):
    """`simulate`'s checks of what `linearise` and `equilibrium` are given, before anything is computed: the
    components' own (`check_parameters`), the state as a `y0`, a finite time, the command, a continuous valve."""
    if not isinstance(system, AbstractSystem):
        raise PamjaxInputError(f"system must be a pamjax system (TankSystem, MuscleSystem, ...), got {type(system)}")
    check_parameters(system)
    check_start_state(system, state, state_name)  # simulate's checks (5.4 for 5.4 bar: poles of a vacuum)
    check_finite(t, "t")
    _check_command(system, command, state, t)
    for name, element in system.actuators.items():
        if element.switches:  # its flow at `t` is one PWM phase's (101325 Pa at t = 0, -1.09e9 Pa at 5 ms: MAS-10)
            raise PamjaxInputError(f"system.{name} ({type(element).__name__}) switches on PWM edges: linearised or "
                                   "solved for rest at one time t, it is frozen at that phase of its period. Use the "
                                   'cycle-averaged valve (eq. 13): presets.mas10_system("averaged"), or an '
                                   "AveragedValve (pj.fit_averaged_valve fits one to a switching valve)")


def _check_command(system, command, state, t):
    """Refuse a `command` of a shape `system` does not take (a vector where its rates keep the state's shapes, as the
    `AntagonisticJoint`'s (V_f, V_e), else broadcast into an A of shape (4, 3)), and a concrete one not finite or
    outside `system.command_range`, as `simulate` does (eq. 13's parabola gave a 2 MPa equilibrium at duty -0.3)."""
    if np.ndim(command) > 1 or (np.ndim(command) == 1 and not _takes_vector(system, command, state, t)):
        raise PamjaxInputError(
            f"command must be one number (the valve command, e.g. a duty ratio), or a vector for a system that takes "
            f"one (an AntagonisticJoint's (V_f, V_e)), got shape {np.shape(command)}: for several operating points, "
            "call once per command (or jax.vmap over it)")
    value = concrete_values(command)
    if value is None:
        return
    if not np.all(np.isfinite(value)):
        raise PamjaxInputError(f"command must be finite (no NaN or inf), got {np.array2string(value, threshold=6)}")
    bounds = [concrete_values(b) for b in system.command_range]
    if any(b is None for b in bounds):
        return
    lo, hi = float(np.max(bounds[0])), float(np.min(bounds[1]))
    if np.any(value < lo - 1e-12) or np.any(value > hi + 1e-12):
        raise PamjaxInputError(f"command (the valve command, e.g. a duty ratio) must lie within the system's "
                               f"command_range [{lo}, {hi}], got {np.array2string(value, threshold=6)}")


def _takes_vector(system, command, state, t):
    """Whether `system`'s rates at `state` for the vector `command` have the state's shapes (shapes only: nothing
    computed or compiled); a `PamjaxInputError` the system raises for it (the joint's "(flexor, extensor)") passes."""
    try:
        shape = jax.ShapeDtypeStruct(np.shape(command), float)  # a shape only: no array made, nothing compiled
        rates = jax.eval_shape(lambda c: system.vector_field(t, state, c), shape)
    except PamjaxInputError:
        raise
    except (TypeError, ValueError, IndexError):  # the command could not be broadcast into the state
        return False
    shapes = [np.shape(leaf) for leaf in jtu.tree_leaves(state)]
    return (jtu.tree_structure(rates) == jtu.tree_structure(state)
            and shapes == [leaf.shape for leaf in jtu.tree_leaves(rates)])


# Singular values of the scaled Jacobian below this fraction of the largest are zero in the Newton step: measured,
# physical ones down to ~1e-4 of the largest (MAS-10 with Coulomb friction), a memory state's null direction ~1e-18.
SINGULAR_RCOND = 1e-10


def equilibrium(system: AbstractSystem, command: RealScalarLike | Real[ArrayLike, " m"], guess: eqx.Module, *,
                t: RealScalarLike = 0.0,
                rtol: RealScalarLike = 1e-10, atol: RealScalarLike = 1e-10, max_steps: int = 200) -> eqx.Module:
    """A state where `system.vector_field(t, ·, command)` vanishes, by Newton's method from `guess` in the system's
    scaled units (`state_scale`), until a step is below `atol + rtol |z|` in every scaled component. Each step is the
    least-squares (minimum-norm) one: with a memory state (Bouc–Wen or bristle friction, a `PressureHysteresis`),
    whose rate vanishes at rest whatever its value, the equilibria form a continuum and the steps converge to the
    one nearest the guess; a long `simulate` (or `steady_state_map`) gives the one reached from a given start. One
    small compiled loop (optimistix's `Newton` compiled one several times the size: ~12 s against ~2 s, DMSP-40).
    **Raises:** `PamjaxInputError` before anything is computed for what `linearise` refuses in any state, a guess
    of stick-slip friction (`KarnoppFriction`) not at rest in its stuck mode, and `rtol`, `atol` not finite numbers
    > 0 or a `max_steps` not an int >= 1; `PamjaxSolveError` if it does not converge within `max_steps`, or
    converges to a state the system cannot reach (a spurious root: `check_reachable`) or, with stick-slip friction,
    to a stuck payload under a net force beyond F_c (Newton's method cannot move a stuck one: `check_mode_holds`)."""
    _check_inputs(system, command, guess, "guess", t)
    check_guess_at_rest(system, guess)  # stick-slip: an equilibrium is stuck at rest
    check_positive_number(rtol, "rtol")
    check_positive_number(atol, "atol")
    check_count(max_steps, "max_steps", "an int >= 1 (Newton steps)")
    scale = jtu.tree_map(jnp.asarray, system.state_scale())
    scaled_guess = jtu.tree_map(lambda a, s: jnp.asarray(a, dtype=float) / s, guess, scale)
    y, converged, singular = _newton(system, jnp.asarray(command, dtype=float), jnp.asarray(t, dtype=float),
                                     scaled_guess, scale, float(rtol), float(atol), int(max_steps))
    if not bool(converged):
        raise PamjaxSolveError(_no_convergence(y, np.asarray(singular), max_steps))
    check_reachable(system, y, t)
    check_mode_holds(system, y, t, command)  # a stuck payload's zero rates made any position an "equilibrium"
    return y


def _no_convergence(y, singular, max_steps):
    """The message of a failed `equilibrium`: the last state's values, and why (a singular Jacobian named)."""
    names = _names(y, "")
    values = np.concatenate([np.ravel(np.asarray(leaf, dtype=float)) for leaf in jtu.tree_leaves(y)])
    state = ", ".join(f"{n.lstrip('.')}={v:.9g}" for n, v in zip(names, values))
    message = f"equilibrium: Newton's method did not converge within max_steps={max_steps} (last state: {state}); "
    if not np.all(np.isfinite(values)):
        return (f"equilibrium: Newton's method left the model's domain: its state turned non-finite ({state}), where "
                "the vector field or its Jacobian is NaN or inf; try a guess closer to the operating point, or "
                "simulate to steady state (`pamjax.simulate`, `pamjax.steady_state_map`)")
    along = [names[k].lstrip(".") for k in np.argsort(-np.abs(singular)) if abs(singular[k]) > 0.1]
    return message + (f"the Jacobian of the vector field is singular there, along {', '.join(along)}: the equilibria "
                      "form a continuum (e.g. a friction or hysteresis memory state, whose rate vanishes at rest "
                      "whatever its value), and which one the system reaches depends on its path: simulate to steady "
                      "state instead (`pamjax.simulate` with a long horizon, or `pamjax.steady_state_map`)"
                      if np.all(np.isfinite(singular)) and np.any(singular != 0) else "try a guess closer to the "
                      "operating point or a larger max_steps, or simulate to steady state (`pamjax.simulate`, "
                      "`pamjax.steady_state_map`)")


def _with_value(fun):
    return lambda w: ((out := fun(w)), out)  # (value, value): jacfwd's has_aux gives the Jacobian and f in one trace


@eqx.filter_jit
def _newton(system, command, t, scaled_guess, scale, rtol, atol, max_steps):
    z0, unravel = jfu.ravel_pytree(jax.lax.stop_gradient(scaled_guess))

    def residual_of(system, command, t, scale, z):
        y = jtu.tree_map(lambda a, s: a * s, unravel(z), scale)
        return jfu.ravel_pytree(jtu.tree_map(lambda d, s: d / s, system.vector_field(t, y, command), scale))[0]

    # The loop sees the inputs without their derivatives (JAX cannot reverse-differentiate a while loop); the
    # derivative is the implicit function's, added after it (below).
    fixed = jtu.tree_map(lambda x: jax.lax.stop_gradient(x) if eqx.is_array(x) else x, (system, command, t, scale))

    def residual(z):
        return residual_of(*fixed, z)

    def cond(carry):
        z, done, k = carry
        return ~done & (k < max_steps) & jnp.all(jnp.isfinite(z))

    def body(carry):
        z, _, k = carry
        jac, f = jax.jacfwd(_with_value(residual), has_aux=True)(z)
        dz = -jnp.linalg.lstsq(jac, f, rcond=SINGULAR_RCOND)[0]  # minimum norm where the Jacobian is singular
        z = z + dz
        return z, jnp.all(jnp.abs(dz) <= atol + rtol * jnp.abs(z)), k + 1

    z, done, _ = jax.lax.while_loop(cond, body, (z0, jnp.asarray(False), jnp.asarray(0)))
    converged = done & jnp.all(jnp.isfinite(z))

    def null_direction(z_end):  # for a failure's message only: the Jacobian's null direction, zero where regular
        _, sigma, vt = jnp.linalg.svd(jax.jacfwd(residual)(z_end))
        null = vt[-1] / jnp.max(jnp.abs(vt[-1]))
        return jnp.where(sigma[-1] <= SINGULAR_RCOND * sigma[0], null, jnp.zeros_like(null))

    # at the last state (or the guess, where the last state is not finite); not computed for a converged solve
    z_end = jnp.where(jnp.all(jnp.isfinite(z)), z, z0)
    singular = jax.lax.cond(converged, lambda _: jnp.zeros_like(z0), null_direction, z_end)
    # Implicit-function derivative: one more Newton step with the inputs' derivatives, its value taken off again,
    # so that dz = -J⁺ ∂f (f = 0 at the root; minimum norm where J is singular), in forward and reverse mode alike.
    step = -jnp.linalg.pinv(jax.jacfwd(residual)(z), rtol=SINGULAR_RCOND) @ residual_of(system, command, t, scale, z)
    z = z + (step - jax.lax.stop_gradient(step))
    return jtu.tree_map(lambda a, s: a * s, unravel(z), scale), converged, singular
