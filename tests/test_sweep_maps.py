"""The sweep recipes users map an actuator with (`pamjax._sweep.maps`): the steady-state map shows paper 000's
10-90 % dead band and equals a direct `simulate`; the frequency response equals a least-squares sinusoid fit to a
direct `simulate` and falls with frequency. Short horizons; the oracle is independent of `sweep` (adaptive diffrax
solve, NumPy least squares on its own time grid)."""

import numpy as np
import pytest

import pamjax
from pamjax import presets
from pamjax._sweep.maps import frequency_response, steady_state_map

HORIZON, WINDOW = 2.0, 0.4  # s: 100 PWM periods, the last 20 averaged (a whole number of 50 Hz periods)


@pytest.fixture(scope="module")
def pwm_map():
    system = presets.mas10_system(valve="pwm")  # MHE2: 50 Hz, 2 ms switching delays, smoothed edges
    duties = np.array([0.0, 0.05, 0.08, 0.15, 0.23, 0.3, 0.5, 0.7, 0.85, 0.92, 0.95, 1.0])
    result = steady_state_map(system, duties, horizon=HORIZON, window=WINDOW, progress=False)
    return system, duties, result


def test_steady_state_map_shows_the_dead_band(pwm_map):
    _, duties, r = pwm_map
    assert np.all(r.status == 0)
    p, x = r["pressure"], r["position"]
    p_span, x_span = np.ptp(p), np.ptp(x)
    assert p_span > 4e5 and x_span > 0.05  # the map spans the muscle's working range (0.55 MPa, 62 mm measured)
    low, high = duties < 0.1, duties > 0.9
    # A 2 ms delay is 10 % of a 20 ms period: below it the valve never opens (chamber exhausted to atmosphere),
    # above 90 % it never closes (chamber at supply). Flat to 0.1 % of the range (549 Pa, 62 µm); measured: 15 Pa,
    # 0.7 µm off at 0.08 and 22 Pa, 13 µm at 0.92 (the smoothed 0.1 ms edges leak a little).
    np.testing.assert_allclose(p[low], 101325.0, atol=1e-3 * p_span)
    np.testing.assert_allclose(p[high], float(presets.SUPPLY_PRESSURE), atol=1e-3 * p_span)
    np.testing.assert_allclose(x[low], x[0], atol=1e-3 * x_span)
    np.testing.assert_allclose(x[high], x[-1], atol=1e-3 * x_span)
    # between the band edges both rise with duty, every step by more than 1 % of the range
    inner = slice(np.flatnonzero(low)[-1], np.flatnonzero(high)[0] + 1)
    assert np.all(np.diff(p[inner]) > 0.01 * p_span), p[inner]
    assert np.all(np.diff(x[inner]) > 0.01 * x_span), x[inner]


@pytest.mark.parametrize("duty", [0.23, 0.3, 0.7])
def test_steady_state_map_equals_direct_simulation(pwm_map, duty):
    """The map's mean is the time average over the window, each PWM phase once: against a dense (0.2 ms) `simulate`
    of the window, trapezoid rule. The plain mean of the map's 1 ms samples in the closed window counted the phase at
    its start twice: 59 Pa off at duty 0.3, 21 Pa at 0.7 (measured). At 0.23 the valve's edges fall between 1 ms
    samples (at 0.3 and 0.7 they land on them): the trapezoid mean over 20 phases a period aliased the ripple's kinks,
    43 Pa off (measured); the window is now sampled 100 times a period."""
    system, duties, r = pwm_map
    k = int(np.flatnonzero(duties == duty)[0])
    ts = np.concatenate([[0.0, 1.0], np.linspace(HORIZON - WINDOW, HORIZON, 2001)])  # 0.2 ms in the window
    traj = pamjax.simulate(system, pamjax.Constant(duty), ts)
    window = ts >= HORIZON - WINDOW - 1e-12
    for channel, tol in (("pressure", 10.0), ("position", 1e-5)):
        dense = np.trapezoid(np.asarray(traj.channel(channel))[window], ts[window]) / WINDOW
        # sweep: fixed RK4 at 0.2 ms, 0.2 ms samples in the window; simulate: adaptive Tsit5, rtol 1e-6. Measured
        # 0.1-2.8 Pa, < 1 µm (against a tight simulate, rtol 1e-10: within 0.03 Pa).
        assert abs(r[channel][k] - dense) < tol, (channel, r[channel][k], dense)


def _sine_fit(t, y, frequency):
    """Least squares y ≈ c + a sin(ωt) + b cos(ωt) = c + R sin(ωt + φ): returns R, φ [deg]."""
    w = 2 * np.pi * frequency
    design = np.stack([np.ones_like(t), np.sin(w * t), np.cos(w * t)], axis=1)
    (_, a, b), *_ = np.linalg.lstsq(design, y, rcond=None)
    return np.hypot(a, b), np.degrees(np.arctan2(b, a))


def test_frequency_response_equals_sinusoid_fit_and_falls_with_frequency():
    system = presets.mas10_system(valve="averaged")
    frequencies = np.array([0.5, 1.5, 4.0])  # Hz
    offset, amplitude, settle, periods = 0.5, 0.2, 3, 2
    fr = frequency_response(system, frequencies, offset=offset, amplitude=amplitude, settle_periods=settle,
                            periods=periods, progress=False)
    assert np.all(fr["result"].status == 0)
    # the sweep's common grid is 160 Hz, on which 2 periods of 1.5 Hz are 213.3 samples: a plain Fourier sum leaks
    # 0.5 % there; 0.5 Hz fits whole. The oracle: 300 Hz (whole windows for both), simulate, NumPy least squares.
    horizon = (settle + periods) / frequencies.min()
    ts = np.linspace(0.0, horizon, int(round(horizon * 300)) + 1)
    for k, f in enumerate(frequencies[:2]):
        traj = pamjax.simulate(system, pamjax.Sine(offset, amplitude, f), ts)
        last = ts > horizon - periods / f + 1e-9
        for channel in ("position", "pressure"):
            amp, phase = _sine_fit(ts[last], np.asarray(traj.channel(channel))[last], f)
            # the default method (rodas5a) against a tight simulate: 5.5e-7 relative in gain, 4e-6 deg in phase at
            # these frequencies (up to 8.8e-6 and 3.3e-4 deg at 2 Hz, docs/sweeps.md); bounds 1e-4 and 0.01 deg
            np.testing.assert_allclose(fr[channel]["gain"][k], amp / amplitude, rtol=1e-4)
            dphi = (fr[channel]["phase"][k] - phase + 180.0) % 360.0 - 180.0
            assert abs(dphi) < 0.01, (f, channel, fr[channel]["phase"][k], phase)
    # the reference is the commanded sine's exact coefficient -i A; with the averaged valve the "command" channel is
    # that sine, and dividing by its sampled coefficient gives the same to the trapezoid rule's error on 1.5 Hz's
    # fractional window (measured 4e-7 in gain, 3e-5 deg; 1e-15 on the whole windows of 0.5 and 4 Hz)
    ratio = {c: fr["result"][c] / fr["result"]["command"] for c in ("position", "pressure")}
    for channel in ("position", "pressure"):
        np.testing.assert_allclose(fr[channel]["gain"], np.abs(ratio[channel]), rtol=1e-6)
        np.testing.assert_allclose(fr[channel]["phase"], np.degrees(np.unwrap(np.angle(ratio[channel]))), atol=1e-4)
    for channel in ("position", "pressure"):  # a low-pass plant: gain and phase fall with frequency
        assert np.all(np.diff(fr[channel]["gain"]) < 0), fr[channel]["gain"]
        assert np.all(np.diff(fr[channel]["phase"]) < 0), fr[channel]["phase"]


def test_frequency_response_of_a_pwm_valve_does_not_depend_on_the_sampling():
    """With the PWM valve the "command" channel is the duty latched per PWM period: its sampled harmonic, the old
    reference, moved the 5 Hz pressure phase with `samples_per_period` (-65.7 deg at 40, -62.3 deg at 64). Against
    the commanded sine, on a grid of at least 20 samples per PWM period: -79.33 deg at the defaults, a tight
    reference's (-79.17 and -79.18 deg, gains 0.17 % apart, when the 50 Hz ripple aliased into Y)."""
    system = presets.mas10_system(valve="pwm")
    fr = [frequency_response(system, [5.0], settle_periods=1, periods=1, samples_per_period=spp, progress=False)
          for spp in (40, 64)]
    for channel in ("position", "pressure"):
        np.testing.assert_allclose(fr[0][channel]["gain"], fr[1][channel]["gain"], rtol=0.01)
        np.testing.assert_allclose(fr[0][channel]["phase"], fr[1][channel]["phase"], atol=0.5)
    # a low-pass lag: -75.1 deg after this one settling period, -79.33 settled (the old reference gave -65.7)
    assert -90.0 < fr[0]["pressure"]["phase"][0] < -70.0


def test_frequency_response_samples_a_pwm_valves_ripple():
    """At 40 samples per 5 Hz period (200 Hz) the 50 Hz ripple's 4th harmonic aliased onto 5 Hz: the MAS-10's pressure
    gain 0.15 % and phase 0.15 deg off a tight reference (-79.17 against -79.33 deg at the defaults). The grid now
    holds at least 20 samples per PWM period, as `steady_state_map`'s: the same harmonic as at 400 per 5 Hz period."""
    system = presets.mas10_system(valve="pwm")
    fr = [frequency_response(system, [5.0], settle_periods=1, periods=1, samples_per_period=spp, progress=False)
          for spp in (40, 400)]
    assert np.max(np.diff(fr[0]["result"].t)) <= 1.0 / (20 * 50.0) * (1 + 1e-9)
    for channel in ("position", "pressure"):
        np.testing.assert_allclose(fr[0][channel]["gain"], fr[1][channel]["gain"], rtol=1e-4)
        np.testing.assert_allclose(fr[0][channel]["phase"], fr[1][channel]["phase"], atol=0.01)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(amplitude=0.0), "amplitude"),
        (dict(periods=1.5), "periods"),
        (dict(samples_per_period=2), "samples_per_period"),
        (dict(frequencies=[[0.5, 1.0]]), "frequencies"),
        (dict(frequencies=[0.5, -1.0]), "frequencies"),
        # an `over` sweeping the frequency itself replaced the map's axis: the gains at 2 and 3 Hz were reported as
        # those of `frequencies` (or, below the grid's, a 2 s window on a 1 s run)
        (dict(over={"signal.frequency": [2.0, 3.0]}),
         r"frequency_response: over must not hold 'signal.frequency', the map's own axis: pass those values as "
         r"frequencies"),
        # "unknown channel 'p'" (a string read letter by letter), raw errors, a TypeError "multiple values" before
        (dict(channels="position"), r"channels must be .* such as \('position',\), got 'position'"),
        (dict(samples_per_period=float("nan")), r"samples_per_period must be finite"),
        (dict(settle_periods=float("inf")), r"settle_periods must be finite"),
        (dict(reduce=pamjax.FinalValue()), r"frequency_response takes no reduce"),
    ],
)
def test_frequency_response_bad_input_is_named(kwargs, match):
    kwargs = {"frequencies": [0.5, 1.0], **kwargs}
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        frequency_response(presets.mas10_system(valve="averaged"), kwargs.pop("frequencies"), **kwargs)


def test_steady_state_map_of_no_commands_is_refused():
    # an IndexError from deep in the sweep before
    with pytest.raises(pamjax.PamjaxInputError, match=r"commands must be a non-empty 1-D array, got shape \(0,\)"):
        steady_state_map(presets.mas10_system(valve="averaged"), [], horizon=0.5, window=0.1, progress=False)


def test_a_sample_interval_longer_than_the_window_is_named():
    # "ts needs at least two times (the sweep starts at ts[0])" named neither setting before
    with pytest.raises(pamjax.PamjaxInputError, match=r"sample_interval must be at most the window \(0.5 s\) and the "
                                                      r"horizon \(1.0 s\), got 2.0"):
        steady_state_map(presets.mas10_system(valve="averaged"), [0.5], horizon=1.0, window=0.5, sample_interval=2.0,
                         progress=False)


def test_steady_state_map_refuses_its_own_axis_in_over_and_a_reduce():
    # over["signal.value"] replaced the commands silently; reduce= was a raw TypeError "multiple values"
    system = presets.mas10_system(valve="averaged")
    with pytest.raises(pamjax.PamjaxInputError, match=r"steady_state_map: over must not hold 'signal.value', the "
                                                      r"map's own axis: pass those values as commands"):
        steady_state_map(system, [0.2, 0.5], horizon=1.0, window=0.5, over={"signal.value": [0.9, 0.9]})
    with pytest.raises(pamjax.PamjaxInputError, match=r"steady_state_map takes no reduce"):
        steady_state_map(system, [0.5], horizon=1.0, window=0.5, reduce=pamjax.FinalValue())


def test_flow_surface_refuses_pressures_in_bar():
    # pressures=[2.0, 3.0] (bar) mapped a chamber at 2 and 3 Pa abs; fit_averaged_valve refused the same grid
    with pytest.raises(pamjax.PamjaxInputError, match=r"pressures is 3 Pa at most: that looks like bar"):
        pamjax.flow_surface(presets.mas10_valve(), [0.25, 0.5], [2.0, 3.0], pamjax.Air())


def test_frequency_response_refuses_frequencies_at_or_above_the_pwm_nyquist_frequency():
    """A switching valve latches one duty per PWM period: at 50 Hz on the MAS-10's 50 Hz valve the latched duty was
    0.5 every period, yet the map reported a gain of 94,765 Pa/duty at -124 deg (the ripple). Refused before any
    solve, naming the PWM frequency and the averaged valve; a swept PWM frequency counts by its lowest value; the
    averaged valve maps beyond it."""
    pwm = presets.mas10_tank_system()
    for frequencies in ([1.0, 50.0], [25.0], [30.0, 100.0]):
        with pytest.raises(pamjax.PamjaxInputError, match=r"frequencies must lie below half the switching valve's "
                                                          r"PWM frequency \(50 Hz / 2 = 25 Hz\).*averaged valve"):
            frequency_response(pwm, frequencies, channels=("pressure",), progress=False)
    with pytest.raises(pamjax.PamjaxInputError, match=r"\(20 Hz / 2 = 10 Hz\), got \[12.\] Hz"):
        frequency_response(pwm, [12.0], channels=("pressure",), over={"valve.pwm_frequency": [[20.0], [100.0]]},
                           progress=False)
    from pamjax._sweep.maps import check_below_pwm_nyquist  # the CLI's check before it takes its output folder

    check_below_pwm_nyquist(pwm, [24.9])  # below: accepted
    check_below_pwm_nyquist(presets.mas10_tank_system(valve="averaged"), [50.0, 100.0])  # no switching valve


@pytest.mark.parametrize("call, key", [
    (lambda s: frequency_response(s, [1.0], channels=("pressure",), rtol=1e-9), "rtol"),
    (lambda s: steady_state_map(s, [0.5], atol=1e-9), "atol"),
    (lambda s: steady_state_map(s, [0.5], horizn=1.0), "horizn"),
])
def test_a_keyword_no_map_takes_is_named(call, key):
    """`rtol=1e-9` was a raw `TypeError: sweep() got an unexpected keyword argument`: named, with the arguments the
    map and `sweep` take (and, for a tolerance, where it goes)."""
    match = rf"got the keyword {key}=, which neither it nor pamjax.sweep takes.*its arguments: .*, and for " \
            r"pamjax.sweep: y0, .*method, dt"
    with pytest.raises(pamjax.PamjaxInputError, match=match) as err:
        call(presets.mas10_tank_system(valve="averaged"))
    assert ("solve_options" in str(err.value).split("its arguments")[0]) == (key != "horizn")


@pytest.fixture
def maps_no_sweep(monkeypatch):
    """Reaching the map's sweep is a test failure: the refusal must come first."""
    import functools

    from pamjax._sweep import maps

    @functools.wraps(maps.sweep)  # its signature: the map checks its keywords against sweep's
    def refuse(*args, **kwargs):
        raise AssertionError("the map's sweep was started")

    monkeypatch.setattr(maps, "sweep", refuse)


def test_a_sample_interval_that_aliases_a_pwm_valves_ripple_is_refused(maps_no_sweep):
    """On the 50 Hz valve a sample_interval of 0.01 s put the map 3.4 and 5.4 kPa off at duties 0.2 and 0.4 (0.005
    s: 0.8 and 2.0 kPa), status 0: coarser than 1/20 of the PWM period is refused, saying what to write."""
    pwm = presets.mas10_system(valve="pwm")
    for interval in (0.01, 0.005):
        with pytest.raises(pamjax.PamjaxInputError, match=rf"sample_interval = {interval:g} s is coarser than 1/20 of "
                                                          r"the switching valve's PWM period \(1/\(20 x 50 Hz\) = "
                                                          r"0.001 s\).*Drop sample_interval .* or give at most 0.001"):
            steady_state_map(pwm, [0.2, 0.4], horizon=1.0, window=0.2, sample_interval=interval, progress=False)
    with pytest.raises(AssertionError, match="sweep was started"):  # 1/20 of the period: the map runs
        steady_state_map(pwm, [0.2], horizon=1.0, window=0.2, sample_interval=0.001, progress=False)
    from pamjax._sweep.maps import check_pwm_sampling

    check_pwm_sampling(0.01, 0.0)  # no switching valve: any interval up to the window


def test_a_maps_arguments_of_the_wrong_kind_are_named(maps_no_sweep):
    """A window given as a string was a raw TypeError, NaN among the commands was named over['signal.value'] (the
    map's internal path), and flow_surface without an Air a raw AttributeError."""
    averaged = presets.mas10_system(valve="averaged")
    with pytest.raises(pamjax.PamjaxInputError, match=r"window must be a duration \[s\], a number > 0, got '0.2'"):
        steady_state_map(averaged, [0.2], horizon=1.0, window="0.2", progress=False)
    with pytest.raises(pamjax.PamjaxInputError, match=r"commands must be finite \(no NaN or inf\), got \[0.2 nan\]"):
        steady_state_map(averaged, [0.2, np.nan], horizon=1.0, window=0.2, progress=False)
    with pytest.raises(pamjax.PamjaxInputError, match=r"air must be the gas the valve passes, a pamjax Air .*got None"):
        pamjax.flow_surface(presets.mas10_valve(), [0.5], [2e5], None)
