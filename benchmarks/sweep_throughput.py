"""Benchmark: throughput of one large `pamjax.sweep` (default 100,000 constant duties x 5 s, MAS-10 + 9.6 kg).

Issue 4 asks for a 100,000-point sweep's throughput on a GPU when one is available; this script runs on any JAX
backend (CPU too, where a smaller `--points` is sensible). It times `sweep` with the averaged valve (RODAS5 under
per-lane error control, the default there; RK4 at its stability limit: both trajectory-accurate; ROS2 at 5 ms:
steady-state maps) and with the smoothed PWM valve (RK4), each reduced to the final state, and reports points per
second. Compile time (first call minus run) and run time are
separate; run time is the median of `--repeats` calls. Correctness on the device: a few points are compared with a
tight adaptive solve (`pamjax.simulate`, Tsit5, rtol = atol = 1e-10) of the same plant on the host CPU.

    python benchmarks/sweep_throughput.py                           # 100,000 points, all methods
    python benchmarks/sweep_throughput.py --points 8192 --chunk-size 8192 --methods rk4,ros2

`--kernel on` runs a GPU's lanes as one Pallas kernel (`PAMJAX_SWEEP_KERNEL=1`, `pamjax/_sweep/kernel.py`).

Ends with `RESULT platform=... points=... kernel=off|on avg_rodas5a_pts_per_s=... avg_rk4_pts_per_s=... ...
pwm_rk4_pts_per_s=...`.
"""

import argparse
import time

import numpy as np


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--horizon", type=float, default=5.0)
    parser.add_argument("--chunk-size", type=int, default=None,
                        help="points per compiled call (default: sweep's own, at most 8,192)")
    parser.add_argument("--methods", default="rodas5a,rk4,ros2,pwm",
                        help="comma-separated subset of rodas5a, rk4, ros2, ros2a, pwm")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--check", type=int, default=4, help="points checked against a tight adaptive solve")
    parser.add_argument("--kernel", choices=("off", "on"), default="off",
                        help="on: a GPU's lanes as one Pallas kernel (PAMJAX_SWEEP_KERNEL=1; docs/performance.md)")
    args = parser.parse_args()
    import os

    os.environ["PAMJAX_SWEEP_KERNEL"] = "1" if args.kernel == "on" else "0"
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = sorted(set(methods) - {"rodas5a", "rk4", "ros2", "ros2a", "pwm"})
    if unknown or args.points < 1 or args.repeats < 1 or args.horizon <= 0:
        raise SystemExit(f"bad arguments: unknown methods {unknown}, or points/repeats < 1, or horizon <= 0")

    import jax

    jax.config.update("jax_enable_x64", True)
    import diffrax as dfx
    import jax.numpy as jnp

    import pamjax
    from pamjax import presets

    device = jax.devices()[0]
    print(f"jax {jax.__version__}, {device.platform}: {getattr(device, 'device_kind', '?')} x {len(jax.devices())}")
    duties = np.linspace(0.0, 1.0, args.points)
    ts = np.linspace(0.0, args.horizon, int(round(args.horizon * 10)) + 1)
    systems = {"averaged": presets.mas10_system(valve="averaged"), "pwm": presets.mas10_system(valve="pwm")}
    check = np.unique(np.linspace(0, args.points - 1, args.check + 2).astype(int)[1:-1])

    rates = {}
    for name in methods:
        valve, method = ("pwm", "rk4") if name == "pwm" else ("averaged", name)
        system = systems[valve]

        def call(system=system, method=method):
            return pamjax.sweep(system, pamjax.Constant(0.5), ts, {"signal.value": duties}, reduce=pamjax.FinalValue(),
                                channels=("pressure", "position"), method=method, chunk_size=args.chunk_size,
                                progress=False)

        start = time.perf_counter()
        result = call()
        first = time.perf_counter() - start
        times = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            result = call()
            times.append(time.perf_counter() - start)
        run = float(np.median(times))
        errors_p, errors_x = [], []
        for i in check:
            with jax.default_device(jax.devices("cpu")[0]):  # the reference on the host, whatever the device
                ref = pamjax.simulate(system, pamjax.Constant(float(duties[i])), jnp.asarray(ts[[0, -1]]),
                                      solver=dfx.Tsit5(), rtol=1e-10, atol=1e-10, max_steps=10**6)
            errors_p.append(abs(float(ref.pressure[-1]) - float(result["pressure"][i])))
            errors_x.append(abs(float(ref.position[-1]) - float(result["position"][i])))
        failed = int(np.sum(np.asarray(result.status) != 0))
        rates[name] = args.points / run
        step = "adaptive" if method in ("rodas5a", "ros2a") else f"{result.dt:.2e} s"
        print(f"  {valve:8s} {method:7s} step {step:10s}  compile {first - run:6.2f} s  run {run:8.3f} s  "
              f"{args.points / run:12,.0f} points/s  failed {failed}  vs tight solve: max|dp| {max(errors_p):.2e} Pa "
              f"max|dx| {max(errors_x):.2e} m ({len(check)} points)", flush=True)

    fields = " ".join(f"{('avg_' + k) if k != 'pwm' else 'pwm_rk4'}_pts_per_s={v:.0f}" for k, v in rates.items())
    print(f"RESULT platform={device.platform} points={args.points} horizon_s={args.horizon:g} kernel={args.kernel} "
          f"{fields}")


if __name__ == "__main__":
    main()
