"""Paper 000's plant and valve-test tank with the hybrid bench's true parameters (`meta.json`, `params`; the bench's
recordings ship in `pamjax/data/hybrid-reference-bench`, `pamjax.gallery.bench_folder()`). Used by `fits/control.py`,
`fits/valve_tank.py` and the gallery's `p000_06`-`p000_08`.
"""

import jax.numpy as jnp

import pamjax as pj
from pamjax import presets

from ..toolkit import bench_params


def bench_plant(friction="coulomb", params=None):
    """Paper 000's plant with the bench's true parameters (meta.json `params`, or `params`) and the smoothed PWM
    valve; `friction` "coulomb" (smooth sign) or "karnopp" (exact stick-slip, as the bench)."""
    q = bench_params() if params is None else params
    muscle = pj.Muscle(
        force_law=pj.PolynomialForce(jnp.asarray([q[f"a{i}"] for i in range(5)]), q["k0"], q["k1"], q["k2"],
                                     q["p_max"]),
        volume_law=pj.LinearVolume(q["v0"], q["v1"]),
        min_position=q["x_min"],
        max_position=q["x_max"],
    )
    friction = (pj.KarnoppFriction if friction == "karnopp" else pj.CoulombViscousFriction)(q["Fc"], q["Cf"])
    return pj.MuscleSystem(valve=presets.mas10_valve("smooth"), muscle=muscle, payload_mass=q["M"], friction=friction)


def tank_model(P, cv12, b12, cv23, b23):
    """The bench's tank (5e-5 m³, adiabatic) fed by the on/off valve with the given C_v, b_v (meta.json names)."""
    valve = pj.OnOffValve(
        inflate=pj.EllipseRestriction(cv12, b12, P["A"]), exhaust=pj.EllipseRestriction(cv23, b23, P["A"]),
        supply_pressure=P["p_s"], pwm_frequency=P["f_pwm"], switch_on_delay=P["t_on"], switch_off_delay=P["t_off"],
    )
    return pj.TankSystem(valve=valve, volume=5e-5, air=pj.Air(P["R"], P["T"], P["kappa"], P["p_atm"]),
                         polytropic_index=P["kappa"])
