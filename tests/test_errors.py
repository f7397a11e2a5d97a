"""Bad input raises PamjaxInputError naming the argument, before any solve: the checks of `pamjax._core.errors`
(`check_positive`, `check_time_grid`, `require_float64`, ...) as the components' constructors (`pamjax._physics`,
`pamjax._systems`), `simulate` and `simulate_discrete` (`pamjax._solve`) call them."""

import jax.numpy as jnp
import numpy as np
import pytest

import pamjax
from pamjax import presets

E = pamjax.EllipseRestriction
CASES = [
    ("payload_mass", lambda: pamjax.MuscleSystem(presets.mas10_valve(), presets.mas10_muscle(), payload_mass=0.0)),
    ("payload_mass", lambda: pamjax.MuscleSystem(presets.mas10_valve(), presets.mas10_muscle(), payload_mass=-1.0)),
    ("area", lambda: E(0.36, 0.28, 0.0)),
    ("area", lambda: E(0.36, 0.28, -3e-6)),
    ("area", lambda: pamjax.NozzleRestriction(0.8, -1e-6)),
    ("volume", lambda: pamjax.TankSystem(presets.mas10_valve(), 0.0)),
    ("volume", lambda: pamjax.TankSystem(presets.mas10_valve(), -5e-5)),
    ("v0", lambda: pamjax.LinearVolume(-1e-5, 1e-4)),
    ("pwm_frequency", lambda: presets.mas10_valve(pwm_frequency=0.0)),
    ("pwm_frequency", lambda: presets.mas10_valve(pwm_frequency=-50.0)),
    ("frequency", lambda: pamjax.Triangle(0.05, 0.95, 0.0)),
    ("frequency", lambda: pamjax.Sine(0.5, 0.1, -1.0)),
    ("critical_ratio", lambda: E(0.36, 0.0, 3e-6)),
    ("critical_ratio", lambda: E(0.36, 1.0, 3e-6)),
    ("critical_ratio", lambda: E(0.36, 1.2, 3e-6)),
    ("critical_ratio", lambda: pamjax.ISO6358Restriction(1e-8, -0.1)),
    ("heat_capacity_ratio", lambda: pamjax.Air(heat_capacity_ratio=0.9)),
    ("discharge_coefficient", lambda: E(float("nan"), 0.28, 3e-6)),
    ("Sampled.values", lambda: pamjax.Sampled(jnp.linspace(0, 1, 5), jnp.ones(4))),
    ("Sampled.times", lambda: pamjax.Sampled(jnp.asarray([0.0, 1.0, 1.0]), jnp.ones(3))),
    ("supply_pressure", lambda: presets.mas10_valve(supply_pressure=-1.0)),
    ("atmospheric_pressure", lambda: pamjax.Air(atmospheric_pressure=0.0)),
]


@pytest.mark.parametrize("name, build", CASES, ids=[f"{i}-{c[0]}" for i, c in enumerate(CASES)])
def test_constructor_rejects(name, build):
    with pytest.raises(pamjax.PamjaxInputError, match=name):
        build()


SYSTEM = presets.mas10_tank_system("averaged")
TS = jnp.linspace(0.0, 0.1, 5)


@pytest.mark.parametrize(
    "name, kwargs",
    [
        ("ts", dict(ts=jnp.asarray([0.0, 0.1, np.nan]))),
        ("ts", dict(ts=jnp.asarray([0.0, 0.2, 0.1]))),
        ("ts", dict(ts=jnp.asarray([0.0, 0.0, 0.1]))),
        ("signal", dict(signal=pamjax.Constant(1.2))),
        ("signal", dict(signal=pamjax.Constant(-0.1))),
        ("signal", dict(signal=pamjax.Triangle(0.05, 1.05, 0.1))),
        ("y0.pressure", dict(y0=pamjax.TankState(jnp.asarray(-1e5)))),
        ("y0", dict(y0=pamjax.TankState(jnp.asarray(np.nan)))),
    ],
)
def test_simulate_rejects_before_solving(name, kwargs):
    args = dict(ts=TS, signal=pamjax.Constant(0.5))
    args.update(kwargs)
    with pytest.raises(pamjax.PamjaxInputError, match=name.replace(".", r"\.")):
        pamjax.simulate(SYSTEM, args.pop("signal"), args.pop("ts"), **args)


def test_muscle_y0_negative_pressure_and_discrete_inputs():
    system = presets.mas10_system("averaged")
    y0 = pamjax.MuscleState(jnp.asarray(-2e5), jnp.asarray(0.0), jnp.asarray(0.0))
    with pytest.raises(pamjax.PamjaxInputError, match="y0.pressure"):
        pamjax.simulate(system, pamjax.Constant(0.5), TS, y0=y0)
    with pytest.raises(pamjax.PamjaxInputError, match="sample_time"):
        pamjax.simulate_discrete(system, pamjax.Constant(0.5), 0.0, 0.1)
    with pytest.raises(pamjax.PamjaxInputError, match="t_end"):
        pamjax.simulate_discrete(system, pamjax.Constant(0.5), 1e-3, -0.1)
    with pytest.raises(pamjax.PamjaxInputError, match="signal"):
        pamjax.simulate_discrete(system, pamjax.Constant(1.5), 1e-3, 0.1)


def test_float32_mode_is_refused_with_instructions():
    """Without jax_enable_x64 every entry point refuses to run (no silent float32 physics)."""
    import subprocess
    import sys

    code = (
        "import pamjax, numpy as np\n"
        "from pamjax import presets\n"
        "try:\n"
        "    pamjax.simulate(presets.mas10_system('averaged'), pamjax.Constant(0.5), np.linspace(0, 0.1, 3))\n"
        "except pamjax.PamjaxInputError as e:\n"
        "    print('REFUSED', e)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert "REFUSED" in out.stdout and "jax_enable_x64" in out.stdout, out.stdout + out.stderr


def test_a_gradient_of_the_whole_system_on_the_pwm_grid_names_the_remedy():
    # jax.grad of a loss of the whole system traces the PWM frequency; the stick-slip model's PWM-synchronous grid
    # needs it to size the grid: the error names the way that works (the parameters only), which is then checked
    import jax

    system = presets.mas10_system(valve="pwm", friction="karnopp")
    ts = jnp.linspace(0.0, 0.2, 11)

    def loss(s):
        return jnp.mean(pamjax.simulate(s, pamjax.Constant(0.5), ts).position ** 2)

    with pytest.raises(pamjax.PamjaxInputError, match=r"pwm_frequency.*ParameterSpace\(system, free\)\.model\(theta\)"):
        jax.grad(loss)(system)
    space = pamjax.ParameterSpace(system, ["muscle.force_law.k0"])
    g = jax.grad(lambda th: loss(space.model(th)))(jnp.asarray(space.initial_theta()))
    assert bool(jnp.all(jnp.isfinite(g))) and float(g[0]) != 0.0
