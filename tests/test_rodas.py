"""Rodas5 (pamjax._solve.rodas): the Rosenbrock solver's order, stiff stability, dense output, and the stiff plant it
exists for, against independent references (SciPy DOP853, finite differences)."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import NumpyPlant, host_signal, initial_state
from scipy.integrate import solve_ivp

import pamjax
from pamjax import presets
from pamjax._solve.fixed_step import RODAS5A_DEFECT_ALLOWANCE
from pamjax._solve.rodas import (
    rodas5_step,
    rodas5_step_defect,
    rodas5_step_unrolled,
    small_inverse,
    small_inverse_lanes,
)
from pamjax._solve.simulate import solve


def _forced_van_der_pol(t, y, args):
    return jnp.stack([y[1], -y[0] + 0.5 * (1.0 - y[0] ** 2) * y[1] + jnp.sin(3.0 * t)])


@pytest.fixture(scope="module")
def van_der_pol_reference():
    rhs = jax.jit(_forced_van_der_pol)  # one program (eagerly, each of its operations compiles its own)
    sol = solve_ivp(lambda t, y: np.asarray(rhs(float(t), y, None)), (0.0, 2.0), [1.0, 0.0],
                    method="DOP853", rtol=1e-13, atol=1e-13, dense_output=True)
    assert sol.success
    return sol


def test_order_five_on_a_nonautonomous_nonlinear_problem(van_der_pol_reference):
    # Fixed steps h = 2/n: a fifth-order method's end-point error falls 32x per halving of h. The time-dependent
    # forcing exercises the d_i h ∂f/∂t terms (a wrong d_i drops the order to 2-3). Asserted: >= 24x per halving.
    # dt0 an array: diffeqsolve (itself jitted) takes a Python float as a compile-time constant, one program per h
    errors = []
    for n in (10, 20, 40, 80):
        sol = dfx.diffeqsolve(dfx.ODETerm(_forced_van_der_pol), pamjax.Rodas5(), 0.0, 2.0, np.asarray(2.0 / n),
                              np.array([1.0, 0.0]), max_steps=1000)
        errors.append(np.max(np.abs(np.asarray(sol.ys)[-1] - van_der_pol_reference.y[:, -1])))
    ratios = np.asarray(errors[:-1]) / np.asarray(errors[1:])
    assert np.all(ratios > 24.0), (errors, ratios)


def test_dense_output_is_a_cubic_hermite_of_fourth_order_accuracy(van_der_pol_reference):
    # Outputs between the steps come from the cubic Hermite through y and f at both ends: local error O(h^4), so the
    # worst error over a fine output grid falls ~16x per halving of h (asserted: > 10x).
    ts = np.linspace(0.0, 2.0, 201)
    worst = []
    for n in (20, 40, 80):  # dt0 an array: one compiled solve for the three step sizes
        sol = dfx.diffeqsolve(dfx.ODETerm(_forced_van_der_pol), pamjax.Rodas5(), 0.0, 2.0, np.asarray(2.0 / n),
                              np.array([1.0, 0.0]), saveat=dfx.SaveAt(ts=jnp.asarray(ts)), max_steps=1000)
        worst.append(np.max(np.abs(np.asarray(sol.ys).T - van_der_pol_reference.sol(ts))))
    assert worst[0] / worst[1] > 10.0 and worst[1] / worst[2] > 10.0, worst


def test_l_stable_far_beyond_the_explicit_stability_limit():
    # y' = -λ (y - cos t), λ = 1e6: an explicit solver needs h < ~3e-6 s; the exact solution follows
    # cos t + sin(t)/λ + O(1/λ²) after the initial layer. Rodas5 under error control crosses 1 s in < 200 steps
    # and lands on it to 1e-9 (stiffly accurate: the layer is damped, not amplified).
    lam = 1e6
    sol = dfx.diffeqsolve(dfx.ODETerm(lambda t, y, args: -lam * (y - jnp.cos(t))), pamjax.Rodas5(), 0.0, 1.0, 0.1,
                          np.array([0.0]), stepsize_controller=dfx.PIDController(rtol=1e-8, atol=1e-8))
    assert int(sol.stats["num_steps"]) < 200
    assert abs(float(np.asarray(sol.ys)[-1, 0]) - (np.cos(1.0) + np.sin(1.0) / lam)) < 1e-9


def _fixed_step_rodas5(step, n, lanes):
    """End point of the forced van der Pol problem over [0, 2] in n fixed RODAS5 steps of `step`, for `lanes`
    starting values of y[0] (one vmapped program: the form `sweep` runs)."""

    def one(y0):
        def body(i, y):
            return step(lambda t, z: _forced_van_der_pol(t, z, None), i * (2.0 / n), y, 2.0 / n)[0]

        return jax.lax.fori_loop(0, n, body, y0)

    return jax.vmap(one)(lanes)


_unrolled_ends = jax.jit(lambda lanes, n: _fixed_step_rodas5(rodas5_step_unrolled, n, lanes), static_argnums=1)
_loop_ends = jax.jit(lambda lanes, n: _fixed_step_rodas5(
    lambda f, t, y, h: rodas5_step(f, t, y, h, inverse=small_inverse_lanes), n, lanes), static_argnums=1)


def test_unrolled_stages_are_the_same_step_as_the_stage_loop(van_der_pol_reference):
    # sweep's form of the step (stages unrolled, 1/h multiplied, the Jacobian one direction at a time) against the
    # stage loop that Rodas5 runs: the same numbers to rounding, over lanes, and fifth order (>= 24x per halving).
    lanes = jnp.stack([jnp.array([1.0, 0.0]), jnp.array([1.0 + 1e-3, 0.0])])
    errors = []
    for n in (10, 20, 40):
        unrolled, loop = np.asarray(_unrolled_ends(lanes, n)), np.asarray(_loop_ends(lanes, n))
        np.testing.assert_allclose(unrolled, loop, rtol=1e-12, atol=1e-13)
        errors.append(np.max(np.abs(unrolled[0] - van_der_pol_reference.y[:, -1])))
    ratios = np.asarray(errors[:-1]) / np.asarray(errors[1:])
    assert np.all(ratios > 24.0), (errors, ratios)


def _braking_into_stick(t, z):
    """A payload braking into stick under a smooth Coulomb sign (x, v; c = 1.7 m/s², width 1 mm/s: ~1,700 /s in the
    band, as paper 000's F_c / (w M)), forced below the friction level."""
    return jnp.stack([z[1], 0.5 * jnp.sin(3.0 * t) - 1.7 * jnp.tanh(z[1] / 1e-3) - 0.3 * z[0]])


_defect_step = jax.jit(lambda z, h: rodas5_step_defect(_braking_into_stick, 0.0, z, h))


def test_the_defect_sees_a_step_into_stiffness_that_the_embedded_estimate_passes():
    # From v = 10 mm/s (sliding: the Jacobian has none of the band's stiffness) a 17 ms step crosses into the band.
    # RODAS5's last three stages, all at the step's end, settle on the same wrong velocity, so its embedded estimate
    # passes at rtol = atol = 1e-5 while the step is > 1,000x that off; the filtered midpoint defect is > 1,000x too.
    # A resolved step (2 ms) has both small. Reference: SciPy's Radau at rtol 1e-13.
    z0 = np.array([0.0, 0.01])
    for h, bad in ((0.017, True), (0.002, False)):
        z1, error, defect = (np.asarray(a) for a in _defect_step(z0, h))
        exact = solve_ivp(lambda t, z: np.asarray(_braking_into_stick(t, z)), (0.0, h), z0, method="Radau",
                          rtol=1e-13, atol=1e-15).y[:, -1]
        scale = 1e-5 * (1.0 + np.maximum(np.abs(z0), np.abs(z1)))
        rms = lambda v: float(np.sqrt(np.mean((v / scale) ** 2)))  # noqa: E731
        if bad:
            assert rms(error) < 1.0 and rms(z1 - exact) > 1e3 and rms(defect) > 1e2 * RODAS5A_DEFECT_ALLOWANCE
        else:
            assert rms(z1 - exact) < 1e-2 and rms(error) < 1e-2 and rms(defect) < 1e-2 * RODAS5A_DEFECT_ALLOWANCE


# `small_inverse` jitted (as the solver runs it): eagerly, its gather-based elimination compiles dozens of one-operation
# programs per size (~2-3 s); jitted, one program per size (0.2-1.1 s). The lanes variant stays eager: its eager
# operations compile faster than the jitted unrolled elimination at n = 5 (~1 s eager against ~3 s jitted, ~4 s for
# its vmap).
_INVERSES = (jax.jit(small_inverse), small_inverse_lanes)


@pytest.mark.parametrize("n", [1, 3, 5])
def test_small_inverse_matches_numpy_including_pivoting(n):
    rng = np.random.default_rng(n)
    a = rng.normal(size=(n, n))
    if n > 1:
        a[0, 0] = 0.0  # forces a row swap
    for inverse in _INVERSES:
        np.testing.assert_allclose(np.asarray(inverse(jnp.asarray(a))), np.linalg.inv(a), rtol=1e-10, atol=1e-12)
    batch = rng.normal(size=(4, n, n))
    np.testing.assert_allclose(np.asarray(jax.vmap(small_inverse_lanes)(jnp.asarray(batch))), np.linalg.inv(batch),
                               rtol=1e-9, atol=1e-11)


def _rodas5_triangle_run(system, u, ts, y0, tol):
    """`simulate` with the default solver (Rodas5 for the averaged valve) at rtol = atol = `tol`. The two tests below
    run the same compiled solve: same signal type, ten output times, an explicit start, the tolerances as arrays
    (Python floats would be constants of the program, one compilation per tolerance)."""
    return pamjax.simulate(system, u, jnp.asarray(ts), y0=y0, rtol=jnp.asarray(tol), atol=jnp.asarray(tol))


def test_stiff_plant_through_stick_matches_scipy_dop853():
    # Paper 000's MAS-10 with the averaged valve, duty falling 0.95 -> 0.05 over 5.6 s: the payload goes down and
    # sticks (|v| < 1 mm/s for most of the last second: the stiff phase). Both solved at rtol 1e-10; tolerances as in
    # test_simulate: 1e-5 relative in pressure, 1e-7 m in position, 1e-5 m/s in velocity.
    system = presets.mas10_system("averaged")
    u = pamjax.Triangle(0.05, 0.95, 0.08)
    # every quarter second, plus 6.375 and 7.875 s: ten times, as the next test's run (one compiled solve)
    ts = np.sort(np.concatenate([np.linspace(6.25, 8.0, 8), [6.375, 7.875]]))
    y0 = initial_state(system, pressure=np.asarray(5.5e5))
    traj = _rodas5_triangle_run(system, u, ts, y0, 1e-10)
    plant = NumpyPlant(
        a=presets.MAS10_MAX_FORCE_COEFFICIENTS, k0=presets.MAS10_K0, k1=presets.MAS10_K1, k2=presets.MAS10_K2,
        v0=presets.MAS10_V0, v1=presets.MAS10_V1, x_min=presets.MAS10_MIN_POSITION, x_max=presets.MAS10_MAX_POSITION,
        valve="averaged", m=presets.MAS10_AVERAGED_VALVE,
    )
    ref = solve_ivp(plant.rhs, (6.25, 8.0), [5.5e5, float(y0.position), 0.0], method="DOP853", t_eval=ts,
                    rtol=1e-10, atol=[1e-4, 1e-12, 1e-10], args=(host_signal(u),))
    assert ref.success
    np.testing.assert_allclose(traj.pressure, ref.y[0], rtol=1e-5)
    np.testing.assert_allclose(traj.position, ref.y[1], atol=1e-7)
    np.testing.assert_allclose(traj.velocity, ref.y[2], atol=1e-5)
    assert np.min(np.abs(ref.y[2][1:])) < 1e-3  # it does stick


def test_takes_far_fewer_steps_than_tsit5_where_the_payload_sticks():
    # Step counts are deterministic (not timings): over 6-9 s of the triangle run (slow descent, stick, lift-off)
    # Tsit5 is held at its stability limit by the smooth Coulomb sign; Rodas5 at the same tolerance is not.
    system = presets.mas10_system("averaged")
    ts = np.linspace(0.0, 9.0, 10)
    u = pamjax.Triangle(0.05, 0.95, 0.08)
    tsit5 = pamjax.simulate(system, u, ts, solver=dfx.Tsit5())
    # the default solver for a continuous valve, at simulate's default tolerance (1e-6) and start
    rodas5 = _rodas5_triangle_run(system, u, ts, initial_state(system), 1e-6)
    assert isinstance(pamjax.unchecked.default_solver(system), pamjax.Rodas5)
    assert int(rodas5.num_steps) < 0.5 * int(tsit5.num_steps), (int(rodas5.num_steps), int(tsit5.num_steps))
    np.testing.assert_allclose(rodas5.position, tsit5.position, atol=1e-7)


def test_gradient_through_rodas5_matches_finite_differences_and_tsit5():
    # Reverse mode through the Rosenbrock step differentiates its Jacobian (second derivatives of the physics).
    # Four parameters that enter the stiff friction, the force map and the mass balance, as sensitivities θ ∂L/∂θ.
    # (1) Constant duty: against central differences (relative step 1e-5, rtol 1e-12), to 2e-5 relative.
    # (2) Triangle duty: its kinks make finite differences of an adaptive solve noisy (~1e-4), so the reference is
    #     Tsit5's reverse-mode gradient (itself checked against finite differences in test_simulate): 1e-5 (the two
    #     discrete solutions differ by ~1e-8 relative where steps cross the kinks; measured worst 2.2e-6).
    system = presets.mas10_system("averaged")
    ts = np.linspace(0.0, 0.3, 7)
    names = ("payload_mass", "friction.coulomb_force", "friction.velocity_width", "muscle.force_law.k0")
    x0 = np.asarray([float(_get(system, n)) for n in names])  # NumPy: the steps below on the host, not eager JAX

    def make_loss(solver):
        def loss(values, signal):
            s = system
            for name, value in zip(names, values):
                s = _set(s, name, value)
            y0 = s.initial_state(pressure=3e5)
            traj = solve(s, signal, ts, y0, ts[0], solver=solver, rtol=1e-12, atol=1e-12)
            return jnp.sum((traj.pressure / 1e5) ** 2) + jnp.sum((traj.position / 1e-2) ** 2)

        return loss

    # One compiled Rodas5 value-and-gradient for both parts, the signal a traced argument: the constant duty is a flat
    # triangle (0.6 + 0 · shape, exactly 0.6 at every t), and the finite differences use its values.
    rodas5 = jax.jit(jax.value_and_grad(make_loss(pamjax.Rodas5())))
    constant = pamjax.Triangle(0.6, 0.6, 4.0)
    grad = np.asarray(rodas5(x0, constant)[1]) * np.asarray(x0)
    fd = []
    for i in range(len(names)):
        step = 1e-5 * abs(float(x0[i]))
        e = np.zeros_like(x0)
        e[i] = step
        up, down = rodas5(x0 + e, constant)[0], rodas5(x0 - e, constant)[0]
        fd.append((float(up) - float(down)) / (2 * step) * float(x0[i]))
    np.testing.assert_allclose(grad, fd, rtol=2e-5, atol=1e-7 * np.max(np.abs(fd)))

    triangle = pamjax.Triangle(0.3, 0.8, 4.0)
    rodas = np.asarray(rodas5(x0, triangle)[1])
    tsit5 = np.asarray(jax.jit(jax.grad(make_loss(dfx.Tsit5())))(x0, triangle))
    np.testing.assert_allclose(rodas, tsit5, rtol=1e-5, atol=1e-9 * np.max(np.abs(tsit5)))


def _get(module, dotted):
    for part in dotted.split("."):
        module = getattr(module, part)
    return module


def _set(module, dotted, value):
    import equinox as eqx

    return eqx.tree_at(lambda m: _get(m, dotted), module, value)
