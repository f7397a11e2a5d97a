"""Paper 001, eq. 1-2, 12-14, Tables 1-2 and Figs. 13-14: the VPPM's sonic conductance C and critical ratio b from
charging and discharging the 0.04 m³ tank, and the modelled flow-rate curves.

Tables 1-2 by the appendix's procedure (`fits/regulator.py`): each row's tank run simulated with that row's C, b
(`ISO6358Regulator`, main stage fully open), 2 mbar noise, C and b fitted back (start values read off the record as the
paper does, then Levenberg-Marquardt). `--quick` takes the 6.943 bar charging and 3.97 bar discharging rows and stops
after the read-off: C from the choked slope (eq. 14), b by least squares over a 0.005 grid at that C (`read_off`).
Figs. 13-14: the ISO 6358 flow per row against the tank pressure, in the standard ratio form of eq. 13 and as eq. 1 is
printed (b subtracted from the pressures in bar), which jumps where it switches to eq. 2; `ISO6358Restriction` is
checked against eq. 13-14 in NumPy, and Table 2's spread is measured against the appendix's sentence that its C and b
"have the same values for the different analysed supply pressures".
"""

import functools

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np

import pamjax as pj
from pamjax import presets
from pamjax.gallery import Result, Row, plt, save
from pamjax.gallery.procedures import regulator
from pamjax.units import BAR, ISO8778_DENSITY, ISO8778_TEMPERATURE

PAPER001_AIR = presets.paper001_air()  # R = 286.9 J/(kg K), T = 298 K

PAPER = "001"
TITLE = "Sonic conductance and critical ratio from tank tests (Tables 1-2, eq. 1-2, 12-14, Figs. 13-14)"
COVERS = ("eq. 1", "eq. 2", "eq. 12", "eq. 13", "eq. 14", "Table 1", "Table 2", "Fig. 13", "Fig. 14",
          "text: discharging C and b do not depend on the pressure")

QUICK_ROWS = {"charging": [5], "discharging": [2]}  # 6.943 bar (the regulator's supply), 3.97 bar
NOISE = 200.0  # Pa, 2 mbar (fits/regulator.py)


def eq1_as_printed(c, b, p_in, p_out):
    """Paper 001 eq. 1-2 as printed [m³/s]: C p_in √(1 − ((p_out − b)/(p_in − b))²) above b, C p_in below; pressures
    in bar, C in m³/(s bar)."""
    z = np.clip((p_out - b) / (p_in - b), 0.0, 1.0)
    return np.where(p_out / p_in > b, c * p_in * np.sqrt(1 - z**2), c * p_in)


def eq13(c, b, p_in, p_out):
    """The ISO 6358 ratio form (eq. 13-14) [m³/s], C in m³/(s bar), pressures in bar (T_in = T_out)."""
    z = np.clip((p_out / p_in - b) / (1 - b), 0.0, 1.0)
    return c * p_in * np.sqrt(1 - z**2)


def curves(table, pcol, mode, n=200):
    """Flow [l/min ANR] against the tank pressure [bar abs] per row, eq. 13 and eq. 1 as printed (charging: upstream
    = the row's pressure, tank from 1 atm up; discharging: tank from the row's pressure down to 1 atm)."""
    p_atm = float(PAPER001_AIR.atmospheric_pressure) / BAR
    out = []
    for p_row, b, c in zip(table[pcol], table["critical_ratio"], table["sonic_conductance_m3_per_s_bar"]):
        tank = np.linspace(p_atm, p_row, n)
        if mode == "charge":
            args = (np.full(n, p_row), tank)
        else:
            args = (tank, np.full(n, p_atm))
        # C is defined at ISO 8778 reference conditions: C p is a volumetric flow ANR [m³/s] → l/min
        out.append((tank, 6e4 * eq13(c, b, *args), 6e4 * eq1_as_printed(c, b, *args), p_row))
    return out


def mode_values(reg, mode, p_row):
    """`fits/regulator.tank_run`'s constants of a `mode` at row pressure `p_row` [Pa]: (supply, pilot target, start
    pressure [Pa], voltage [V]), as arrays, so that charging and discharging runs are one program."""
    if mode == "charge":
        values = (p_row, reg.P_ATM + 10.1 * BAR, reg.P_ATM, 10.0)
    else:
        values = (7e5, reg.P_ATM, p_row, 0.0)
    return tuple(jnp.asarray(v, dtype=float) for v in values)


def tank_pressure(reg, theta, values, ts):
    """`fits/regulator.tank_run(theta, mode, p_row, ts, solver=Tsit5())` with the mode's constants (`mode_values`)
    as arguments: the same system, start state, command and solve."""
    supply, target, p0, volts = values
    system = reg.tank_system(jnp.exp(theta[0]), reg.to_b(theta[1]), supply)
    y0 = pj.ISO6358RegulatorState(pilot=target, pilot_output=target, pressure=p0)
    return pj.simulate(system, pj.Constant(volts), ts, y0=y0, adjoint="forward", rtol=1e-8, atol=1e-8,
                       solver=dfx.Tsit5()).pressure


def grid_costs(reg, rows):
    """Per read-off row (`start`: ts, data, C, mode values), the squared misfit of the tank run at each b of the
    0.005 grid at that row's C: ONE vmapped batch of every row's runs (rows × b values, Tsit5), so that the quick
    run compiles one program instead of one per row (whose pressure and mode were constants of its program)."""
    grid = np.arange(0.3, 0.8975, 0.005)  # inside fits/regulator.py's b range (0.1, 0.9)
    runs = np.asarray(_grid_runs(reg, jnp.log(jnp.asarray([r["c0"] for r in rows])),  # stacked in NumPy: no programs
                                 tuple(jnp.asarray(np.stack(v)) for v in zip(*(r["values"] for r in rows))),
                                 jnp.asarray(np.stack([r["ts"] for r in rows])), jnp.asarray(reg.from_b(grid))))
    return grid, [np.sum((run - r["data"]) ** 2, axis=1) for run, r in zip(runs, rows)]


@functools.partial(jax.jit, static_argnums=0)
def _grid_runs(reg, log_c0, values, ts, zs):
    """Tank pressures (rows, b values, samples) of `tank_pressure` at θ = (log C of the row, z) for each z."""

    def one_row(log_c, vals, times):
        return jax.vmap(lambda z: tank_pressure(reg, jnp.stack([log_c, z]), vals, times))(zs)

    return jax.vmap(one_row)(log_c0, values, ts)


def start(reg, mode, p_row, c_true, b_true, rng):
    """One row's tank run (150 samples, 2 mbar noise) and C [m³/(s Pa)] read off the choked slope over its first
    tenth (eq. 14: ṗ = k p_in charging, d ln p/dt = −k discharging)."""
    ts = jnp.linspace(0.0, reg.tank_horizon(mode, p_row * BAR, c_true / BAR, b_true), 150)
    truth = jnp.array([np.log(c_true / BAR), reg.from_b(b_true)])
    data = np.asarray(reg.tank_run(truth, mode, p_row * BAR, ts, solver=dfx.Tsit5()))
    data = data + NOISE * rng.standard_normal(data.shape)
    t, n = np.asarray(ts), ts.size // 10
    y = data[:n] / (p_row * BAR) if mode == "charge" else -np.log(data[:n])
    c0 = float(np.polyfit(t[:n], y, 1)[0] / reg.tank_rate_constant(1.0))  # m³/(s Pa)
    return dict(ts=ts, data=data, c0=c0, values=mode_values(reg, mode, p_row * BAR), pressure_bar=p_row,
                C_table=c_true, b_table=b_true)


def read_off(grid, row):
    """b by least squares over the 0.005 grid at the read-off C (the row's `cost` from `grid_costs`): a parabola
    through the three lowest. Returns a `fits/regulator.fit_tables`-like row."""
    c0, c_true, b_true, cost = row["c0"], row["C_table"], row["b_table"], row["cost"]
    k = int(np.clip(np.argmin(cost), 1, grid.size - 2))
    a, b_, c_ = cost[k - 1: k + 2]
    b0 = float(grid[k] + 0.0025 * (a - c_) / (a - 2 * b_ + c_))  # parabola through the three lowest
    return dict(pressure_bar=row["pressure_bar"], C_table=c_true, b_table=b_true, C_fit=c0 * BAR, b_fit=b0,
                C_error_percent=100 * (c0 * BAR / c_true - 1), b_error=b0 - b_true)


def quick_tables(reg, rng):
    """The quick rows read off the record: every row's run and C first (in the order of the noise draws), then b
    for all rows in one batch (`grid_costs`)."""
    starts = {}
    for key, mode, table, pcol in (("charging", "charge", presets.PAPER001_CHARGING_TABLE, "upstream_pressure_bar"),
                                   ("discharging", "discharge", presets.PAPER001_DISCHARGING_TABLE,
                                    "tank_pressure_bar")):
        starts[key] = [start(reg, mode, table[pcol][i], table["sonic_conductance_m3_per_s_bar"][i],
                             table["critical_ratio"][i], rng) for i in QUICK_ROWS[key]]
    rows = [r for key in starts for r in starts[key]]
    grid, costs = grid_costs(reg, rows)
    for r, cost in zip(rows, costs):
        r["cost"] = cost
    return {key: [read_off(grid, r) for r in starts[key]] for key in starts}


@jax.jit
def _iso6358_flows(c, b, p_in, p_out):
    return jax.vmap(lambda *a: pj.ISO6358Restriction(a[0], a[1]).mass_flow(a[2], a[3], PAPER001_AIR))(
        c, b, p_in, p_out)


def eq13_against_pamjax():
    """Max |`ISO6358Restriction` − ρ₀ × eq. 13-14 (NumPy)| / choked flow over Table 1's rows, tank pressure from 1 atm
    to just below the laminar branch (0.999 of the supply, ISO 6358-1)."""
    table = presets.PAPER001_CHARGING_TABLE
    heat = np.sqrt(ISO8778_TEMPERATURE / float(PAPER001_AIR.temperature))  # sqrt(T0/T_in) of eq. 13
    rows = []
    for p_row, b, c in zip(table["upstream_pressure_bar"], table["critical_ratio"],
                           table["sonic_conductance_m3_per_s_bar"]):
        tank = np.linspace(1.01325, 0.999 * p_row, 200)
        rows.append((np.full(tank.shape, c / BAR), np.full(tank.shape, b), np.full(tank.shape, p_row * BAR),
                     tank * BAR, ISO8778_DENSITY * eq13(c, b, p_row, tank) * heat, ISO8778_DENSITY * c * p_row))
    c, b, p_in, p_out, printed, choked = (np.concatenate([np.broadcast_to(r[k], r[0].shape) for r in rows])
                                          for k in range(6))
    ours = np.asarray(_iso6358_flows(*(jnp.asarray(a) for a in (c, b, p_in, p_out))))
    return float(np.max(np.abs(ours - printed) / choked))


def table_spread(table):
    """(max − min) / mean of a table's b and C columns."""
    out = {}
    for key in ("critical_ratio", "sonic_conductance_m3_per_s_bar"):
        col = np.asarray(table[key], dtype=float)
        out[key] = float(np.ptp(col) / np.mean(col))
    return out


def run(out, quick=False):
    reg = regulator
    rng = np.random.default_rng(0)
    report = quick_tables(reg, rng) if quick else reg.fit_tables(rng, quick)
    fitted = report["charging"] + report["discharging"]
    max_c = max(abs(r["C_error_percent"]) for r in fitted)
    max_b = max(abs(r["b_error"]) for r in fitted)
    charge = curves(presets.PAPER001_CHARGING_TABLE, "upstream_pressure_bar", "charge")
    discharge = curves(presets.PAPER001_DISCHARGING_TABLE, "tank_pressure_bar", "discharge")
    jumps = []
    for c_row in charge + discharge:
        tank, q13, q1, _ = c_row
        jumps.append(float(np.max(np.abs(np.diff(q1))) / np.max(q13)))
    choked = [float(np.max(c_row[1])) for c_row in charge]
    numbers = dict(rows=report, max_C_error_percent=max_c, max_b_error=max_b,
                   eq1_printed_max_jump_fraction=max(jumps), charging_choked_flow_l_per_min_anr=choked,
                   charging_choked_flow_min_step_ratio=min(b / a for a, b in zip(choked, choked[1:])),
                   eq13_vs_pamjax_max_relative=eq13_against_pamjax(),
                   table_2_spread=table_spread(presets.PAPER001_DISCHARGING_TABLE))

    pyplot = plt()
    fig, axes = pyplot.subplots(1, 2, figsize=(11, 4.2))
    for ax, rows_, title in ((axes[0], charge, "Fig. 13: charging (supply = row pressure)"),
                             (axes[1], discharge, "Fig. 14: discharging to atmosphere")):
        for k, (tank, q13, q1, p_row) in enumerate(rows_):
            ax.plot(tank, q13, "-", color=f"C{k}", label=f"{p_row:.2f} bar")
            ax.plot(tank, q1, ":", color=f"C{k}")
        ax.set(title=title + "\nsolid: eq. 13-14, dotted: eq. 1 as printed", xlabel="tank pressure [bar abs]",
               ylabel="flow [l/min ANR]")
        ax.legend(fontsize=7)
    fig_name = save(fig, out, "flow_curves.png")
    n_rows = f"{len(report['charging'])} + {len(report['discharging'])} rows (charging + discharging)"
    how = "read off the record (choked slope, b by a grid scan)" if quick else "read off, then Levenberg-Marquardt"
    rows = [
        Row("Tables 1-2, eq. 12-14", f"C and b from simulated tank runs ({n_rows}, 2 mbar noise), {how}",
            "C 1.67e-4…7.89e-4 m³/(s bar), b 0.53-0.75 (12 rows)",
            f"C within {max_c:.3f} %, b within {max_b:.4f} of each row",
            figure=fig_name),
        Row("eq. 1-2 vs eq. 13-14", "eq. 1 as printed (b subtracted from pressures) at the choke point",
            "eq. 1 and eq. 13 given as the same law", f"eq. 1 jumps by up to {100 * max(jumps):.0f} % of the choked "
            "flow where it switches to eq. 2; eq. 13 is continuous", figure=fig_name),
        Row("Figs. 13-14", "modelled flow curves per row (choked flow while charging)", "curves only",
            f"choked {min(choked):.0f}-{max(choked):.0f} l/min ANR over Table 1's rows", figure=fig_name),
    ]
    return Result(rows, numbers, paper=dict(table_1=presets.PAPER001_CHARGING_TABLE,
                                            table_2=presets.PAPER001_DISCHARGING_TABLE))


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
