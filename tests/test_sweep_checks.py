"""A sweep's swept values meet the checks `simulate` applies to a system's parameters (`pamjax._sweep.plan`,
`check_parameters`: the magnitudes that betray another unit), named by their key and first bad point before any
solve; and `pamjax sweep`'s columns of swept matrix elements carry the element's own unit (`pamjax._cli.sweep`)."""

import numpy as np
import pytest

import pamjax
import pamjax._sweep.sweep as sweep_module
from pamjax import presets
from pamjax._cli.sweep import element_unit, over_column


@pytest.fixture
def no_solve(monkeypatch):
    """Reaching the compiled lanes is a test failure: the refusal must come first."""

    def refuse(*args, **kwargs):
        raise AssertionError("a solve was started before the input was rejected")

    monkeypatch.setattr(sweep_module, "chunk_program", refuse)


@pytest.mark.parametrize("path, values, match", [
    # 9600 kg is 9.6 kg typed in grams: simulate and the presets refuse it; the sweep solved it (status 1, NaN)
    ("payload_mass", [9.6, 9.6, 9600.0, 9.6], r"over\['payload_mass'\] at point 2: .*payload_mass = 9600 kg: more "
                                              r"than 1000 kg; that looks like g"),
    # its own check (max_position > min_position) takes no batch of values: the points' extremes are checked
    ("muscle.max_position", [0.075, 75.0], r"over\['muscle.max_position'\] at point 1: .*that looks like mm"),
    ("air.temperature", [293.15, 293.15, 20.0], r"over\['air.temperature'\] at point 2: .*looks like °C"),
    ("muscle.force_law.max_pressure", [6e5, 6.0], r"over\['muscle.force_law.max_pressure'\] at point 1: .*bar"),
])
def test_swept_values_in_another_unit_are_refused_by_key_and_point(no_solve, path, values, match):
    system = presets.mas10_system(valve="averaged")
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        pamjax.sweep(system, pamjax.Constant(0.5), np.linspace(0.0, 0.1, 3), {path: values},
                     reduce=pamjax.FinalValue(), progress=False)


def test_the_first_bad_point_of_a_grid_is_named(no_solve):
    """On a grid of two swept paths the index is the flat point's (row-major), the first of several bad ones."""
    system = presets.mas10_system(valve="averaged")
    over = {"payload_mass": np.array([5.0, 9.6, 2000.0, 3000.0])[:, None], "signal.value": [0.3, 0.6]}
    with pytest.raises(pamjax.PamjaxInputError, match=r"over\['payload_mass'\] at point 4: .*= 2000 kg"):
        pamjax.sweep(system, pamjax.Constant(0.5), np.linspace(0.0, 0.1, 3), over, reduce=pamjax.FinalValue(),
                     progress=False)


def test_swept_matrix_elements_are_labelled_with_their_own_unit():
    """eq. 13's m[i, j] multiplies u^i p_g^j: its unit is kg/(s Pa^j), which the CSV's header wrote with a literal
    j ("valve.coefficients[1,0] [kg/(s Pa^j)]" for m4, in kg/s)."""
    model = presets.mas10_system(valve="averaged")
    assert over_column(model, "valve.coefficients[1,0]") == "valve.coefficients[1,0] [kg/s]"
    assert over_column(model, "valve.coefficients[0,1]") == "valve.coefficients[0,1] [kg/(s Pa)]"
    assert over_column(model, "valve.coefficients[2,2]") == "valve.coefficients[2,2] [kg/(s Pa^2)]"
    assert over_column(model, "payload_mass") == "payload_mass [kg]"
    assert element_unit("m", (1,)) == "m"  # a unit without index exponents is every element's


def test_a_key_a_signal_factory_never_reads_is_refused_with_the_nearest_leaf(no_solve):
    """With a factory, a misspelt system path went to the factory, which never read it: every point ran the base
    payload, status 0. Refused now, with the nearest leaf's path, as the same typo is without a factory; a key the
    factory reads (by item, `get`, or by iterating over the values) reaches the solve."""
    system = presets.mas10_system(valve="averaged")
    ts = np.linspace(0.0, 0.1, 3)

    def run(signal, over):
        pamjax.sweep(system, signal, ts, over, reduce=pamjax.FinalValue(), progress=False)

    with pytest.raises(pamjax.PamjaxInputError, match=r"over\['payload_mas'\]: the system \(MuscleSystem\) has no leaf "
                                                      r"'payload_mas' and the signal factory never reads it .*it reads "
                                                      r"\['amp'\]\); did you mean 'payload_mass'\?"):
        run(lambda v: pamjax.Sine(0.5, v["amp"], 1.0), {"amp": 0.2, "payload_mas": [5.0, 15.0]})
    with pytest.raises(pamjax.PamjaxInputError, match=r"over\['payload_mas'\]: the system \(MuscleSystem\) has no leaf "
                                                      r"'payload_mas'; did you mean 'payload_mass'\?"):
        run(pamjax.Sine(0.5, 0.2, 1.0), {"payload_mas": [5.0, 15.0]})
    with pytest.raises(pamjax.PamjaxInputError, match=r"over\['signal.amp'\]: with a signal factory every signal.\* "
                                                      r"key goes to the factory, which never reads this one"):
        run(lambda v: pamjax.Sine(0.5, v["amp"], 1.0), {"amp": 0.2, "signal.amp": [0.1, 0.2]})
    for factory, over in [(lambda v: pamjax.Sine(0.5, v.get("amp", 0.1), 1.0), {"amp": [0.1, 0.2]}),
                          (lambda v: pamjax.Sine(**v), {"offset": 0.5, "amplitude": [0.1, 0.2], "frequency": 1.0}),
                          (lambda v: pamjax.Sine(0.5, v["amp"], 1.0), {"amp": [0.1, 0.2], "payload_mass": 9.6})]:
        with pytest.raises(AssertionError, match="a solve was started"):
            run(factory, over)
