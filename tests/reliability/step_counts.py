"""The benchmark experiments whose solver step counts are recorded in `step_counts.json` (a bound with a margin is
tested: counts can differ by a few steps between CPUs)."""

import jax.numpy as jnp

import pamjax
from pamjax import presets


def experiments():
    """name → zero-argument callable returning a Trajectory (benchmarks/simulate.py's experiments, plus tank tests)."""
    triangle = pamjax.Triangle(0.05, 0.95, 0.08)
    ts = jnp.linspace(0.0, 25.0, 2501)
    tank_ts = jnp.linspace(0.0, 2.0, 201)
    return {
        "triangle_0.08Hz_averaged": lambda: pamjax.simulate(presets.mas10_system("averaged"), triangle, ts),
        "triangle_0.08Hz_pwm_smooth": lambda: pamjax.simulate(presets.mas10_system("pwm"), triangle, ts),
        "triangle_0.08Hz_pwm_synchronous": lambda: pamjax.simulate(presets.mas10_system("pwm"), triangle, ts,
                                                                   stepping="pwm"),
        "tank_inflate_0.25_pwm_smooth": lambda: pamjax.simulate(presets.mas10_tank_system("pwm"),
                                                                pamjax.Constant(0.25), tank_ts),
        "tank_deflate_0.75_averaged": lambda: pamjax.simulate(
            presets.mas10_tank_system("averaged"), pamjax.Constant(0.75), tank_ts,
            y0=pamjax.TankState(jnp.asarray(presets.SUPPLY_PRESSURE))),
    }


def measure():
    out = {}
    for name, run in experiments().items():
        traj = run()
        out[name] = dict(steps=int(traj.num_steps), accepted=int(traj.num_accepted_steps),
                         rejected=int(traj.num_rejected_steps))
    return out


if __name__ == "__main__":
    import json
    import pathlib
    import sys

    import jax

    jax.config.update("jax_enable_x64", True)
    counts = measure()
    print(json.dumps(counts, indent=1))
    if "--write" in sys.argv:
        (pathlib.Path(__file__).parent / "step_counts.json").write_text(json.dumps(counts, indent=1) + "\n")
