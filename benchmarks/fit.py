"""Joint-fit benchmark: pamjax (its optimistix Levenberg-Marquardt, forward-mode Jacobians through diffrax, jitted)
against SciPy (`scipy.optimize.least_squares`, trust-region reflective, 2-point finite-difference Jacobian, each
residual from `scipy.integrate.solve_ivp` RK45 on an independent NumPy transcription of the same vector field), on
the same synthetic data, model, parameterisation (pamjax's unconstrained θ) and start.

Model: MAS-10 preset with the averaged valve (eq. 13). 20 free parameters: m1…m9, a0…a4 (node basis), k0, k1, v0,
v1, F_c, C_f. 4 experiments: triangle runs at 0.25 Hz (8 s) and 0.08 Hz (12.5 s, half a period), tank charge and
discharge at duty 0.5 (2 s); `--rate` Hz samples (default 50), noise 2 kPa / 0.1 mm, start 10 % off.

speedup = SciPy's time to reach pamjax's final cost (or, if it stops short, its time to stop: then `scipy_reached=0`)
÷ pamjax's fit time after compilation. Ends with one `RESULT` line.

`--solvers` fits the same problem again with other optimistix solvers, each in `pamjax.fit(solver=...)` on the same
two compiled programs, printed beside pamjax's default (`RESULT` is the default's): `plain` (pamjax's
`LevenbergMarquardt(geodesic=False)`), `optimistix` (`optimistix.LevenbergMarquardt(rtol=1e-8, atol=1e-8)`, run by
`optimistix.least_squares`). `--skip-scipy`: pamjax's fits only.

    python benchmarks/fit.py [--rate 50] [--scipy-budget-s 600] [--skip-scipy] [--solvers plain,optimistix]
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax import presets  # noqa: E402

FAILED_RESIDUAL = 1e6  # a failed SciPy solve's residual (pamjax's own fit rejects such a trial instead)

FREE = ["valve.coefficients", "muscle.force_law.max_force_coefficients", "muscle.force_law.k0", "muscle.force_law.k1",
        "muscle.volume_law.v0", "muscle.volume_law.v1", "friction.coulomb_force", "friction.viscous_coefficient"]
NOISE = dict(pressure=2e3, position=1e-4)


def build_experiments(truth, rate):
    specs = [("tri_025", pj.Triangle(0.05, 0.95, 0.25), 8.0, None, {}),
             ("tri_008", pj.Triangle(0.05, 0.95, 0.08), 12.5, None, {}),
             ("charge_050", pj.Constant(0.5), 2.0, pj.TankFromModel(5e-5), dict(pressure=101325.0)),
             ("discharge_050", pj.Constant(0.5), 2.0, pj.TankFromModel(5e-5), dict(pressure=6.5e5))]
    exps = []
    for k, (name, sig, horizon, build, initial) in enumerate(specs):
        system = truth if build is None else build(truth)
        channels = ["pressure"] if build is not None else ["pressure", "position"]
        ts = np.arange(0.0, horizon + 1e-9, 1.0 / rate)
        rec = pj.synthetic_recording(system, sig, ts, noise={c: NOISE[c] for c in channels}, seed=k, name=name,
                                     channels=channels, y0=system.initial_state(**initial))
        exps.append(pj.Experiment(rec, sig, channels=channels, scales={c: NOISE[c] for c in channels}, build=build,
                                  initial=initial, name=name))
    return exps


# --- SciPy peer: an independent NumPy transcription of the averaged-valve muscle/tank vector fields -------------
P_ATM, R, T, N_POLY, M, G = 101325.0, 287.0, 293.0, 1.4, 9.6, 9.81
P_MAX, K2, SLACK_W, V_W = 6e5, 1e5, 1.0, 1e-3
X_MIN, X_MAX, K_STOP, C_STOP, W_STOP = -0.02, 0.075, 1e6, 6e3, 1e-4


def softplus(x, w):
    return w * np.logaddexp(x / w, 0.0)


def mdot(m, u, p):
    pg = p - P_ATM
    return np.array([1.0, u, u * u]) @ m @ np.array([1.0, pg, pg * pg])


def static_force(q, x, p):
    a = q["a"]
    fmax = a[0] + x * (a[1] + x * (a[2] + x * (a[3] + x * a[4])))
    return fmax - (P_MAX - (p - P_ATM)) * (q["k0"] - q["k1"] * x) / K2


def muscle_rhs(t, y, q, sig):
    p, x, v = y
    u = sig(t)
    vol, dvol = q["v0"] + q["v1"] * x, q["v1"] * v
    dp = N_POLY * (R * T * mdot(q["m"], u, p) - p * dvol) / vol
    f = softplus(static_force(q, x, p), SLACK_W)
    fric = q["Fc"] * np.tanh(v / V_W) + q["Cf"] * v
    over, under = x - X_MAX, X_MIN - x
    stops = -K_STOP * softplus(over, W_STOP) + K_STOP * softplus(under, W_STOP) - C_STOP * v * (
        0.5 * (1 + np.tanh(0.5 * over / W_STOP)) + 0.5 * (1 + np.tanh(0.5 * under / W_STOP)))
    return [dp, v, (f - fric + stops) / M - G]


def equilibrium(q):
    lo, hi = X_MIN, X_MAX
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if softplus(static_force(q, mid, P_ATM), SLACK_W) - M * G > 0 else (lo, mid)
    return 0.5 * (lo + hi)


def scipy_residuals(theta, space, exps, counter):
    from scipy.integrate import solve_ivp

    vals = np.asarray(space.physical(jnp.asarray(theta)))
    q = dict(m=vals[:9].reshape(3, 3), a=vals[9:14], k0=vals[14], k1=vals[15], v0=vals[16], v1=vals[17],
             Fc=vals[18], Cf=vals[19])
    out = []
    for e in exps:
        ts = np.asarray(e.times)
        sig = e.signal
        u_of = (lambda s: (lambda t: float(s(t))))(sig)  # signals are cheap pure functions of t
        counter[0] += 1
        if len(e.channels) == 1:
            V = float(e.build.volume)
            sol = solve_ivp(lambda t, y: [N_POLY * R * T * mdot(q["m"], u_of(t), y[0]) / V], (ts[0], ts[-1]),
                            [float(e.initial["pressure"])], t_eval=ts, rtol=1e-6, atol=[0.1])
            pred = dict(pressure=sol.y[0] if sol.success else np.full(ts.size, np.nan))
        else:
            sol = solve_ivp(muscle_rhs, (ts[0], ts[-1]), [P_ATM, equilibrium(q), 0.0], t_eval=ts, rtol=1e-6,
                            atol=[0.1, 1e-8, 1e-8], args=(q, u_of))
            ok = sol.success
            pred = dict(pressure=sol.y[0] if ok else np.full(ts.size, np.nan),
                        position=sol.y[1] if ok else np.full(ts.size, np.nan))
        for c in e.channels:
            out.append((pred[c] - np.asarray(e.data[c])) * np.asarray(e.weights[c]))
    r = np.concatenate(out)
    return np.where(np.isfinite(r), r, FAILED_RESIDUAL) if not np.all(np.isfinite(r)) else r


def other_solver(name):
    """The optimistix solvers `--solvers` compares with pamjax's default."""
    if name == "plain":
        return pj.LevenbergMarquardt(geodesic=False)
    if name == "optimistix":
        import optimistix as optx

        return optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8)
    raise SystemExit(f"--solvers: unknown solver {name!r} (plain, optimistix)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--scipy-budget-s", type=float, default=600.0, help="wall-time cap for SciPy")
    ap.add_argument("--off", type=float, default=0.10, help="relative start offset")
    ap.add_argument("--skip-scipy", action="store_true", help="pamjax's fit only (benchmarks/check.py's quick run)")
    ap.add_argument("--solvers", default="", help="comma-separated: plain, optimistix (fitted beside the default)")
    args = ap.parse_args()

    truth = presets.mas10_system(valve="averaged")
    exps = build_experiments(truth, args.rate)
    space = pj.ParameterSpace(truth, FREE)
    true_values = np.asarray(space.initial_values())
    signs = np.where(np.arange(true_values.size) % 2 == 0, 1.0, -1.0)
    factors = 1.0 + args.off * signs
    factors[9:14] = 1.0 + args.off  # the quartic scaled as a whole
    start = space.with_values(true_values * factors)

    t0 = time.perf_counter()
    res = pj.fit(start, exps, FREE, max_steps=100, progress=False)
    total = time.perf_counter() - t0
    error = np.abs(np.asarray(res.values) - true_values)
    nonzero = true_values != 0  # m1 (eq. 13's constant term) is exactly 0 in the preset: no relative error there
    rel = np.where(nonzero, error / np.where(nonzero, np.abs(true_values), 1.0), 0.0)
    z = error / np.asarray(res.standard_errors)  # distance from the truth in reported standard errors
    print(f"pamjax: {res.status}, {res.iterations} iterations, cost {res.initial_cost:.6g} -> {res.cost:.6g}; "
          f"fit {res.fit_s:.2f} s after compile {res.compile_s:.2f} s (wall incl. setup {total:.1f} s)")
    print(f"pamjax max |fitted - true|/|true| = {rel.max():.3g} ({res.labels[int(rel.argmax())]}; over the "
          f"{int(nonzero.sum())} parameters whose truth is non-zero); max |fitted - true|/std err = {z.max():.2f} "
          f"({res.labels[int(z.argmax())]})")
    for i in np.flatnonzero(~nonzero):
        print(f"  {res.labels[i]}: true 0, fitted {res.values[i]:.3g} ± {res.standard_errors[i]:.3g}")
    for name in filter(None, args.solvers.split(",")):
        other = pj.fit(start, exps, FREE, max_steps=100, progress=False, solver=other_solver(name))
        print(f"SOLVER {name}: {other.status}, {other.iterations} iterations ({other.accepted_steps} accepted), cost "
              f"{other.cost:.9g} ({other.cost / res.cost:.6f} x the default's); fit {other.fit_s:.2f} s after "
              f"compile {other.compile_s:.2f} s ({other.fit_s / res.fit_s:.2f} x the default's fit time)")
    if args.skip_scipy:
        print(f"RESULT fit_s={res.fit_s:.3f} compile_s={res.compile_s:.3f} cost={res.cost:.6g} "
              f"max_rel_error={rel.max():.3g} max_z={z.max():.2f} total_s={res.fit_s + res.compile_s:.3f} "
              f"iterations={res.iterations} n_params={true_values.size} n_experiments={len(exps)}")
        return

    from scipy.optimize import least_squares

    space_start = pj.ParameterSpace(start, FREE)
    theta0 = np.asarray(space.theta(space_start.initial_values()))
    counter, trace = [0], []
    t_start = time.perf_counter()

    class Budget(Exception):
        pass

    def fun(theta):
        if time.perf_counter() - t_start > args.scipy_budget_s:
            raise Budget
        r = scipy_residuals(theta, space, exps, counter)
        trace.append((time.perf_counter() - t_start, 0.5 * float(r @ r)))
        return r

    try:
        sp = least_squares(fun, theta0, jac="2-point", method="trf", x_scale=1.0, max_nfev=200)
        scipy_stop = "converged" if sp.status > 0 else f"status {sp.status}"
    except Budget:
        scipy_stop = f"time budget {args.scipy_budget_s:.0f} s"
    scipy_s = time.perf_counter() - t_start
    scipy_cost = min(c for _, c in trace)
    reached = [t for t, c in trace if c <= res.cost * (1 + 1e-6)]
    scipy_time = reached[0] if reached else scipy_s
    print(f"scipy: stopped by {scipy_stop} after {scipy_s:.1f} s and {counter[0]} simulations; best cost "
          f"{scipy_cost:.6g}; {'reached' if reached else 'did NOT reach'} pamjax's cost"
          + (f" after {scipy_time:.1f} s" if reached else ""))
    speedup = scipy_time / res.fit_s
    print(f"RESULT fit_s={res.fit_s:.3f} compile_s={res.compile_s:.3f} scipy_fit_s={scipy_time:.3f} "
          f"speedup={speedup:.1f} cost={res.cost:.6g} scipy_cost={scipy_cost:.6g} max_rel_error={rel.max():.3g} "
          f"max_z={z.max():.2f} total_s={res.fit_s + res.compile_s:.3f} "
          f"scipy_reached={int(bool(reached))} n_params={true_values.size} n_experiments={len(exps)}")


if __name__ == "__main__":
    main()
