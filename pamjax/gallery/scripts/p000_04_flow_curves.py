"""Paper 000, eq. 10-11, Table 1 and Fig. 7: C_v and b_v of both valve paths from ISO 6358 flow-rate curves.

ISO 6358-1's test, as the paper ran it: upstream pressure held at 0.5, 0.6 and 0.7 MPa abs, the downstream throttled
from atmosphere up towards the upstream pressure, the mass flow measured, per path (1→2 inflate, 2→3 exhaust).
The points are synthetic: eq. 11 with Table 1's values plus 1 % of the choked flow as flow-meter noise (assumed).
Eq. 11's C_v, b_v are fitted to both paths at once (`FlowCurveExperiment`, from 30 % off), and so is eq. 10's nozzle,
the law the paper found "does not correspond well" (one C_q per path, its critical ratio fixed at 0.528).
`EllipseRestriction` is checked against a NumPy transcription of eq. 11 as printed at Table 1's values.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import pamjax as pj
from pamjax import presets
from pamjax.gallery import Result, Row, plt, save

PAPER = "000"
TITLE = "Valve flow-rate curves per path, C_v and b_v (eq. 10-11, Table 1, Fig. 7)"
COVERS = ("eq. 10", "eq. 11", "Table 1", "Fig. 7")

UPSTREAM = (5e5, 6e5, 7e5)  # Pa abs, paper 000 Table 1
TABLE_1 = {"inflate.discharge_coefficient": 0.36, "inflate.critical_ratio": 0.28,
           "exhaust.discharge_coefficient": 0.39, "exhaust.critical_ratio": 0.49}  # paper 000, Table 1
NOISE = 0.01  # flow-meter noise, fraction of the choked flow (assumed)
AIR = pj.Air()


@eqx.filter_jit
def flow_curve(restriction, upstream_pressure, ratios, air):
    """`pamjax.bench.flow_curve` jitted: one program per restriction type and number of ratios. Run eagerly, each of its
    vmapped operations compiled a program of its own, anew for each curve (~140 in all)."""
    return pj.bench.flow_curve(restriction, upstream_pressure, ratios, air)


def curve(restriction, p_up, ratios):
    """`flow_curve` of `restriction` at `p_up` [Pa abs] (an array argument, not a constant of the program)."""
    return np.asarray(flow_curve(restriction, jnp.asarray(p_up, dtype=float), jnp.asarray(ratios, dtype=float), AIR))


def restriction_of(valve, path):
    """The valve's restriction on `path` ("inflate": 1→2, "exhaust": 2→3), as `FlowCurveExperiment` names it."""
    return {"inflate": valve.inflate, "exhaust": valve.exhaust}[path]


def flow_points(valve, n, rng):
    """ISO 6358 test points (p_up, p_down, ṁ + noise) per path of `valve`: `n` downstream pressures from atmosphere
    to 0.98 p_up."""
    data = {}
    for path in ("inflate", "exhaust"):
        restriction = restriction_of(valve, path)
        rows = []
        for p_up in UPSTREAM:
            ratios = np.linspace(float(AIR.atmospheric_pressure) / p_up, 0.98, n)
            flow = curve(restriction, p_up, ratios)
            flow = flow + NOISE * flow[0] * rng.standard_normal(flow.shape)
            rows.append(np.stack([np.full(ratios.shape, p_up), ratios * p_up, flow]))
        data[path] = np.concatenate(rows, axis=1)
    return data


def eq11_transcription(valve):
    """Max |pamjax − eq. 11 as printed| / choked flow over both paths, the three upstream pressures and
    p_down/p_up from 0 to the start of pamjax's laminar branch (0.999, ISO 6358-1), NumPy, Table 1's values."""
    r, t = float(AIR.gas_constant), float(AIR.temperature)
    worst = 0.0
    for path, (cv, b) in (("inflate", (0.36, 0.28)), ("exhaust", (0.39, 0.49))):
        for p_up in UPSTREAM:
            ratios = np.linspace(0.0, 0.999, 201)  # the figure's curves' size: the same compiled program
            choked = cv * 3.14e-6 * p_up / np.sqrt(r * t)  # eq. 11, sonic branch, A = 3.14e-6 m² (Table 1)
            printed = choked * np.sqrt(1 - np.clip((ratios - b) / (1 - b), 0.0, None) ** 2)
            error = np.max(np.abs(curve(restriction_of(valve, path), p_up, ratios) - printed))
            worst = max(worst, float(error) / choked)
    return worst


def run(out, quick=False):
    truth = presets.mas10_valve("exact")
    data = flow_points(truth, 12 if quick else 25, np.random.default_rng(0))
    sigma = {k: NOISE * float(np.max(v[2])) for k, v in data.items()}

    def experiments():
        return [pj.bench.FlowCurveExperiment(*data[k], scale=sigma[k], restriction=k, name=k) for k in data]

    space = pj.ParameterSpace(truth, list(TABLE_1))
    start = space.with_values(np.asarray(space.initial_values()) * np.array([1.3, 0.7, 1.3, 0.7]))
    res11 = pj.fit(start, experiments(), list(TABLE_1), progress=False)
    fitted = dict(zip(res11.labels, np.asarray(res11.values)))
    se = dict(zip(res11.labels, np.asarray(res11.standard_errors)))

    nozzle = presets.mas10_valve("exact", inflate=pj.NozzleRestriction(0.5), exhaust=pj.NozzleRestriction(0.5))
    res10 = pj.fit(nozzle, experiments(), ["inflate.flow_coefficient", "exhaust.flow_coefficient"], progress=False)
    err = {f"eq{n}_{k}_rmse_percent_of_choked": res.channel_errors[k]["mass_flow"]["rmse"] / (sigma[k] / NOISE) * 100
           for n, res in (("11", res11), ("10", res10)) for k in data}
    numbers = dict(fitted=fitted, standard_errors=se, table_1=TABLE_1, **err,
                   eq11_vs_transcription_max_relative=eq11_transcription(truth),
                   eq10_over_eq11_rmse=dict((k, err[f"eq10_{k}_rmse_percent_of_choked"]
                                             / err[f"eq11_{k}_rmse_percent_of_choked"]) for k in data),
                   eq10_flow_coefficients=dict(zip(res10.labels, np.asarray(res10.values))),
                   max_relative_error_percent=float(max(abs(fitted[k] / v - 1) for k, v in TABLE_1.items()) * 100))

    pyplot = plt()
    fig, axes = pyplot.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    rr = np.linspace(0.0, 1.0, 201)
    for ax, path in zip(axes, ("inflate", "exhaust")):
        p_up, p_down, flow = data[path]
        for k, pu in enumerate(UPSTREAM):
            sel = p_up == pu
            ax.plot(p_down[sel] / pu, flow[sel] * 1e3, "o", color=f"C{k}", ms=4, label=f"{pu / 1e6:.1f} MPa points")
            ax.plot(rr, curve(restriction_of(res11.model, path), pu, rr) * 1e3, "-", color=f"C{k}")
            ax.plot(rr, curve(restriction_of(res10.model, path), pu, rr) * 1e3, ":", color=f"C{k}")
        name = "1→2 (inflate)" if path == "inflate" else "2→3 (exhaust)"
        ax.set(title=f"Fig. 7, path {name}: eq. 11 (solid), eq. 10 (dotted)", xlabel="p_down / p_up [-]")
    axes[0].set_ylabel("mass flow [g/s]")
    axes[0].legend(fontsize=8)
    fig_name = save(fig, out, "flow_curves.png")

    names = {"inflate.discharge_coefficient": "C_v(1→2)", "inflate.critical_ratio": "b_v(1→2)",
             "exhaust.discharge_coefficient": "C_v(2→3)", "exhaust.critical_ratio": "b_v(2→3)"}
    table = ", ".join(f"{names[k]} {fitted[k]:.3f} ± {se[k]:.3f}" for k in TABLE_1)
    rows = [
        Row("Table 1, eq. 11, Fig. 7", "C_v, b_v of both paths fitted to ISO 6358 flow curves at 0.5/0.6/0.7 MPa",
            "C_v 0.36 / 0.39, b_v 0.28 / 0.49 (1→2 / 2→3)", table + " (started 30 % off)",
            figure=fig_name),
        Row("eq. 10", "isentropic nozzle (critical ratio 0.528) fitted to the same curves",
            "\"does not correspond well\"",
            f"RMSE {err['eq10_inflate_rmse_percent_of_choked']:.1f} % / "
            f"{err['eq10_exhaust_rmse_percent_of_choked']:.1f} % of the choked flow (eq. 11: "
            f"{err['eq11_inflate_rmse_percent_of_choked']:.1f} / "
            f"{err['eq11_exhaust_rmse_percent_of_choked']:.1f} %, the noise level)",
            figure=fig_name),
    ]
    return Result(rows, numbers, paper=dict(table_1=TABLE_1, upstream_pressures_Pa=UPSTREAM))


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
