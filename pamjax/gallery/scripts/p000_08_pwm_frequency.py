"""Paper 000's text on the PWM frequency: "the amplitude of chattering in the actuator pressure is approximately
15 kPa" (50 Hz), "25 Hz resulted in an unacceptably large amount of chattering into the actuator displacement", "an
even smoother trajectory was gained with 100 Hz; the drawback … is the poor resolution of the input signal; even if
an 0.1 ms sampling time is used".

The bench plant (its true parameters, exact stick-slip, 2 ms switching delays) runs the 0.25 Hz triangle duty
0.05-0.95 at 25, 50 and 100 Hz on the PWM-synchronous grid, sampled at 2 kHz. Ripple = the peak-to-peak of pressure
and displacement within each PWM period once their slow part (the motion along the triangle: the average over one
PWM period) is taken out, median (and 90th percentile) over the run after the first second. Resolution: with a 0.1 ms
sampling time a period of T holds T / 0.1 ms duty steps, of which the 2 ms switching delays leave (T − 4 ms) / 0.1 ms
usable.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import pamjax as pj
from pamjax import KarnoppFriction
from pamjax.gallery import Result, Row, plt, save
from pamjax.gallery.procedures.bench import bench_plant

PAPER = "000"
TITLE = "PWM frequency: pressure ripple, chattering at 25 Hz, resolution at 100 Hz (text)"
COVERS = ("text: pressure ripple ≈ 15 kPa", "text: 25 Hz PWM chatters, 100 Hz is smoother",
          "text: 100 Hz PWM gives a poor duty resolution at 0.1 ms sampling")

FREQUENCIES = (25.0, 50.0, 100.0)  # Hz, paper 000
SAMPLE_TIME = 1e-4  # s, paper 000's controller sampling ("0.1 ms")
OUTPUT_RATE = 2000.0  # Hz


def plant(frequency):
    bench = bench_plant()
    f = bench.friction
    bench = eqx.tree_at(lambda s: s.friction, bench, KarnoppFriction(f.coulomb_force, f.viscous_coefficient))
    return eqx.tree_at(lambda s: s.valve.pwm_frequency, bench, jnp.asarray(frequency))


@eqx.filter_jit
def solve_pwm(system, signal, ts, t0, num_periods):
    """`pamjax.unchecked.solve` on the PWM-synchronous grid of `num_periods` periods (static): the frequency is an array
    leaf of `system`, so the three frequencies share this one compiled program when they are given the same grid size.
    A grid longer than [t0, ts[-1]] needs adds only zero-length intervals, which the fixed-grid integrator skips
    exactly (`pamjax.unchecked.solve`), so every frequency's trajectory is the one `simulate` sizes for it."""
    return pj.unchecked.solve(system, signal, ts, None, t0, stepping="pwm", num_periods=num_periods)


def simulate_pwm(system, signal, ts, num_periods):
    """`solve_pwm` from ts[0], raising as `simulate` does on a failed (non-finite) solve."""
    traj = solve_pwm(system, signal, jnp.asarray(ts), jnp.asarray(float(ts[0])), num_periods)
    if int(traj.result) != 0:
        raise pj.PamjaxSolveError(f"the PWM-synchronous solve failed (result code {int(traj.result)})")
    return traj


def ripple(t, y, frequency, start=1.0):
    """Peak-to-peak within each whole PWM period after `start` [s] of `y` less its slow part: (median, 90th
    percentile). The slow part is `y` averaged over one PWM period centred on each sample, which is exactly the trend
    for a periodic ripple on a straight line whatever the ripple's shape (a line fitted within each period would take
    a share of a lopsided sawtooth for trend). Without it the slow motion along the 0.25 Hz triangle, up to ~0.7 mm in
    one 25 Hz period, counts as ripple: a smooth ramp's would grow with the period (twice at 25 Hz what it is at
    50 Hz) and pass the 25 / 50 / 100 Hz comparison with no chattering at all. `t`: uniform, a whole number of samples
    per period."""
    t, y = np.asarray(t, float), np.asarray(y, float)
    n = int(round(1.0 / (frequency * (t[1] - t[0]))))  # samples per period: 80 / 40 / 20 at 25 / 50 / 100 Hz, 2 kHz
    # one period centred on each sample: n samples (n odd), or n + 1 with half weights at both ends (n even)
    kernel = np.ones(n) / n if n % 2 else np.r_[0.5, np.ones(n - 1), 0.5] / n
    half = len(kernel) // 2
    fast = y - np.convolve(y, kernel, mode="same")
    fast[:half], fast[len(fast) - half:] = np.nan, np.nan  # where the window runs off the record
    period = np.floor(t * frequency + 1e-9).astype(int)
    keep = t >= start
    spans = []
    for k in np.unique(period[keep]):
        within = fast[keep & (period == k)]
        if within.size == n and np.all(np.isfinite(within)):  # whole periods only
            spans.append(np.ptp(within))
    return float(np.median(spans)), float(np.percentile(spans, 90))


def run(out, quick=False):
    horizon = 4.0 if quick else 8.0
    ts = np.arange(0.0, horizon + 1e-9, 1.0 / OUTPUT_RATE)
    pyplot = plt()
    fig, (ax0, ax1) = pyplot.subplots(2, 1, figsize=(10, 6), sharex=True)
    numbers = {}
    plants = {f: plant(f) for f in FREQUENCIES}
    # one grid size for all frequencies (the finest's): one compiled solve instead of one per frequency
    periods = max(pj.unchecked.num_periods(p.valve, ts[0], ts[-1]) for p in plants.values())
    for k, f in enumerate(FREQUENCIES):
        traj = simulate_pwm(plants[f], pj.Triangle(0.05, 0.95, 0.25), ts, periods)
        p, x = np.asarray(traj.pressure), np.asarray(traj.position)
        period = 1.0 / f
        numbers[f"{f:.0f}Hz"] = dict(
            pressure_ripple_kPa=[v / 1e3 for v in ripple(ts, p, f)],
            position_ripple_mm=[v * 1e3 for v in ripple(ts, x, f)],
            duty_steps_per_period=period / SAMPLE_TIME,
            usable_duty=[2e-3 / period, 1 - 2e-3 / period],
            usable_duty_steps=(period - 4e-3) / SAMPLE_TIME,
        )
        window = (ts > 2.0) & (ts < 2.4)
        ax0.plot(ts[window], p[window] / 1e5, color=f"C{k}", lw=1, label=f"{f:.0f} Hz")
        ax1.plot(ts[window], x[window] * 1e3, color=f"C{k}", lw=1)
    ax0.set(ylabel="pressure [bar abs]", title="0.25 Hz triangle duty, bench plant, PWM at 25 / 50 / 100 Hz")
    ax1.set(ylabel="displacement [mm]", xlabel="t [s]")
    ax0.legend(fontsize=8)
    fig_name = save(fig, out, "pwm_frequency.png")
    n = numbers
    numbers["50Hz"]["pressure_amplitude_kPa"] = n["50Hz"]["pressure_ripple_kPa"][0] / 2  # ½ peak-to-peak, median
    numbers["position_ripple_ratio"] = {
        f"{k}_to_50Hz": n[k]["position_ripple_mm"][0] / n["50Hz"]["position_ripple_mm"][0] for k in ("25Hz", "100Hz")}
    rows = [
        Row("text: pressure ripple", "pressure chattering amplitude (½ peak-to-peak within a PWM period, about the "
            "one-period average) at 50 Hz",
            "≈ 15 kPa", f"{n['50Hz']['pressure_ripple_kPa'][0] / 2:.0f} kPa median, "
            f"{n['50Hz']['pressure_ripple_kPa'][1] / 2:.0f} kPa 90th percentile", figure=fig_name),
        Row("text: 25 / 100 Hz", "displacement ripple per period at 25 / 50 / 100 Hz (median)",
            "25 Hz unacceptable chattering; 100 Hz smoother",
            " / ".join(f"{n[k]['position_ripple_mm'][0] * 1e3:.0f}" for k in ("25Hz", "50Hz", "100Hz")) + " µm "
            "(pressure " + " / ".join(f"{n[k]['pressure_ripple_kPa'][0]:.0f}" for k in ("25Hz", "50Hz", "100Hz"))
            + " kPa)", figure=fig_name),
        Row("text: 100 Hz resolution", "usable duty steps per period at 0.1 ms sampling, 2 ms switching",
            "\"poor resolution … even if an 0.1 ms sampling time is used\"",
            " / ".join(f"{n[k]['usable_duty_steps']:.0f}" for k in ("25Hz", "50Hz", "100Hz"))
            + " steps, usable duty " + " / ".join(f"{100 * n[k]['usable_duty'][0]:.0f}-"
                                                 f"{100 * n[k]['usable_duty'][1]:.0f} %" for k in ("25Hz", "50Hz",
                                                                                                  "100Hz"))),
    ]
    return Result(rows, numbers, paper=dict(pressure_ripple_kPa=15.0, frequencies_Hz=FREQUENCIES,
                                            sample_time_s=SAMPLE_TIME))


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
