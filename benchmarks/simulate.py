"""Benchmark: paper 000's 25 s triangle experiment in pamjax against SciPy's solve_ivp on the same equations.

Plant: `presets.mas10_system` (MAS-10-300, 9.6 kg), duty triangle 0.05-0.95 at 0.08 Hz, outputs every 10 ms.
Valves: the averaged valve (eq. 13) and the smoothed PWM valve (50 Hz, edge width 1e-4 s); pamjax additionally
runs the PWM-synchronous stepping (`stepping="pwm"`, exact edges). pamjax uses `simulate`'s default solver
(`pamjax.unchecked.default_solver`: Rodas5 for the averaged valve, Tsit5 for the switching one); the averaged run is
repeated with Tsit5 for comparison (`averaged_tsit5_ms`). The peer is a float-scalar NumPy/`math`
transcription of the same vector field (same parameters, read from the pamjax objects; same initial state; same
scaled state and tolerances; same 2 ms step cap for the switching valve) integrated by `scipy.integrate.solve_ivp`
with RK45 and LSODA, in the same run. The transcription is checked against pamjax's vector field before timing.

    python benchmarks/simulate.py            # full 25 s run (SciPy PWM runs take ~5-15 s each)
    python benchmarks/simulate.py --quick    # 2 s horizon, smoke check
    PAMJAX_XLA_CPU_TUNING=0 python benchmarks/simulate.py   # XLA's default CPU loop execution, for comparison

pamjax's XLA CPU loop setting (each solve loop compiled to one function; docs/performance.md) is reported in the
output and as `xla_cpu_loop_setting=` in the RESULT line.

Ends with `RESULT averaged_ms=... pwm_ms=... speedup_averaged_vs_scipy=... speedup_pwm_vs_scipy=... ...`; the
`*_cpu_ms` figures are the process's CPU time of the same calls (one thread: what they take on a free core, whatever
else the machine runs; benchmarks/check.py compares them). `averaged_ms` times the jitted core
(`pamjax.unchecked.solve`), `averaged_simulate_ms` / `averaged_simulate_cpu_ms` the whole `simulate()` call of the
same run (its input checks, set-up and result checks too).
"""

import argparse
import math
import platform
import time

import jax

jax.config.update("jax_enable_x64", True)

import diffrax as dfx  # noqa: E402
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import pamjax  # noqa: E402
from pamjax import presets  # noqa: E402

_solve_jit = eqx.filter_jit(pamjax.unchecked.solve)  # the traceable core of simulate, without its Python-side checks
RTOL = ATOL = 1e-6  # pamjax's defaults; atol on the scaled state (1e5 Pa, 1e-2 m, 1e-2 m/s)


# ----------------------------------------------------------------------------------------------------------------
# The peer: the same vector field, transcribed to float scalars (math module) for scipy.integrate.solve_ivp.
# ----------------------------------------------------------------------------------------------------------------
def _relu(x, w):  # smooth_relu: w log(1 + exp(x / w)), overflow-safe
    y = x / w
    return w * (max(y, 0.0) + math.log1p(math.exp(-abs(y))))


def _step(x, w):  # smooth_step
    return 0.5 * (1.0 + math.tanh(0.5 * x / w))


def _ellipse_flow(p1, p2, cv, b, area, gas_constant, temperature, r_lam=0.999):
    """Paper 000 eq. 11 with the ISO 6358 laminar branch (pamjax.EllipseRestriction)."""
    forward = p1 >= p2
    p_up, p_down = (p1, p2) if forward else (p2, p1)
    ratio = min(max(p_down / max(p_up, 1.0), 0.0), 1.0)
    r_lam = max(r_lam, b + 1e-6)

    def ellipse(r):
        z = min(max((r - b) / (1.0 - b), 0.0), 1.0)
        return math.sqrt(max(1.0 - z * z, 0.0))

    if ratio > r_lam:
        phi = ellipse(r_lam) * (1.0 - ratio) / (1.0 - r_lam)
    elif ratio <= b:
        phi = 1.0
    else:
        phi = ellipse(ratio)
    sonic = cv * area * max(p_up, 0.0) / math.sqrt(gas_constant * temperature)
    return (1.0 if forward else -1.0) * sonic * phi


def numpy_field(system, signal):
    """f(t, z) on the scaled state z = (p / 1e5, x / 1e-2, v / 1e-2), as pamjax integrates it."""
    f = lambda a: float(np.asarray(a))  # noqa: E731
    air, muscle, valve = system.air, system.muscle, system.valve
    R, T, p_atm = f(air.gas_constant), f(air.temperature), f(air.atmospheric_pressure)
    law, vol = muscle.force_law, muscle.volume_law
    a = [f(c) for c in law.max_force_coefficients]
    k0, k1, k2, pmax = f(law.k0), f(law.k1), f(law.k2), f(law.max_pressure)
    v0, v1 = f(vol.v0), f(vol.v1)
    xmin, xmax, slack = f(muscle.min_position), f(muscle.max_position), f(muscle.slack_width)
    friction = system.friction
    fc, cf, vw = f(friction.coulomb_force), f(friction.viscous_coefficient), f(friction.velocity_width)
    ks, cs, ws = f(system.end_stops.stiffness), f(system.end_stops.damping), f(system.end_stops.width)
    mass, g, n = f(system.payload_mass), f(system.gravity), f(system.polytropic_index)
    lo, hi, freq = f(signal.low), f(signal.high), f(signal.frequency)
    scale = (1e5, 1e-2, 1e-2)

    if isinstance(valve, pamjax.AveragedValve):
        m = np.asarray(valve.coefficients, dtype=float).tolist()

        def mass_flow(t, u, p):
            pg = p - p_atm
            up, pp = (1.0, u, u * u), (1.0, pg, pg * pg)
            return sum(up[i] * m[i][j] * pp[j] for i in range(3) for j in range(3))
    else:
        ps, period = f(valve.supply_pressure), 1.0 / f(valve.pwm_frequency)
        d_on, d_off, ew = f(valve.switch_on_delay), f(valve.switch_off_delay), f(valve.edge_width)
        inf, ex = valve.inflate, valve.exhaust
        inf_cv, inf_b, inf_a = f(inf.discharge_coefficient), f(inf.critical_ratio), f(inf.area)
        ex_cv, ex_b, ex_a = f(ex.discharge_coefficient), f(ex.critical_ratio), f(ex.area)

        def mass_flow(t, u, p):
            phase = t - math.floor(t / period) * period
            end = u * period + d_off
            window = sum(_step(phase - d_on - k * period, ew) * _step(end + k * period - phase, ew) for k in (-1, 0, 1))
            opens = _step(u * period - d_on, ew)
            closes = _step((1.0 - u) * period - d_off, ew)
            o = opens * (closes * min(max(window, 0.0), 1.0) + (1.0 - closes))
            inflow = _ellipse_flow(ps, p, inf_cv, inf_b, inf_a, R, T)
            outflow = _ellipse_flow(p, p_atm, ex_cv, ex_b, ex_a, R, T)
            return o * inflow - (1.0 - o) * outflow

    def field(t, z):
        p, x, v = z[0] * scale[0], z[1] * scale[1], z[2] * scale[2]
        ph = t * freq - math.floor(t * freq)
        u = lo + (hi - lo) * (1.0 - abs(2.0 * ph - 1.0))
        mdot = mass_flow(t, u, p)
        volume = v0 + v1 * x
        dp = n * (R * T * mdot - p * v1 * v) / volume
        fmax = a[0] + x * (a[1] + x * (a[2] + x * (a[3] + x * a[4])))
        force = _relu(fmax - (pmax - (p - p_atm)) * (k0 - k1 * x) / k2, slack)
        friction = fc * math.tanh(v / vw) + cf * v
        over, under = x - xmax, xmin - x
        stops = -ks * _relu(over, ws) + ks * _relu(under, ws) - cs * v * (_step(over, ws) + _step(under, ws))
        dv = (force - friction + stops) / mass - g
        return np.array([dp / scale[0], v / scale[1], dv / scale[2]])

    return field


def check_transcription(system, signal, field):
    """The NumPy field equals pamjax's vector field (relative 1e-9) on random states: the same problem is solved."""
    rng = np.random.default_rng(0)
    y0 = system.initial_state()
    scale = np.array([1e5, 1e-2, 1e-2])
    for _ in range(20):
        t = float(rng.uniform(0, 25))
        y = np.array([rng.uniform(1.0e5, 6.5e5), rng.uniform(-0.02, 0.07), rng.uniform(-0.1, 0.1)])
        state = pamjax.MuscleState(pressure=jnp.asarray(y[0]), position=jnp.asarray(y[1]), velocity=jnp.asarray(y[2]),
                                   friction=y0.friction)
        dy = system.vector_field(t, state, signal(t))
        ref = np.array([float(dy.pressure), float(dy.position), float(dy.velocity)]) / scale
        got = field(t, y / scale)
        if not np.allclose(got, ref, rtol=1e-9, atol=1e-9 * np.max(np.abs(ref))):
            raise SystemExit(f"NumPy transcription differs from pamjax at t={t}, y={y}: {got} vs {ref}")


def time_scipy(system, signal, ts, method, repeats, max_step):
    field = numpy_field(system, signal)
    check_transcription(system, signal, field)
    y0 = system.initial_state()
    z0 = np.array([float(y0.pressure) / 1e5, float(y0.position) / 1e-2, float(y0.velocity) / 1e-2])
    times, sol = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        sol = solve_ivp(field, (float(ts[0]), float(ts[-1])), z0, method=method, t_eval=np.asarray(ts),
                        rtol=RTOL, atol=ATOL, max_step=max_step)
        times.append(time.perf_counter() - start)
        if not sol.success:
            raise SystemExit(f"SciPy {method} failed: {sol.message}")
    return np.median(times), sol.nfev, sol.y[1] * 1e-2, sol.y[0] * 1e5


def time_pamjax(system, signal, ts, repeats, **kwargs):
    """Compile time (first call), then the median run time of the jitted core and of the whole `simulate` call
    (its input checks, set-up and result checks too), wall and CPU."""
    args = (system, signal, ts, None, ts[0])
    if kwargs.get("stepping", "adaptive") == "adaptive":
        kwargs.setdefault("solver", pamjax.unchecked.default_solver(system))  # what simulate() picks
    if kwargs.get("stepping") == "pwm":
        kwargs["num_periods"] = pamjax.unchecked.num_periods(system.valve, float(ts[0]), float(ts[-1]))
    start = time.perf_counter()
    traj = jax.block_until_ready(_solve_jit(*args, **kwargs))
    compile_s = time.perf_counter() - start
    core, core_cpu, whole, whole_cpu = [], [], [], []
    sim_kwargs = {k: v for k, v in kwargs.items() if k != "num_periods"}
    jax.block_until_ready(pamjax.simulate(system, signal, ts, **sim_kwargs))  # warm the simulate() path too
    for _ in range(repeats):
        start, cpu = time.perf_counter(), time.process_time()
        traj = jax.block_until_ready(_solve_jit(*args, **kwargs))
        core.append(time.perf_counter() - start)
        core_cpu.append(time.process_time() - cpu)
        start, cpu = time.perf_counter(), time.process_time()
        jax.block_until_ready(pamjax.simulate(system, signal, ts, **sim_kwargs))
        whole.append(time.perf_counter() - start)
        whole_cpu.append(time.process_time() - cpu)
    return compile_s, np.median(core), np.median(whole), traj, np.median(core_cpu), np.median(whole_cpu)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 s horizon and 3 repeats (smoke check)")
    parser.add_argument("--repeats", type=int, default=None, help="timed repeats per method (default 5)")
    parser.add_argument("--skip-scipy-pwm", action="store_true", help="skip the slow SciPy PWM runs")
    args = parser.parse_args()
    horizon = 2.0 if args.quick else 25.0
    repeats = args.repeats or (3 if args.quick else 5)
    ts = jnp.linspace(0.0, horizon, int(round(horizon * 100)) + 1)  # 10 ms output grid
    signal = pamjax.Triangle(0.05, 0.95, 0.08)
    print(f"pamjax simulate benchmark: {horizon:g} s triangle, 0.05-0.95 duty at 0.08 Hz, 9.6 kg, rtol=atol={RTOL:g}")
    print(f"jax {jax.__version__}, {platform.processor() or platform.machine()}, {jax.devices()[0].platform}, "
          f"repeats={repeats}")
    xla = pamjax.runtime.xla_cpu_status()
    print(f"pamjax XLA CPU loop setting (docs/performance.md): {'active' if xla['active'] else 'inactive'} "
          f"({xla['reason']})")

    res = {}
    averaged = presets.mas10_system("averaged")
    pwm = presets.mas10_system("pwm")
    for name, system, kwargs in (
        ("averaged", averaged, {}),  # default solver: Rodas5
        ("avg_tsit5", averaged, dict(solver=dfx.Tsit5())),  # the explicit solver, for comparison
        ("pwm", pwm, {}),  # default solver: Tsit5
        ("pwm_sync", pwm, dict(stepping="pwm")),
    ):
        c, core, whole, traj, core_cpu, whole_cpu = time_pamjax(system, signal, ts, repeats, **kwargs)
        res[name] = dict(compile=c, core=core, whole=whole, traj=traj, cpu=core_cpu, whole_cpu=whole_cpu)
        print(f"  pamjax {name:9s} compile {c:6.2f} s  run {core * 1e3:8.2f} ms (simulate() {whole * 1e3:8.2f} ms)  "
              f"steps {int(traj.num_steps):6d} (rejected {int(traj.num_rejected_steps)})", flush=True)

    scipy_pwm_step = float(pwm.valve.max_step())  # the same 2 ms cap pamjax's adaptive solve uses
    for name, system in (("averaged", averaged), ("pwm", pwm)):
        if name == "pwm" and args.skip_scipy_pwm:
            continue
        for method in ("RK45", "LSODA"):
            run_s, nfev, x, p = time_scipy(system, signal, ts, method, repeats if name == "averaged" else max(
                repeats // 2 + 1, 1), np.inf if name == "averaged" else scipy_pwm_step)
            traj = res[name]["traj"]
            dx = np.max(np.abs(x - np.asarray(traj.position))) * 1e3
            dp = np.max(np.abs(p - np.asarray(traj.pressure)))
            res[name][method] = run_s
            print(f"  scipy  {name:9s} {method:5s}  run {run_s * 1e3:8.1f} ms  nfev {nfev:7d}  "
                  f"max|x - x_pamjax| {dx:.2e} mm  max|p - p_pamjax| {dp:.2e} Pa", flush=True)

    sync, smooth = res["pwm_sync"]["traj"], res["pwm"]["traj"]
    print(f"  pwm_sync (exact edges) vs smooth adaptive: max|dx| "
          f"{np.max(np.abs(np.asarray(sync.position - smooth.position))) * 1e3:.2e} mm, max|dp| "
          f"{np.max(np.abs(np.asarray(sync.pressure - smooth.pressure))):.2e} Pa")

    def best(name):
        return min(res[name].get("RK45", np.nan), res[name].get("LSODA", np.nan))

    sp_avg = best("averaged") / res["averaged"]["core"]
    sp_pwm = best("pwm") / res["pwm"]["core"] if "LSODA" in res["pwm"] else float("nan")
    sp_sync = best("pwm") / res["pwm_sync"]["core"] if "LSODA" in res["pwm"] else float("nan")
    print(f"  speedup vs best SciPy: averaged {sp_avg:.1f}x, smooth PWM {sp_pwm:.1f}x, PWM-synchronous {sp_sync:.1f}x")
    print(
        f"RESULT averaged_ms={res['averaged']['core'] * 1e3:.2f} pwm_ms={res['pwm']['core'] * 1e3:.1f} "
        f"speedup_averaged_vs_scipy={sp_avg:.1f} speedup_pwm_vs_scipy={sp_pwm:.1f} "
        f"pwm_sync_ms={res['pwm_sync']['core'] * 1e3:.1f} speedup_pwm_sync_vs_scipy={sp_sync:.1f} "
        f"averaged_simulate_ms={res['averaged']['whole'] * 1e3:.2f} "
        f"averaged_tsit5_ms={res['avg_tsit5']['core'] * 1e3:.2f} "
        f"speedup_averaged_tsit5_vs_scipy={best('averaged') / res['avg_tsit5']['core']:.1f} horizon_s={horizon:g} "
        f"xla_cpu_loop_setting={int(xla['active'])} averaged_cpu_ms={res['averaged']['cpu'] * 1e3:.2f} "
        f"pwm_cpu_ms={res['pwm']['cpu'] * 1e3:.1f} pwm_sync_cpu_ms={res['pwm_sync']['cpu'] * 1e3:.1f} "
        f"averaged_simulate_cpu_ms={res['averaged']['whole_cpu'] * 1e3:.2f}"
    )


if __name__ == "__main__":
    main()
