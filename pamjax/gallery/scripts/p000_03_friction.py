"""Paper 000, eq. 9 and Fig. 6: friction against velocity from constant-velocity runs (cylinder, muscle, their sum).

The paper's procedure: a low-friction cylinder driven at constant velocities gives its own friction (chamber pressure
difference times area); the muscle coupled to the cylinder gives the total (load cell); the muscle's friction is the
difference. Paper 000 shows the curves only. Here each run is synthetic: 0.1 s at 1 kHz of position (0.1 mm noise,
the bench's potentiometer) and force (3 N noise, assumed), the muscle with the preset's friction (F_c = 16 N, paper;
C_f = 250 N s/m, preset) and the cylinder with an assumed F_c = 6 N, C_f = 60 N s/m. Each run is reduced by
`constant_velocity_point`; eq. 9 (F_c sign(v) + C_f v) is fitted to the cylinder and to the total with
`FrictionCurveExperiment`, and the muscle's parameters are their difference.
"""

import numpy as np

import pamjax as pj
from pamjax import presets
from pamjax.gallery import Result, Row, plt, save

PAPER = "000"
TITLE = "Friction against velocity from constant-velocity runs (eq. 9, Fig. 6)"
COVERS = ("eq. 9", "Fig. 6")

MUSCLE = pj.CoulombViscousFriction(presets.COULOMB_FORCE, presets.VISCOUS_COEFFICIENT)
CYLINDER = pj.CoulombViscousFriction(6.0, 60.0)  # N, N s/m: an assumed low-friction cylinder (no numbers in paper)
POSITION_NOISE, FORCE_NOISE = 1e-4, 3.0  # m (bench potentiometer), N (assumed load cell / pressure-force noise)
RATE, DURATION = 1000.0, 0.1  # Hz, s per constant-velocity run


def runs(truth, speeds, rng):
    """Reduce one synthetic constant-velocity run per speed (both directions) to (v, F, σ_F)."""
    t = np.arange(0.0, DURATION, 1.0 / RATE)
    points = []
    for v in np.concatenate([-speeds[::-1], speeds]):
        force = float(truth(v)) + FORCE_NOISE * rng.standard_normal(t.size)
        position = v * t + POSITION_NOISE * rng.standard_normal(t.size)
        points.append(pj.bench.constant_velocity_point(t, position, force))
    return np.array(points).T


def fit(velocities, forces, sigma, name):
    start = pj.CoulombViscousFriction(10.0, 100.0)
    exp = pj.bench.FrictionCurveExperiment(velocities, forces, scale=sigma, friction="", name=name)
    res = pj.fit(start, [exp], ["coulomb_force", "viscous_coefficient"], progress=False)
    return np.asarray(res.values), np.asarray(res.standard_errors), res


def run(out, quick=False):
    speeds = np.array([0.01, 0.03, 0.06, 0.1, 0.15]) if quick else np.array([0.01, 0.02, 0.04, 0.06, 0.08, 0.1, 0.15,
                                                                             0.2])
    rng = np.random.default_rng(0)
    cylinder = runs(lambda v: pj.bench.steady_friction_force(CYLINDER, v), speeds, rng)
    total = runs(lambda v: pj.bench.steady_friction_force(CYLINDER, v) + pj.bench.steady_friction_force(MUSCLE, v),
                 speeds, rng)
    sigma = FORCE_NOISE / np.sqrt(DURATION * RATE)
    cyl, cyl_se, _ = fit(cylinder[0], cylinder[1], sigma, "cylinder")
    tot, tot_se, _ = fit(total[0], total[1], sigma, "cylinder_and_muscle")
    muscle, muscle_se = tot - cyl, np.hypot(tot_se, cyl_se)
    truth = np.array([presets.COULOMB_FORCE, presets.VISCOUS_COEFFICIENT])
    z = (muscle - truth) / muscle_se
    numbers = dict(cylinder=dict(coulomb_N=cyl[0], viscous_Ns_per_m=cyl[1]),
                   total=dict(coulomb_N=tot[0], viscous_Ns_per_m=tot[1]),
                   muscle=dict(coulomb_N=muscle[0], coulomb_se_N=muscle_se[0], viscous_Ns_per_m=muscle[1],
                               viscous_se_Ns_per_m=muscle_se[1]),
                   muscle_z=z.tolist(), runs=int(cylinder.shape[1]))

    pyplot = plt()
    fig, ax = pyplot.subplots(figsize=(7, 4.5))
    vv = np.linspace(-speeds.max(), speeds.max(), 401)
    curve = lambda p: p[0] * np.sign(vv) + p[1] * vv  # noqa: E731
    ax.errorbar(cylinder[0], cylinder[1], cylinder[2], fmt="o", color="C0", ms=4, label="cylinder runs")
    ax.errorbar(total[0], total[1], total[2], fmt="s", color="C2", ms=4, label="cylinder + muscle runs")
    ax.plot(vv, curve(cyl), "C0-", lw=1)
    ax.plot(vv, curve(tot), "C2-", lw=1)
    ax.plot(vv, curve(muscle), "C3-", lw=2, label=f"muscle = total − cylinder: F_c {muscle[0]:.1f} N, "
                                                    f"C_f {muscle[1]:.0f} N s/m")
    ax.set(xlabel="velocity [m/s]", ylabel="friction force [N]", title="Fig. 6: friction against velocity (eq. 9)")
    ax.legend(fontsize=8)
    fig_name = save(fig, out, "friction.png")
    rows = [Row("eq. 9, Fig. 6", "muscle friction = total − cylinder, eq. 9 fitted to constant-velocity runs",
                "curves only (F_c = 16 N from the loop; C_f 'experimentally approximated')",
                f"F_c {muscle[0]:.1f} ± {muscle_se[0]:.1f} N, C_f {muscle[1]:.0f} ± {muscle_se[1]:.0f} N s/m "
                f"(truth 16 N, 250 N s/m; {numbers['runs']} runs each)",
                figure=fig_name)]
    return Result(rows, numbers, paper=dict(coulomb_N=16.0))


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
