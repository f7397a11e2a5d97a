"""Paper 000, Fig. 12 and its silencer: the exhaust silencer identified from deflation runs instead of assumed.

Paper 000 blames the offset of its deflation tests (Fig. 12) on a silencer on port 3 and gives no data for it:
"the effects of the silencer at higher upstream pressure levels are almost negligible", and "as the pressure drop
across the valve decreases the silencer slows down the flow". pamjax's preset silencer (`presets.mas10_silencer()`,
a porous element ṁ = K (p1² − p2²) in series with the exhaust port) has K from an ASSUMED reading of the first
sentence (98 % of the unsilenced flow at 0.65 MPa). Here K is identified from deflation recordings instead:

- synthetic recordings: the 50 cm³ tank of the valve tests discharged from the 0.65 MPa supply through the exact
  switching valve (2 ms delays, 50 Hz, Table 1 paths) with a silencer K = 1.5e-14 kg/(s Pa²) (chosen: three
  quarters of the preset's, a silencer that throttles more, still ~5 % at 0.65 MPa), at duty 0 (valve off: the
  exhaust path alone, a plain tank discharge) and at Fig. 12's 0.25/0.50/0.75, 2 s at 100 Hz with the bench's
  2 kPa pressure noise;
- K fitted alone from the preset's assumed value (Table 1's exhaust path known), then jointly with the exhaust
  path's C_v and b_v (from Table 1), with profile likelihoods of all three (full mode);
- the identified silencer's Fig. 12 offsets (end pressure with minus without it) and its flow ratio at 0.65 and
  0.2 MPa, the two things the paper says in words.

The recovered K is a procedure check (the truth is pamjax's own); the paper's numbers are words, compared as such.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import pamjax as pj
from pamjax import presets
from pamjax.gallery import Result, Row, plt, save

PAPER = "000"
TITLE = "Exhaust silencer identified from deflation runs (Fig. 12 and its text)"
COVERS = ("Fig. 12", "text: exhaust silencer explains Fig. 12's offset")

TRUE_PERMEANCE = 1.5e-14  # kg/(s Pa²), chosen (see the docstring)
NOISE = 2e3  # Pa, the hybrid bench's pressure noise
DUTIES = (0.0, 0.25, 0.50, 0.75)
PERMEANCE = "valve.exhaust.second.permeance"
EXHAUST = ("valve.exhaust.first.discharge_coefficient", "valve.exhaust.first.critical_ratio")
P_ATM = 101325.0


def comparison(item, quantity, pamjax, *, paper=None, truth=None, tolerance=None, kind="procedure check", note=""):
    """One comparison as plain data (see p000_12_hysteresis)."""
    return dict(item=item, quantity=quantity, paper=paper, pamjax=float(pamjax), truth=truth, tolerance=tolerance,
                kind=kind, note=note)


def tank(permeance=None):
    """The valve-test tank with the exact switching valve; with a silencer of `permeance` (None: without one)."""
    silencer = False if permeance is None else pj.PorousRestriction(permeance)
    return presets.mas10_tank_system("exact", silencer=silencer)


def recordings(truth, horizon, rate):
    ts = np.arange(0.0, horizon + 1e-9, 1.0 / rate)
    out = []
    for k, u in enumerate(DUTIES):
        rec = pj.synthetic_recording(truth, pj.Constant(u), ts, noise=dict(pressure=NOISE), channels=["pressure"],
                                     y0=truth.initial_state(presets.SUPPLY_PRESSURE), seed=10 + k,
                                     name=f"deflate_u{u:.2f}", stepping="pwm", substeps=32)
        out.append(pj.Experiment(rec, pj.Constant(u), channels=["pressure"], scales=dict(pressure=NOISE),
                                 initial=dict(pressure=presets.SUPPLY_PRESSURE), stepping="pwm"))
    return out


def flow_ratio(system, p_up):
    """Silenced over unsilenced exhaust flow from `p_up` [Pa abs] to atmosphere."""
    silenced = system.valve.exhaust.mass_flow(p_up, P_ATM, system.air)
    bare = system.valve.exhaust.first.mass_flow(p_up, P_ATM, system.air)
    return float(silenced / bare)


def end_pressures(system, horizon):
    ts = jnp.linspace(0.0, horizon, 3)
    return {u: float(pj.simulate(system, pj.Constant(u), ts, y0=system.initial_state(presets.SUPPLY_PRESSURE),
                                 stepping="pwm").pressure[-1]) for u in DUTIES[1:]}


def draw(out, experiments, alone, profiles):
    """The figure (written into `out`): the runs with the silencer fitted alone, the joint fit's profiles (full
    mode); returns its file name."""
    k_fit, k_se = float(alone.values[0]), float(alone.standard_errors[0])
    pyplot = plt()
    fig, axes = pyplot.subplots(1, 2, figsize=(13, 4.5))
    predicted = pj.predictions(alone.model, experiments)  # one program for the runs (one per run: 4x the compiling)
    for k, (e, p) in enumerate(zip(experiments, predicted)):
        pred = np.asarray(p["pressure"])
        axes[0].plot(e.times, np.asarray(e.data["pressure"]) / 1e5, ".", color=f"C{k}", ms=1.5)
        axes[0].plot(e.times, pred / 1e5, "-", color=f"C{k}", lw=1, label=f"u = {DUTIES[k]:.2f}")
    axes[0].set(xlabel="t [s]", ylabel="tank pressure [bar abs]",
                title=f"deflation runs (dots) and the identified silencer: K = {k_fit:.3g} ± {k_se:.1g}")
    axes[0].legend(fontsize=8)
    for k, p in enumerate([] if profiles is None else profiles.profiles):
        axes[1].plot(np.asarray(p.values) / p.value, p.delta, "o-", ms=3, color=f"C{k}",
                     label=f"{p.label.split('.')[-1]}: {p.verdict}")
    axes[1].axhline(3.84, color="k", lw=0.8, ls="--")
    axes[1].set(xlabel="value / fitted value", ylabel="Δχ²", ylim=(0, 12),
                title="profiles: K with the exhaust path's C_v, b_v")
    if profiles is None:
        axes[1].text(0.5, 0.5, "profiles: full mode", ha="center", transform=axes[1].transAxes)
    else:
        axes[1].legend(fontsize=8)
    return save(fig, out, "silencer.png")


def run(out, quick=False):
    horizon, rate = (1.0, 50.0) if quick else (2.0, 100.0)
    truth = tank(TRUE_PERMEANCE)
    experiments = recordings(truth, horizon, rate)
    start = tank(presets.MAS10_SILENCER_PERMEANCE)  # the preset's assumed silencer, Table 1's exhaust path
    free_k = [dict(path=PERMEANCE, transform="log")]
    alone = pj.fit(start, experiments, free_k, progress=False)
    joint = pj.fit(start, experiments, free_k + list(EXHAUST), progress=False)
    profiles = None if quick else pj.profile_likelihood(joint, progress=False, max_points=10)  # full mode only
    k_fit, k_se = float(alone.values[0]), float(alone.standard_errors[0])
    identified = eqx.tree_at(lambda s: s.valve.exhaust.second.permeance, start, jnp.asarray(k_fit))

    ends = {name: end_pressures(system, horizon) for name, system in
            (("without", tank(None)), ("identified", identified), ("preset", start), ("truth", truth))}
    offsets = {name: {u: ends[name][u] - ends["without"][u] for u in DUTIES[1:]}
               for name in ("identified", "preset", "truth")}
    ratios = {name: {f"{p / 1e5:.2f} bar": flow_ratio(system, p) for p in (6.5e5, 2e5)}
              for name, system in (("identified", identified), ("preset", start))}
    numbers = dict(
        true_permeance=TRUE_PERMEANCE, preset_permeance=presets.MAS10_SILENCER_PERMEANCE,
        alone=dict(permeance=k_fit, standard_error=k_se, converged=bool(alone.converged),
                   z=(k_fit - TRUE_PERMEANCE) / k_se, abs_z=abs(k_fit - TRUE_PERMEANCE) / k_se),
        joint=dict(values=dict(zip(joint.labels, joint.values)),
                   standard_errors=dict(zip(joint.labels, joint.standard_errors)),
                   correlation=np.asarray(joint.correlation).tolist(), converged=bool(joint.converged),
                   permeance_abs_z=abs(float(joint.values[0]) - TRUE_PERMEANCE) / float(joint.standard_errors[0])),
        profiles={} if profiles is None else {p.label: dict(verdict=p.verdict, interval=p.interval)
                                              for p in profiles.profiles},
        fig12_offset_kPa={name: {f"{u:.2f}": v / 1e3 for u, v in d.items()} for name, d in offsets.items()},
        fig12_offset_identified_over_truth={f"{u:.2f}": offsets["identified"][u] / offsets["truth"][u]
                                            for u in DUTIES[1:]},
        flow_ratio=ratios, horizon_s=horizon, rate_Hz=rate)
    joint_k = numbers["joint"]["values"][PERMEANCE]
    numbers["comparisons"] = [
        comparison("text: exhaust silencer", "silencer permeance K fitted alone [kg/(s Pa²)]", k_fit,
                   truth=TRUE_PERMEANCE, tolerance=3 * k_se, note="from the preset's assumed K, 2.0e-14"),
        comparison("text: exhaust silencer", "K fitted with the exhaust path's C_v, b_v [kg/(s Pa²)]", joint_k,
                   truth=TRUE_PERMEANCE, tolerance=3 * numbers["joint"]["standard_errors"][PERMEANCE]),
        comparison("text: exhaust silencer", "silenced / unsilenced exhaust flow at 0.65 MPa, identified silencer",
                   ratios["identified"]["6.50 bar"], paper=None, kind="paper (words)",
                   note="paper: 'almost negligible at higher upstream pressure levels'; near 1 agrees"),
        comparison("Fig. 12", "end-pressure offset at duty 0.25, identified silencer [kPa]",
                   offsets["identified"][0.25] / 1e3, paper=None, kind="paper (words)",
                   note="paper: the simulation without the silencer drops faster, a steady-state offset; > 0 agrees"),
    ]

    fig_name = draw(out, experiments, alone, profiles)

    verdicts = ", ".join(f"{k.split('.')[-1]} {v['verdict']}" for k, v in numbers["profiles"].items()) or "full mode"
    rows = [
        Row("text: exhaust silencer", "silencer permeance identified from deflation runs (duty 0, 0.25, 0.5, 0.75; "
            "synthetic, exact switching valve, 2 kPa noise)", "no data: 'negligible at high pressure, slows the end "
            "of a discharge'",
            f"K = {k_fit:.4g} ± {k_se:.2g} alone, {joint_k:.4g} with C_v, b_v (truth {TRUE_PERMEANCE:.3g}; the "
            f"preset assumed {presets.MAS10_SILENCER_PERMEANCE:.3g}); profiles: {verdicts}", figure=fig_name),
        Row("Fig. 12", "end-pressure offset (with − without the identified silencer) at duty 0.25 / 0.50 / 0.75; "
            "silenced/unsilenced exhaust flow at 0.65 / 0.2 MPa",
            "simulation without the silencer drops faster: steady-state offset; negligible at high pressure",
            " / ".join(f"+{v / 1e3:.0f}" for v in offsets["identified"].values()) + " kPa; flow ratio "
            + " / ".join(f"{v:.2f}" for v in ratios["identified"].values()), figure=fig_name),
    ]
    return Result(rows, numbers, paper=dict(silencer="no data", duties=DUTIES[1:]))


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
