"""Antagonistic joint control (issue 6 item 5): the ankle angle follows a 0.5 Hz gait-like reference through the
pressure difference while the joint stiffness is held, then steps, through the pressure sum (paper 001's future
work). Runs the closed loop and the feed-forward alone, prints RMSEs, writes a figure and a JSON.

    python fits/joint_control.py [--out results/joint_control] [--stiffness 160] [--step 145 165] [--overwrite]
"""

import argparse
import pathlib

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax import (  # noqa: E402
    AntagonisticJointController,
    GaitAngle,
    JointControlLoop,
    simulate_joint_control,
)
from pamjax.gallery import json_text, refuse_existing  # noqa: E402

WINDOW_START = 2.0  # s, the gait's RMSE window: after the first gait cycle (t >= 2 s)
STEP_TIME = 1.0  # s, the stiffness step; its error is read from 1 s after it (t >= 2 s)
OPEN_LOOP = dict(angle_proportional_gain=0.0, angle_integral_gain=0.0, sum_proportional_gain=0.0, sum_integral_gain=0.0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="results/joint_control")
    ap.add_argument("--stiffness", type=float, default=160.0, help="held stiffness in the gait run [N m/rad]")
    ap.add_argument("--step", type=float, nargs=2, default=[145.0, 165.0], help="stiffness step [N m/rad]")
    ap.add_argument("--frequency", type=float, default=0.5, help="gait frequency [Hz]")
    ap.add_argument("--overwrite", action="store_true", help="replace existing results in --out")
    ap.add_argument("--duration", type=float, default=6.0,
                    help=f"run length [s], above the RMSE window's start ({WINDOW_START} s)")
    args = ap.parse_args(argv)
    if not args.duration > WINDOW_START:  # the RMSE and the step's settled error are over t >= 2 s: an empty window
        ap.error(f"--duration must exceed the RMSE window's start {WINDOW_START} s (the gait's RMSE and the step's "
                 f"error are over t >= {WINDOW_START} s), got {args.duration}")
    out = pathlib.Path(args.out)
    refuse_existing("joint_control.py", [out / "joint_control.json", out / "joint_control.png"], args.overwrite)
    out.mkdir(parents=True, exist_ok=True)

    m = pj.presets.dmsp40_muscle()
    joint = pj.AntagonisticJoint(pj.ISO6358Regulator(), pj.ISO6358Regulator(), m, m)
    ts = jnp.linspace(0.0, args.duration, int(round(100 * args.duration)) + 1)
    start, step_time = WINDOW_START, STEP_TIME
    runs = {}
    for label, ctl in (
        ("closed loop", AntagonisticJointController()),
        ("feed-forward", AntagonisticJointController(**OPEN_LOOP)),
    ):
        k = args.stiffness
        gait = simulate_joint_control(JointControlLoop(joint, ctl, GaitAngle(args.frequency), pj.Step(k, k, 0.0)), ts)
        held = GaitAngle(args.frequency, offset=0.1, first=0.0, second=0.0)
        step = simulate_joint_control(JointControlLoop(joint, ctl, held, pj.Step(*args.step, step_time)), ts)
        angle_rmse, stiffness_rmse = (float(x) for x in gait.rmse(start))
        t = np.asarray(step.t)
        settle = t >= step_time + 1.0
        runs[label] = dict(
            gait=gait,
            step=step,
            summary=dict(
                gait_angle_rmse_rad=angle_rmse,
                gait_stiffness_rmse=stiffness_rmse,
                step_stiffness_error_after_1s=float(np.abs(np.asarray(step.stiffness) - args.step[1])[settle].max()),
                step_peak_angle_deviation_rad=float(np.abs(np.asarray(step.angle) - 0.1).max()),
            ),
        )
        s = runs[label]["summary"]
        print(
            f"{label:12s}: gait angle RMSE {angle_rmse:.4f} rad ({np.degrees(angle_rmse):.2f}°), stiffness RMSE "
            f"{stiffness_rmse:.3f} N m/rad; step {args.step[0]:.0f}→{args.step[1]:.0f}: |K − K_r| ≤ "
            f"{s['step_stiffness_error_after_1s']:.3f} N m/rad from 1 s after, peak angle deviation "
            f"{s['step_peak_angle_deviation_rad']:.4f} rad"
        )
    (out / "joint_control.json").write_text(json_text({k: v["summary"] for k, v in runs.items()}, indent=2))
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(2, 2, figsize=(11, 6), sharex=True)
        first = runs["closed loop"]
        ax[0, 0].plot(ts, np.degrees(first["gait"].angle_reference), "k--", label="reference")
        ax[1, 0].plot(ts, first["gait"].stiffness_reference, "k--", label="reference")
        ax[0, 1].plot(ts, np.degrees(first["step"].angle_reference), "k--", label="reference")
        ax[1, 1].plot(ts, first["step"].stiffness_reference, "k--", label="reference")
        for label, r in runs.items():
            ax[0, 0].plot(
                ts,
                np.degrees(r["gait"].angle),
                label=f"{label} ({np.degrees(r['summary']['gait_angle_rmse_rad']):.2f}° RMSE)",
            )
            ax[1, 0].plot(ts, r["gait"].stiffness, label=label)
            ax[0, 1].plot(ts, np.degrees(r["step"].angle), label=label)
            ax[1, 1].plot(ts, r["step"].stiffness, label=label)
        ax[0, 0].set_title(f"{args.frequency} Hz gait, stiffness held at {args.stiffness:.0f} N m/rad")
        ax[0, 1].set_title("angle held, stiffness step")
        ax[0, 0].set_ylabel("angle [°]")
        ax[1, 0].set_ylabel("K_θ = −∂τ/∂θ [N m/rad]")
        for a in ax.ravel():
            a.legend(fontsize=7)
        for a in ax[1]:
            a.set_xlabel("t [s]")
        fig.tight_layout()
        fig.savefig(out / "joint_control.png", dpi=110)
    except ImportError:
        pass
    best = runs["closed loop"]["summary"]["gait_angle_rmse_rad"]
    print(f"wrote {out}/joint_control.json")
    feedforward = runs["feed-forward"]["summary"]["gait_angle_rmse_rad"]
    print(f"RESULT angle_rmse_rad={best:.5f} feedforward_rmse_rad={feedforward:.5f}")


if __name__ == "__main__":
    main()
