"""Paper 000, eq. 17-21: the discrete-time state-space model (Euler at the sample time T_s, state [p, x, ẋ, ẍ]).

`pamjax.simulate_discrete` steps the averaged-valve MAS-10 preset (eq. 13, as the paper's eq. 18 uses it) at the
paper's T_s = 0.1 ms and at 0.5 ms, under the 0.25 Hz triangle duty 0.05-0.95, and is compared with the continuous
model (`simulate`, Tsit5 at rtol 1e-8): eq. 18-21 are a first-order discretisation of eq. 15-16. Over the first
second at 0.1 ms, its states are checked against eq. 18-21 as printed, stepped in NumPy with the same commands (their
right-hand sides are eq. 7, 13, 15 and 16; absolute pressure in the state, so eq. 20's P_max − x1 reads
p_max − (x1 − p_atm); sign(ẋ) as the preset's tanh(ẋ / 1 mm/s); no end stop is reached).
"""

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
import numpy as np

import pamjax as pj
from pamjax import presets
from pamjax.gallery import Result, Row, plt, save

PAPER = "000"
TITLE = "Discrete-time state-space model (eq. 17-21)"
COVERS = ("eq. 15", "eq. 16", "eq. 17", "eq. 18", "eq. 19", "eq. 20", "eq. 21")

SAMPLE_TIMES = (1e-4, 5e-4)  # s: the paper's 0.1 ms, and 5× coarser


@eqx.filter_jit
def initial_state(system):
    """`system.initial_state()` (the payload's equilibrium) as one jitted program: `simulate_discrete` computes its
    default start state eagerly, ~30 operations each compiled on its own."""
    return system.initial_state()


def printed_steps(system, commands, y0, sample_time, steps):
    """Eq. 18-21 as printed, stepped in NumPy from `y0` with the commands u_k: positions, pressures, velocities,
    accelerations (k = 0 … steps)."""
    m = np.asarray(system.valve.coefficients)  # eq. 13: m1…m9 row-wise over (u power, p_gauge power)
    law, vol, fr, air = system.muscle.force_law, system.muscle.volume_law, system.friction, system.air
    a = np.asarray(law.max_force_coefficients)
    k0, k1, k2, p_max = (float(v) for v in (law.k0, law.k1, law.k2, law.max_pressure))
    v0, v1, mass, g = float(vol.v0), float(vol.v1), float(system.payload_mass), float(system.gravity)
    kappa, rt, p_atm = float(system.polytropic_index), float(air.gas_constant * air.temperature), float(
        air.atmospheric_pressure)
    fc, cf, width = float(fr.coulomb_force), float(fr.viscous_coefficient), float(fr.velocity_width)
    x1, x2, x3 = float(y0.pressure), float(y0.position), float(y0.velocity)
    out = [(x1, x2, x3, 0.0)]
    for k in range(steps):
        u, pg = float(commands[k]), x1 - p_atm
        mdot = np.array([1, u, u * u]) @ m @ np.array([1, pg, pg * pg])  # eq. 13
        x1n = kappa * sample_time / (v0 + v1 * x2) * (rt * mdot - x1 * v1 * x3) + x1  # eq. 18
        f_max = sum(a[i] * x2**i for i in range(5))
        x3n = sample_time / mass * (f_max - (p_max - pg) * (k0 - k1 * x2) / k2 - fc * np.tanh(x3 / width) - cf * x3
                                    - mass * g) + x3  # eq. 20
        x2n = sample_time * x3n + x2  # eq. 19
        out.append((x1n, x2n, x3n, (x3n - x3) / sample_time))  # eq. 21
        x1, x2, x3 = x1n, x2n, x3n
    return np.array(out)


def run(out, quick=False):
    horizon = 4.0 if quick else 8.0
    system = presets.mas10_system("averaged")
    signal = pj.Triangle(0.05, 0.95, 0.25)
    numbers = {}
    pyplot = plt()
    fig, (ax0, ax1) = pyplot.subplots(2, 1, figsize=(9, 6), sharex=True)
    y0 = initial_state(system)
    for k, ts_ in enumerate(SAMPLE_TIMES):
        d = pj.simulate_discrete(system, signal, ts_, horizon, y0=y0)
        t = np.asarray(d.t)[::max(1, int(round(1e-2 / ts_)))]  # compare every 10 ms
        ref = pj.simulate(system, signal, jnp.asarray(t), rtol=1e-8, atol=1e-8, solver=dfx.Tsit5(), max_steps=10**6)
        x_d = np.asarray(d.position)[::max(1, int(round(1e-2 / ts_)))]
        p_d = np.asarray(d.pressure)[::max(1, int(round(1e-2 / ts_)))]
        numbers[f"{ts_ * 1e3:g}ms"] = dict(
            max_position_difference_mm=float(1e3 * np.max(np.abs(x_d - np.asarray(ref.position)))),
            max_pressure_difference_kPa=float(np.max(np.abs(p_d - np.asarray(ref.pressure))) / 1e3),
            steps=int(np.asarray(d.t).size - 1))
        if k == 0:
            fine = d  # the paper's T_s: checked against eq. 18-21 as printed below
            ax0.plot(t, np.asarray(ref.position) * 1e3, "k-", lw=2, label="continuous (eq. 15-16)")
            acc = np.asarray(d.acceleration)
        ax0.plot(t, x_d * 1e3, "--", color=f"C{k}", label=f"discrete, T_s = {ts_ * 1e3:g} ms")
        ax1.plot(t, (x_d - np.asarray(ref.position)) * 1e6, color=f"C{k}")
    ax0.set(ylabel="x [mm]", title="eq. 18-21 against the continuous model, averaged valve")
    ax0.legend(fontsize=8)
    ax1.set(xlabel="t [s]", ylabel="discrete − continuous [µm]")
    fig_name = save(fig, out, "discrete.png")
    numbers["max_abs_acceleration_eq21"] = float(np.max(np.abs(acc)))
    steps = int(round(1.0 / SAMPLE_TIMES[0]))  # the first second
    printed = printed_steps(system, np.asarray(fine.command), y0, SAMPLE_TIMES[0], steps)
    ours = np.stack([np.asarray(v)[: steps + 1] for v in (fine.pressure, fine.position, fine.velocity,
                                                            fine.acceleration)], axis=1)
    numbers["eq18_21_vs_printed_max_relative"] = float(np.max(np.abs(ours - printed) / np.ptp(printed, axis=0)))
    numbers["error_ratio_0.5ms_to_0.1ms"] = numbers["0.5ms"]["max_position_difference_mm"] / numbers["0.1ms"][
        "max_position_difference_mm"]
    a, b = (numbers[f"{t * 1e3:g}ms"]["max_position_difference_mm"] for t in SAMPLE_TIMES)
    rows = [Row("eq. 17-21", "Euler discretisation (state p, x, ẋ, ẍ) vs the continuous model, max |Δx|",
                "used for control and estimation; no numbers",
                f"{a * 1e3:.1f} µm at T_s = 0.1 ms, {b * 1e3:.1f} µm at 0.5 ms (ratio {b / a:.1f}; first order: 5)",
                figure=fig_name)]
    return Result(rows, numbers, paper=dict(sample_time_s=1e-4))


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
