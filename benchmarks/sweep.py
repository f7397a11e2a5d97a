"""Benchmark: 1,024 constant duties x 5 s of paper 000's MAS-10 plant, pamjax `sweep` against its peers.

Peers, all in this one run, on the SAME equations (an independent scalar transcription for numba/SciPy):
- pamjax `sweep` with the averaged valve, reduced to the final state on the fly: the default method (`"auto"` =
  `"rodas5a"`: RODAS5 under per-lane error control, trajectory-accurate; the headline figure), RK4 at its stability
  limit (trajectory-accurate, fixed step) and ROS2 at 5 ms (steady-state configuration);
- numba: a hand-written fixed-step RK4 loop over the 1,024 duties (serial and `prange`);
- SciPy: a loop of `solve_ivp(method="LSODA")` on a plain-Python right-hand side (what a SciPy user writes; the
  `speedup_vs_scipy` peer) and on the numba-compiled one (the stronger variant, `speedup_vs_scipy_numba_rhs`), each
  timed on a subset (median of the repeats) and extrapolated to 1,024 (said in the output);
- pamjax `sweep` with the smoothed PWM valve (RK4 at 2 edge widths);
- pamjax `sweep(method="ros2a")`: ROS2 under error control at 1e-3 (a quick map: looser than the others, its
  errors are printed beside it; not used for the headline ratios).

Accuracy matching: every method's final state is compared with a tight reference (DOP853, rtol = atol = 1e-12, on
the numba transcription). RK4 cannot take a step beyond its stability limit (|λ h| < 2.78; λ ≈ 1,700 /s from the
smooth friction sign), so at any accuracy target at or above its error there, numba's fastest run IS the RK4 run at
that limit; the run at 1.35x that step shows what happens past it. pamjax RK4 and numba RK4 use the identical step.

Usage: python benchmarks/sweep.py [--points 1024] [--horizon 5] [--scipy-subset 16] [--repeats 3] [--host-devices 2]
                                 [--pwm-points N] [--quick]
(`--quick`, for benchmarks/check.py: the SciPy loop timed on 4 points, the PWM sweep on 128; the headline averaged
sweep as in a full run.)
Ends with: RESULT sweep_avg_s=... sweep_pwm_s=... speedup_vs_scipy=... ratio_vs_numba=...
"""

import argparse
import math
import time

import numpy as np


def median_time(fn, repeats):
    return median_times(fn, repeats)[0]


def median_times(fn, repeats):
    """Medians of the wall time and of the process's CPU time of `fn()` over `repeats` calls. On one XLA device a
    sweep runs on one thread, so its CPU time is what the call takes on a free core, whatever else the machine
    runs (benchmarks/check.py compares it)."""
    walls, cpus = [], []
    for _ in range(repeats):
        start, cpu = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu)
    return float(np.median(walls)), float(np.median(cpus))


def numba_plant(system):
    """Scalar numba transcription of MuscleSystem + AveragedValve + CoulombViscousFriction + EndStops."""
    import numba

    air, muscle, law, vol = system.air, system.muscle, system.muscle.force_law, system.muscle.volume_law
    coef = np.asarray(system.valve.coefficients, dtype=float)
    a = np.asarray(law.max_force_coefficients, dtype=float)
    pa, rt = float(air.atmospheric_pressure), float(air.gas_constant * air.temperature)
    n = float(system.polytropic_index)
    k0, k1, k2, pmax = float(law.k0), float(law.k1), float(law.k2), float(law.max_pressure)
    v0, v1 = float(vol.v0), float(vol.v1)
    xmin, xmax, sw = float(muscle.min_position), float(muscle.max_position), float(muscle.slack_width)
    fc, cf, w = float(system.friction.coulomb_force), float(system.friction.viscous_coefficient), float(
        system.friction.velocity_width)
    ks, cs, ds = float(system.end_stops.stiffness), float(system.end_stops.damping), float(system.end_stops.width)
    mass, g = float(system.payload_mass), float(system.gravity)

    @numba.njit(inline="always")
    def softplus(z):
        return max(z, 0.0) + math.log1p(math.exp(-abs(z)))

    @numba.njit
    def rhs(p, x, v, u):
        pg = p - pa
        mdot = 0.0
        ui = 1.0
        for i in range(3):
            mdot += ui * (coef[i, 0] + coef[i, 1] * pg + coef[i, 2] * pg * pg)
            ui *= u
        volume = v0 + v1 * x
        dp = n * (rt * mdot - p * v1 * v) / volume
        fmax = a[0] + x * (a[1] + x * (a[2] + x * (a[3] + x * a[4])))
        fstatic = fmax - (pmax - pg) * (k0 - k1 * x) / k2
        fmuscle = sw * softplus(fstatic / sw)
        ffric = fc * math.tanh(v / w) + cf * v
        over, under = x - xmax, xmin - x
        spring = -ks * ds * softplus(over / ds) + ks * ds * softplus(under / ds)
        contact = 0.5 * (1.0 + math.tanh(0.5 * over / ds)) + 0.5 * (1.0 + math.tanh(0.5 * under / ds))
        dv = (fmuscle - ffric + spring - cs * v * contact) / mass - g
        return dp, v, dv

    @numba.njit
    def rk4_one(p, x, v, u, h, steps):
        for _ in range(steps):
            a1, b1, c1 = rhs(p, x, v, u)
            a2, b2, c2 = rhs(p + 0.5 * h * a1, x + 0.5 * h * b1, v + 0.5 * h * c1, u)
            a3, b3, c3 = rhs(p + 0.5 * h * a2, x + 0.5 * h * b2, v + 0.5 * h * c2, u)
            a4, b4, c4 = rhs(p + h * a3, x + h * b3, v + h * c3, u)
            p += h / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4)
            x += h / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4)
            v += h / 6.0 * (c1 + 2 * c2 + 2 * c3 + c4)
        return p, x, v

    @numba.njit
    def rk4_serial(duties, p0, x0, h, steps):
        out = np.empty((duties.size, 3))
        for i in range(duties.size):
            out[i] = rk4_one(p0, x0, 0.0, duties[i], h, steps)
        return out

    @numba.njit(parallel=True)
    def rk4_parallel(duties, p0, x0, h, steps):
        out = np.empty((duties.size, 3))
        for i in numba.prange(duties.size):
            out[i] = rk4_one(p0, x0, 0.0, duties[i], h, steps)
        return out

    def rhs_python(p, x, v, u):
        """The same right-hand side in plain Python (math module): what a SciPy user writes."""
        pg = p - pa
        mdot, ui = 0.0, 1.0
        for row in coef_rows:
            mdot += ui * (row[0] + row[1] * pg + row[2] * pg * pg)
            ui *= u
        volume = v0 + v1 * x
        dp = n * (rt * mdot - p * v1 * v) / volume
        fmax = a_py[0] + x * (a_py[1] + x * (a_py[2] + x * (a_py[3] + x * a_py[4])))
        fstatic = fmax - (pmax - pg) * (k0 - k1 * x) / k2
        fmuscle = sw * softplus.py_func(fstatic / sw)
        ffric = fc * math.tanh(v / w) + cf * v
        over, under = x - xmax, xmin - x
        spring = -ks * ds * softplus.py_func(over / ds) + ks * ds * softplus.py_func(under / ds)
        contact = 0.5 * (1.0 + math.tanh(0.5 * over / ds)) + 0.5 * (1.0 + math.tanh(0.5 * under / ds))
        dv = (fmuscle - ffric + spring - cs * v * contact) / mass - g
        return dp, v, dv

    coef_rows = [[float(c) for c in row] for row in coef]
    a_py = [float(c) for c in a]
    return rhs, rhs_python, rk4_serial, rk4_parallel


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=1024)
    parser.add_argument("--horizon", type=float, default=5.0)
    parser.add_argument("--scipy-subset", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--pwm-points", type=int, default=None, help="points of the PWM-valve sweep (default --points)")
    parser.add_argument("--quick", action="store_true", help="SciPy timed on 4 points, the PWM sweep on 128")
    parser.add_argument("--default-only", action="store_true",
                        help="time pamjax's default method alone (no peers, no reference): RESULT sweep_avg_s")
    parser.add_argument("--host-devices", type=int, default=1,
                        help="split the CPU into this many XLA devices; pamjax.sweep shards its batch over them "
                             "(2 on a 2-core machine uses both cores, as numba's prange does)")
    args = parser.parse_args()
    if args.quick:
        args.scipy_subset = min(args.scipy_subset, 4)
        args.pwm_points = args.pwm_points or 128
    if args.host_devices > 1:  # must be set before JAX starts
        import os

        os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") +
                                   f" --xla_force_host_platform_device_count={args.host_devices}").strip()

    import jax

    jax.config.update("jax_enable_x64", True)
    import numba
    from scipy.integrate import solve_ivp

    import pamjax
    from pamjax import presets

    platform = jax.devices()[0].platform
    print(f"jax {jax.__version__} ({platform}, {len(jax.devices())} device), numba {numba.__version__}")
    system = presets.mas10_system(valve="averaged")
    duties = np.linspace(0.0, 1.0, args.points)
    ts = np.linspace(0.0, args.horizon, int(round(args.horizon * 10)) + 1)  # outputs every 0.1 s, steps land on them
    if args.default_only:  # benchmarks/check.py's two-device check: the headline figure alone
        def call():
            return pamjax.sweep(system, pamjax.Constant(0.5), ts, {"signal.value": duties}, reduce=pamjax.FinalValue(),
                                channels=("pressure", "position"), progress=False)

        start = time.perf_counter()
        result = call()
        first = time.perf_counter() - start
        run, cpu = median_times(call, args.repeats)
        print(f"pamjax default ({result.method}): first call {first:.2f} s, run {run:.3f} s, CPU {cpu:.3f} s "
              f"(medians of {args.repeats})")
        print(f"RESULT sweep_avg_s={run:.3f} sweep_avg_cpu_s={cpu:.3f} devices={len(jax.devices())}")
        return
    y0 = system.initial_state()
    p0, x0 = float(y0.pressure), float(y0.position)
    check = np.unique(np.linspace(0, args.points - 1, 8).astype(int))  # points whose error is measured

    rhs, rhs_python, rk4_serial, rk4_parallel = numba_plant(system)

    def rhs_vec(t, y, u):
        return np.array(rhs(y[0], y[1], y[2], u))

    def rhs_vec_python(t, y, u):
        return np.array(rhs_python(y[0], y[1], y[2], u))

    state = np.array([p0 + 2e5, x0 + 0.01, 0.02])
    if not np.allclose(rhs_vec_python(0.0, state, 0.37), rhs_vec(0.0, state, 0.37), rtol=1e-12, atol=0.0):
        raise SystemExit("the plain-Python right-hand side differs from the numba one")

    # --- tight reference (independent transcription, DOP853)
    reference = np.array([solve_ivp(rhs_vec, (0, args.horizon), [p0, x0, 0.0], method="DOP853", rtol=1e-12,
                                    atol=[1e-6, 1e-13, 1e-13], args=(duties[i],)).y[:, -1] for i in check])

    def errors(final):  # final: (len(check), >=2) pressure [Pa], position [m]
        difference = np.abs(final[:, :2] - reference[:, :2])
        return float(np.max(difference[:, 0])), float(np.max(difference[:, 1]))

    rows = {}

    # --- pamjax
    cpu_times = {}

    def pamjax_run(system, method, dt=None, duties=duties):
        def call():
            return pamjax.sweep(system, pamjax.Constant(0.5), ts, {"signal.value": duties}, reduce=pamjax.FinalValue(),
                                channels=("pressure", "position"), method=method, dt=dt, progress=False)

        start = time.perf_counter()
        result = call()
        first = time.perf_counter() - start
        run, cpu_times[method if system.valve.switches is False else "pwm"] = median_times(call, args.repeats)
        return result, first - run, run

    res_rk4, compile_rk4, t_rk4 = pamjax_run(system, "rk4")
    h, steps = res_rk4.dt, int(round(args.horizon / res_rk4.dt))
    counts = int(math.ceil(0.1 / h * (1 - 1e-12)))
    h = 0.1 / counts  # the exact step pamjax took (steps land on the 0.1 s outputs)
    steps = counts * (len(ts) - 1)
    final = np.stack([res_rk4["pressure"], res_rk4["position"]], axis=1)
    rows["pamjax rk4"] = (t_rk4, compile_rk4, h, *errors(final[check]))
    res_ros2, compile_ros2, t_ros2 = pamjax_run(system, "ros2")
    final_ros2 = np.stack([res_ros2["pressure"], res_ros2["position"]], axis=1)
    rows["pamjax ros2 (steady state)"] = (t_ros2, compile_ros2, res_ros2.dt, *errors(final_ros2[check]))
    res_auto, compile_auto, t_auto = pamjax_run(system, "auto")
    final_auto = np.stack([res_auto["pressure"], res_auto["position"]], axis=1)
    rows[f"pamjax default ({res_auto.method}, error control)"] = (t_auto, compile_auto, float("nan"),
                                                                *errors(final_auto[check]))
    res_ros2a, compile_ros2a, t_ros2a = pamjax_run(system, "ros2a")
    final_ros2a = np.stack([res_ros2a["pressure"], res_ros2a["position"]], axis=1)
    rows["pamjax ros2a (quick map, error control 1e-3)"] = (t_ros2a, compile_ros2a, float("nan"),
                                                            *errors(final_ros2a[check]))

    # --- numba RK4, same equations, same step
    start = time.perf_counter()
    rk4_serial(duties[:2], p0, x0, h, 10)
    rk4_parallel(duties[:2], p0, x0, h, 10)
    compile_numba = time.perf_counter() - start
    out_numba = rk4_serial(duties, p0, x0, h, steps)
    t_numba = median_time(lambda: rk4_serial(duties, p0, x0, h, steps), args.repeats)
    t_numba_par = median_time(lambda: rk4_parallel(duties, p0, x0, h, steps), args.repeats)
    rows["numba rk4 serial"] = (t_numba, compile_numba, h, *errors(out_numba[check]))
    name = f"numba rk4 prange ({numba.get_num_threads()} threads)"
    rows[name] = (t_numba_par, compile_numba, h, *errors(out_numba[check]))
    h_big = 1.35 * h
    out_big = rk4_serial(duties, p0, x0, h_big, int(round(args.horizon / h_big)))
    rows["numba rk4 at 1.35x step"] = (float("nan"), 0.0, h_big, *errors(out_big[check]))
    agree = float(np.max(np.abs(out_numba[:, 1] - res_rk4["position"])))

    # --- SciPy loops (LSODA, same tolerances), timed on a subset and extrapolated: on the numba right-hand side and on
    # the plain-Python one (what a SciPy user writes)
    subset = duties[np.linspace(0, args.points - 1, args.scipy_subset).astype(int)]

    def scipy_finals(field, us):
        return np.array([solve_ivp(field, (0, args.horizon), [p0, x0, 0.0], method="LSODA", rtol=1e-8,
                                   atol=[1e-2, 1e-9, 1e-9], args=(u,)).y[:, -1] for u in us])

    def scipy_row(field, label):  # median of `repeats` timings of the subset, extrapolated
        elapsed = median_time(lambda: scipy_finals(field, subset), args.repeats) * args.points / args.scipy_subset
        rows[f"scipy LSODA loop, {label} (x{args.points}/{args.scipy_subset})"] = (
            elapsed, 0.0, float("nan"), *errors(scipy_finals(field, duties[check])))
        return elapsed

    t_scipy_numba = scipy_row(rhs_vec, "numba RHS")
    t_scipy = scipy_row(rhs_vec_python, "Python RHS")

    # --- PWM valve
    pwm = presets.mas10_system(valve="pwm")
    pwm_points = args.pwm_points or args.points
    duties_pwm = np.linspace(0.0, 1.0, pwm_points)
    check_pwm = np.unique(np.linspace(0, pwm_points - 1, 8).astype(int))[1:-1:2]  # interior duties, edges off the grid
    res_pwm, compile_pwm, t_pwm = pamjax_run(pwm, "rk4", duties=duties_pwm)
    ref_pwm = [pamjax.simulate(pwm, pamjax.Constant(float(duties_pwm[i])), ts[[0, -1]], rtol=1e-11, atol=1e-11,
                               max_steps=10**6) for i in check_pwm]
    err_pwm_p = max(abs(float(r.pressure[-1]) - res_pwm["pressure"][i]) for r, i in zip(ref_pwm, check_pwm))
    err_pwm_x = max(abs(float(r.position[-1]) - res_pwm["position"][i]) for r, i in zip(ref_pwm, check_pwm))
    rows[f"pamjax rk4, PWM valve ({pwm_points} points)"] = (t_pwm, compile_pwm, res_pwm.dt, err_pwm_p, err_pwm_x)

    print(f"\n{args.points} constant duties x {args.horizon} s, MAS-10 + 9.6 kg (paper 000), final state per point; "
          f"medians of {args.repeats}; errors: max over {len(check)} duties vs DOP853 rtol 1e-12 "
          f"(PWM: vs pamjax.simulate Tsit5 rtol 1e-11, {len(check_pwm)} duties)")
    print(f"{'method':42s} {'run [s]':>9s} {'compile [s]':>11s} {'step [s]':>10s} {'err p [Pa]':>10s} "
          f"{'err x [m]':>10s} {'numba/this':>10s}")
    for name, (t, c, dt, ep, ex) in rows.items():
        ratio = t_numba / t if np.isfinite(t) else float("nan")
        print(f"{name:42s} {t:9.3f} {c:11.2f} {dt:10.2e} {ep:10.2e} {ex:10.2e} {ratio:10.2f}")
    print(f"pamjax rk4 vs numba rk4 (same step), max |Δx| over all points: {agree:.1e} m")
    print(f"SciPy loop time (median of repeats) extrapolated from {args.scipy_subset} of {args.points} points")
    scipy_err = rows[f"scipy LSODA loop, Python RHS (x{args.points}/{args.scipy_subset})"][3:]
    auto_err = rows[f"pamjax default ({res_auto.method}, error control)"][3:]
    matched = auto_err[0] <= scipy_err[0] and auto_err[1] <= scipy_err[1]
    print(f"pamjax default ({res_auto.method}) accuracy {'at or better than' if matched else 'LOOSER than'} SciPy's "
          f"in both pressure and position")
    print(f"speedup vs the SciPy loop: Python RHS {t_scipy / t_auto:.0f}x (default), {t_scipy / t_rk4:.0f}x (RK4), "
          f"{t_scipy / t_ros2:.0f}x (ROS2); numba RHS {t_scipy_numba / t_auto:.0f}x (default)")
    print(f"RESULT sweep_avg_s={t_auto:.3f} sweep_pwm_s={t_pwm:.3f} speedup_vs_scipy={t_scipy / t_auto:.0f} "
          f"ratio_vs_numba={t_numba / t_auto:.2f} accuracy_matched={matched} sweep_avg_rk4_s={t_rk4:.3f} "
          f"sweep_avg_ros2_s={t_ros2:.3f} ratio_vs_numba_same_scheme={t_numba / t_rk4:.2f} "
          f"speedup_vs_scipy_rk4={t_scipy / t_rk4:.0f} speedup_vs_scipy_numba_rhs={t_scipy_numba / t_auto:.0f} "
          f"devices={len(jax.devices())} sweep_avg_ros2a_s={t_ros2a:.3f} "
          f"speedup_vs_scipy_ros2a={t_scipy / t_ros2a:.0f} pwm_points={pwm_points} "
          f"sweep_avg_cpu_s={cpu_times['auto']:.3f} sweep_pwm_cpu_s={cpu_times['pwm']:.3f}")


if __name__ == "__main__":
    main()
