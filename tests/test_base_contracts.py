"""The contract members the workflows ask instead of reading attributes by name (issue 31 item 3): what each component,
system and experiment answers, that an incomplete implementation cannot be made, and that the workflows' answers are
the ones the duck typing gave (`tests/test_architecture.py` checks that no workflow reads attributes by name).

The contracts' abstract classes: `AbstractSystem` and `AbstractMuscleSystem` (`pamjax._systems.base`: `actuators`,
`with_supply_pressure`), `AbstractFriction` (`pamjax._physics.friction`), `AbstractSignal.cycle_frequency`
(`pamjax._physics.signals`), `AbstractExperiment` (`pamjax._fit.experiment`, `pamjax._fit.static_experiments`)."""

import equinox as eqx
import jax
import numpy as np
import pytest

import pamjax as pj
from pamjax import presets

MUSCLE = presets.dmsp40_muscle()


def _joint():
    return pj.AntagonisticJoint(pj.ISO6358Regulator(), pj.ISO6358Regulator(), MUSCLE, MUSCLE)


@pytest.mark.parametrize("friction", [pj.CoulombViscousFriction(), pj.BristleFriction(), pj.BoucWenFriction(),
                                      pj.KarnoppFriction()], ids=lambda f: type(f).__name__)
def test_every_friction_declares_its_sliding_levels(friction):
    # eq. 8-9's levels, as each friction's own fields hold them (paper 000: F_c = 16 N)
    assert float(friction.coulomb_force) == pytest.approx(16.0)
    assert float(friction.viscous_coefficient) > 0
    width = friction.smoothing_width()
    if friction.hybrid or isinstance(friction, pj.BristleFriction):
        assert width is None  # switches direction at events, or a bristle's exact |v|: nothing smoothed
    else:
        assert width is friction.velocity_width


def test_a_friction_without_its_levels_cannot_be_made():
    class OnlyViscous(pj.AbstractFriction):
        viscous_coefficient: jax.Array = eqx.field(converter=np.asarray, default=1.0)

        def force(self, v, z):
            return self.viscous_coefficient * v

    with pytest.raises(TypeError, match="coulomb_force"):
        OnlyViscous()


def test_actuators_name_what_the_command_drives():
    mas10 = presets.mas10_system(valve="pwm")
    assert mas10.actuators == {"valve": mas10.valve}
    regulated = pj.RegulatedMuscleSystem(pj.ISO6358Regulator(), MUSCLE)
    assert regulated.actuators == {"regulator": regulated.regulator} and regulated.valve is regulated.regulator
    joint = _joint()
    assert list(joint.actuators) == ["flexor_regulator", "extensor_regulator"]
    assert joint.actuators["extensor_regulator"] is joint.extensor_regulator
    assert next(iter(joint.actuators.values())) is joint.valve


def test_with_supply_pressure_feeds_every_actuator():
    mas10 = presets.mas10_system(valve="pwm")
    fed = mas10.with_supply_pressure(5e5)
    assert float(fed.valve.supply()) == 5e5 and float(mas10.valve.supply()) == 6.5e5
    # the same system as feeding `valve` alone gave (one actuator), leaf for leaf
    old = eqx.tree_at(lambda s: s.valve, mas10, mas10.valve.with_supply_pressure(5e5))
    assert jax.tree_util.tree_structure(fed) == jax.tree_util.tree_structure(old)
    assert all(np.array_equal(a, b) for a, b in zip(jax.tree_util.tree_leaves(fed), jax.tree_util.tree_leaves(old)))


def test_muscle_systems_are_those_with_one_muscle():
    assert isinstance(presets.mas10_system(valve="pwm"), pj.AbstractMuscleSystem)
    assert isinstance(pj.RegulatedMuscleSystem(pj.ISO6358Regulator(), MUSCLE), pj.AbstractMuscleSystem)
    assert not isinstance(presets.mas10_tank_system(), pj.AbstractMuscleSystem)
    assert not isinstance(_joint(), pj.AbstractMuscleSystem)  # two muscles: asked by name (flexor, extensor)
    assert isinstance(MUSCLE, pj.AbstractMuscle)


@pytest.mark.parametrize(("signal", "frequency"), [(pj.Triangle(0.1, 0.9, 0.25), 0.25), (pj.Sine(0.5, 0.1, 2.0), 2.0),
                                                   (pj.SquareWave(), 1.5), (pj.Constant(0.5), None),
                                                   (pj.Step(0.0, 1.0), None)], ids=lambda s: type(s).__name__)
def test_signals_say_how_often_they_repeat(signal, frequency):
    got = signal.cycle_frequency()
    assert got is None if frequency is None else float(got) == pytest.approx(frequency)


def test_static_experiments_have_no_noise_channels_and_no_split():
    static = [pj.bench.ForceMapExperiment([0.0, 0.01], [3e5, 4e5], [100.0, 200.0], scale=2.0),
              pj.bench.FrictionCurveExperiment([0.1, 0.2], [40.0, 66.0], scale=1.0),
              pj.bench.FlowCurveExperiment([5e5], [2e5], [1e-3], scale=1e-5)]
    for e in static:
        assert e.noise_channels == () and e.split_time is None


def test_an_experiment_without_noise_channels_or_split_cannot_be_made():
    class Partial(pj.AbstractExperiment):
        name: str = "partial"
        channels: tuple = ("force",)

        def check(self, model):
            pass

        def predict(self, model):
            return {}

        def layout(self):
            return []

        def residuals_of(self, pred, part="identification"):
            return np.zeros(0)

    with pytest.raises(TypeError, match="noise_channels|split_time"):
        Partial()


def test_a_dynamic_experiment_reports_its_noise_channels_and_split():
    ts = np.linspace(0.0, 1.0, 11)
    rec = pj.Recording(ts, {"pressure": np.full(11, 2e5), "position": np.zeros(11)})
    e = pj.Experiment(rec, pj.Constant(0.5), scales={"pressure": 2e3}, validation_fraction=0.4)
    assert e.noise_channels == ("pressure",)
    assert float(e.split_time) == pytest.approx(0.6, abs=1e-9)


def test_force_maps_and_loops_ask_for_a_muscle_system():
    loop = pj.bench.LoopForceMapExperiment([0.0], [3e5], [1e-3], [10.0], scale=1.0)
    with pytest.raises(pj.PamjaxInputError, match="needs a 'muscle' and a 'friction'.*AntagonisticJoint"):
        loop.check(_joint())
    force_map = pj.bench.ForceMapExperiment([0.0, 0.01], [3e5, 4e5], [100.0, 200.0])
    force_map.check(MUSCLE)  # a muscle on its own
    force_map.check(pj.RegulatedMuscleSystem(pj.ISO6358Regulator(), MUSCLE))
    with pytest.raises(pj.PamjaxInputError, match="has no muscle"):
        force_map.check(_joint())
