"""Paper 000, Figs. 11-12 and the valve-test text: a 50 cm³ tank inflated from atmosphere and deflated from the
0.65 MPa supply at PWM duty 0.25/0.50/0.75 (50 Hz), the switching ("non-analytic", eq. 11) and averaged ("analytic",
eq. 13) valve models against the hybrid bench's recordings (E1, E2: exact switching, 2 kPa noise), the exhaust
silencer the paper blames for Fig. 12's offset (`presets.mas10_valve(silencer=True)`), the 2 ms switching time's
usable duty range, and Table 1 identified from the tank recordings (`fits/valve_tank.py`'s fit).
"""

import json

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np

import pamjax as pj
from pamjax import presets
from pamjax.gallery import Result, Row, bench_folder, plt, save
from pamjax.gallery.procedures.bench import tank_model

PAPER = "000"
TITLE = "Valve tests on a constant volume (Figs. 11-12), silencer, 10-90 % duty, Table 1 from tank tests"
COVERS = ("Fig. 11", "Fig. 12", "Table 1", "text: switching time 2 ms, usable duty 10-90 %",
          "text: exhaust silencer explains Fig. 12's offset")

DUTIES = (0.25, 0.50, 0.75)


def usable_duty_range(valve, air, pressure=3e5, tol=1e-9):
    """The duties between which the cycle-averaged flow at chamber `pressure` [Pa abs] depends on the duty (paper 000:
    10-90 % at 50 Hz with 2 ms switching): the ends of the flat parts at u = 0 and u = 1, by bisection."""
    flow_at = jax.jit(lambda d: pj.cycle_averaged_flow(valve, d, pressure, air))
    ends = float(flow_at(0.0)), float(flow_at(1.0))
    edges = []
    for end, (lo, hi) in zip(ends, ((0.0, 0.5), (1.0, 0.5))):  # lo stays flat, hi does not
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if abs(float(flow_at(mid)) - end) <= tol * abs(ends[1] - ends[0]) else (lo, mid)
        edges.append(0.5 * (lo + hi))
    u = np.asarray(jnp.linspace(0.0, 1.0, 201))
    # the curve by the bisection's compiled program, point by point (a vmapped one would be a second compilation)
    return edges[0], edges[1], u, np.array([float(flow_at(float(v))) for v in u])


def simulate_tank(system, duty, p0, ts, **kwargs):
    return np.asarray(pj.simulate(system, pj.Constant(duty), ts, y0=system.initial_state(p0), **kwargs).pressure)


def run(out, quick=False):
    air = pj.Air()
    lo, hi, u_grid, flow = usable_duty_range(presets.mas10_valve("exact"), air)
    bench = bench_folder()
    rows, numbers = [], dict(usable_duty=[lo, hi])
    pyplot = plt()
    fig, axes = pyplot.subplots(1, 3, figsize=(16, 4.3))
    P = json.loads((bench / "meta.json").read_text())["params"]
    switching = tank_model(P, P["Cv12"], P["b12"], P["Cv23"], P["b23"])
    silenced = pj.TankSystem(presets.mas10_valve("exact", silencer=True), 5e-5, air, polytropic_index=P["kappa"])
    averaged = presets.mas10_tank_system("averaged")
    results = {}
    for kind, p0, ax in (("E1", P["p_atm"], axes[0]), ("E2", P["p_s"], axes[1])):
        for k, u in enumerate(DUTIES):
            rec = np.load(bench / f"{kind}_u{u:.2f}.npz")
            ts = jnp.asarray(rec["t"][::10])  # 100 Hz of the 1 kHz record
            data = rec["p"][::10]
            sims = dict(switching=simulate_tank(switching, u, p0, ts, stepping="pwm"),
                        averaged=simulate_tank(averaged, u, p0, ts, solver=dfx.Tsit5()),
                        silenced=simulate_tank(silenced, u, p0, ts, stepping="pwm"))
            results[f"{kind}_u{u:.2f}"] = {
                **{f"{m}_rmse_kPa": float(np.sqrt(np.mean((s - data) ** 2)) / 1e3) for m, s in sims.items()},
                "final_bench_kPa": float(data[-1] / 1e3),
                **{f"final_{m}_kPa": float(s[-1] / 1e3) for m, s in sims.items()}}
            c = f"C{k}"
            ax.plot(rec["t"], rec["p"] / 1e5, ".", color=c, ms=0.5, alpha=0.4)
            ax.plot(ts, sims["switching"] / 1e5, "-", color=c, lw=1, label=f"u = {u:.2f}: switching")
            ax.plot(ts, sims["averaged"] / 1e5, "--", color=c, lw=1, label="averaged (eq. 13)" if k == 0 else None)
            ax.plot(ts, sims["silenced"] / 1e5, ":", color=c, lw=2, label="with silencer" if k == 0 else None)
        title = "Fig. 11: inflation" if kind == "E1" else "Fig. 12: deflation"
        ax.set(title=f"{title} (dots: bench recordings)", xlabel="t [s]", ylabel="tank pressure [bar abs]")
        ax.legend(fontsize=7)
    numbers["runs"] = results
    rmse = {m: max(r[f"{m}_rmse_kPa"] for r in results.values()) for m in ("switching", "averaged")}
    offset = {u: results[f"E2_u{u:.2f}"]["final_silenced_kPa"] - results[f"E2_u{u:.2f}"]["final_switching_kPa"]
              for u in DUTIES}
    offset_in = {u: results[f"E1_u{u:.2f}"]["final_silenced_kPa"] - results[f"E1_u{u:.2f}"]["final_switching_kPa"]
                 for u in DUTIES}
    by_test = {kind: {m: max(r[f"{m}_rmse_kPa"] for k, r in results.items() if k.startswith(kind))
                      for m in ("switching", "averaged")} for kind in ("E1", "E2")}
    numbers.update(max_rmse_kPa=rmse, max_rmse_kPa_inflation=by_test["E1"], max_rmse_kPa_deflation=by_test["E2"],
                   silencer_final_offset_deflation_kPa=offset,
                   silencer_final_offset_inflation_kPa=offset_in)

    fig_name = "valve_tests.png"
    rows += [
        Row("Figs. 11-12", "tank pressure, switching (eq. 11) and averaged (eq. 13) valves vs bench recordings",
            "switching: good inflation, deflation off (silencer); averaged: reasonable",
            f"max RMSE switching {rmse['switching']:.1f} kPa (noise 2 kPa), averaged {rmse['averaged']:.0f} kPa",
            figure=fig_name),
        Row("text: silencer", "deflation end pressure with the preset's silencer minus without (2 s)",
            "simulation drops faster: steady-state offset; negligible at high pressure",
            ", ".join(f"u {u:.2f}: +{offset[u]:.0f} kPa" for u in DUTIES)
            + f" (inflation: {', '.join(f'+{offset_in[u]:.0f}' for u in DUTIES)} kPa)", figure=fig_name),
    ]
    # Table 1 from the tank recordings (the paper's route to its Table 1), 2 s per run
    rate = 50.0 if quick else 250.0
    fit = numbers["table_1_from_tanks"] = tank_fit(bench, rate)
    rows.append(Row("Table 1 (tank route)", f"C_v, b_v fitted to the bench's E1/E2 recordings (2 s, {rate:.0f} Hz, "
                    "from 30 % off)", "C_v 0.36 / 0.39, b_v 0.28 / 0.49",
                    ", ".join(f"{k} {v['fitted']:.3f} ± {v['se']:.3f}" for k, v in fit.items())))
    axes[2].plot(u_grid, flow * 1e3, "k.-", ms=2)
    for edge in (lo, hi):
        axes[2].axvline(edge, color="C3", lw=0.8)
    axes[2].set(title=f"cycle-averaged flow at 3 bar abs: flat outside {lo:.2f}-{hi:.2f}", xlabel="duty u [-]",
                ylabel="mass flow [g/s]")
    fig_name = save(fig, out, "valve_tests.png")
    rows.append(Row("text: 2 ms switching", "duty range over which the averaged flow depends on the duty (50 Hz)",
                    "10-90 %", f"{100 * lo:.0f}-{100 * hi:.0f} %", figure=fig_name))
    return Result(rows, numbers, paper=dict(usable_duty=[0.1, 0.9], duties=DUTIES))


def tank_fit(bench, rate):
    """C_v, b_v of both paths from the bench's E1/E2 runs (`pamjax.bench.load_bench`, tank tests only) at `rate` [Hz],
    started 30 % off Table 1 (× 1.3 / 0.7 / 1.3 / 0.7), as `fits/valve_tank.py` does."""
    model = presets.mas10_system("pwm", friction="karnopp")
    keys = ["Cv12", "b12", "Cv23", "b23"]
    loaded = pj.bench.load_bench(bench, model, rate=rate, kinds=("tank_charge", "tank_discharge"), fitted_keys=keys)
    space = pj.ParameterSpace(model, loaded.free)
    start = space.with_values(np.asarray(space.initial_values()) * np.array([1.3, 0.7, 1.3, 0.7]))
    res = pj.fit(start, loaded.experiments, loaded.free, progress=False)
    values, errors = pj.bench.bench_values(res, keys)
    names = dict(Cv12="C_v(1→2)", b12="b_v(1→2)", Cv23="C_v(2→3)", b23="b_v(2→3)")
    return {names[k]: dict(fitted=values[k], se=errors[k]) for k in keys}


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
