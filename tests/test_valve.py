"""On/off PWM valve (paper 000 valve section, Table 1) and averaged valve (eq. 13)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import P_ATM, np_ellipse_flow, np_pwm_opening, np_valve_state_machine

import pamjax
from pamjax import presets

AIR = pamjax.Air()
SMOOTH = presets.mas10_valve("smooth")
EXACT = presets.mas10_valve("exact")
T = 0.02  # s, 50 Hz PWM period
PHASES = (np.arange(2000) + 0.5) / 2000 * T  # midpoint samples of one period


# The valve's opening over a batch of times, its cycle average and its flows jitted once per valve mode, the duties
# and pressures as array arguments: called eagerly, every operation of every evaluation would compile a program.
_openings = eqx.filter_jit(lambda valve, ts, duty: jax.vmap(lambda t: valve.opening(t, duty))(ts))
_mean_opening_of = eqx.filter_jit(lambda valve, duty: jnp.mean(_openings(valve, PHASES, duty)))
_cycle_averaged_flow = eqx.filter_jit(pamjax.cycle_averaged_flow)
_averaged_mass_flow = eqx.filter_jit(lambda valve, t, u, p: valve.mass_flow(t, u, p, AIR))


def _mean_opening(valve, duty):
    return float(_mean_opening_of(valve, np.asarray(duty, dtype=float)))


@pytest.mark.parametrize("duty", [0.05, 0.12, 0.3, 0.5, 0.75, 0.88, 0.93])  # off the 10 %/90 % boundaries
def test_opening_matches_numpy_oracle(duty):
    ts = np.linspace(0.0, 3 * T, 601)[:-1] + 1e-7  # three periods, off the exact edges
    exact = np.asarray(_openings(EXACT, ts, np.asarray(duty)))
    smooth = np.asarray(_openings(SMOOTH, ts, np.asarray(duty)))
    np.testing.assert_array_equal(exact, [np_pwm_opening(t, duty) for t in ts])
    np.testing.assert_allclose(smooth, [np_pwm_opening(t, duty, width=1e-4) for t in ts], atol=1e-12)


def test_latched_duty_and_carried_state_match_a_state_machine():
    # Duties that cross the 90 % and 10 % dead-band limits from period to period: a period above 90 % leaves the
    # valve open into the next (its off-pulse is shorter than the switch-off delay), one below 10 % never opens it.
    # The exact mode's opening (duty latched per period, the previous period's duty carried) against a fine-clock
    # state machine of the delays, away from the edges; the smooth mode within its logistic edges.
    duties = np.array([0.3, 0.95, 0.85, 0.93, 0.97, 0.5, 0.05, 0.95, 0.08, 0.6])
    ts = (np.arange(len(duties) * 400) + 0.5) * (T / 400)
    truth = np_valve_state_machine(ts, duties)
    k = np.floor(ts / T + 1e-9).astype(int)
    pairs = np.stack([duties[k], duties[np.maximum(k - 1, 0)] * (k > 0)], axis=1)
    openings = eqx.filter_jit(lambda valve, ts, pairs: jax.vmap(valve.opening)(ts, pairs))  # one program per mode
    exact = np.asarray(openings(EXACT, ts, pairs))
    smooth = np.asarray(openings(SMOOTH, ts, pairs))
    np.testing.assert_array_equal(exact, truth)
    edges = np.concatenate([[kk * T + 2e-3, kk * T + u * T + 2e-3] for kk, u in enumerate(duties)])
    far = np.min(np.abs(ts[:, None] - edges[None, :]), axis=1) > 1e-3  # 10 edge widths from any edge
    np.testing.assert_allclose(smooth[far], truth[far], atol=1e-4)


@pytest.mark.parametrize("valve", [SMOOTH, EXACT], ids=["smooth", "exact"])
def test_dead_band_at_50_hz(valve):
    # Paper 000: the 2 ms switching time leaves only duties 10-90 % effective at 50 Hz. The smooth edges (width
    # 0.1 ms) blur the dead-band limits over ±5 widths = ±2.5 % duty; outside that the valve is shut / open to 1e-3.
    for duty in (0.0, 0.02, 0.05, 0.07):
        assert _mean_opening(valve, duty) < 1e-3
    for duty in (0.93, 0.95, 0.98, 1.0):
        assert _mean_opening(valve, duty) > 1 - 1e-3
    if valve.mode == "exact":
        assert _mean_opening(valve, 0.099) == 0.0 and _mean_opening(valve, 0.901) == 1.0


@pytest.mark.parametrize("valve", [SMOOTH, EXACT], ids=["smooth", "exact"])
def test_cycle_averaged_opening_equals_duty_in_working_range(valve):
    # Equal on/off delays shift the open window but keep its length uT. Exact: midpoint rule error ≤ 1/2000;
    # smooth: logistic edges are symmetric, so their error cancels to < 1e-3.
    for duty in np.linspace(0.15, 0.85, 8):
        assert _mean_opening(valve, duty) == pytest.approx(duty, abs=1e-3 if valve.mode == "smooth" else 5e-4)


def test_mass_flow_and_cycle_average_against_oracle():
    for duty, p in ((0.3, 2e5), (0.6, 4.5e5), (0.5, P_ATM)):
        expected = np.mean(
            [
                np_pwm_opening(t, duty) * np_ellipse_flow(6.5e5, p, 0.36, 0.28, 3.14e-6)
                - (1 - np_pwm_opening(t, duty)) * np_ellipse_flow(p, P_ATM, 0.39, 0.49, 3.14e-6)
                for t in PHASES
            ]
        )
        got = _cycle_averaged_flow(EXACT, np.asarray(duty), np.asarray(p), AIR, samples=2000)
        assert float(got) == pytest.approx(expected, rel=1e-10, abs=1e-15)


def test_averaged_valve_is_eq13_in_gauge_pressure():
    m = np.arange(1, 10) * np.array([1e-4, 1e-9, 1e-15] * 3)
    valve = pamjax.AveragedValve.from_m(m)
    for u, p in ((0.0, P_ATM), (0.3, 2e5), (0.9, 6e5)):
        pg = p - P_ATM
        # eq. 13: m1 + m2 P + m3 P² + m4 u + m5 u P + m6 u P² + m7 u² + m8 u² P + m9 u² P²
        expected = (m[0] + m[1] * pg + m[2] * pg**2 + m[3] * u + m[4] * u * pg + m[5] * u * pg**2
                    + m[6] * u**2 + m[7] * u**2 * pg + m[8] * u**2 * pg**2)
        got = _averaged_mass_flow(valve, np.asarray(0.0), np.asarray(u), np.asarray(p))
        assert float(got) == pytest.approx(expected, rel=1e-13)


_command_for_flow = eqx.filter_jit(
    lambda valve, flows, p: jax.vmap(lambda m: valve.command_for_flow(m, p, AIR))(flows))


def test_command_for_flow_returns_the_duty_nearest_the_flow():
    """Eq. 13's inverse: the increasing root where a duty in [0, 1] reaches the flow, else the duty whose flow comes
    nearest. Above the 6.5 bar supply the preset's outflow peaks inside [0, 1] (-7.609e-4 kg/s at u = 0.951, 7 bar):
    a demand of -7e-4 kg/s is out of reach, and the vertex comes nearer than duty 1 (-7.669e-4 kg/s), which the
    inverse returned."""
    valve = presets.mas10_averaged_valve()
    us = np.linspace(0.0, 1.0, 20001)
    for p in (3e5, 7e5, 8e5):
        flows = np.asarray(_averaged_mass_flow(valve, np.asarray(0.0), us, np.asarray(p)))
        demands = np.concatenate([np.linspace(flows.min() - 2e-4, flows.max() + 2e-4, 9), [-7e-4]])
        duties = np.asarray(_command_for_flow(valve, demands, np.asarray(p)))
        reached = np.asarray(_averaged_mass_flow(valve, np.asarray(0.0), duties, np.asarray(p)))
        assert np.all((duties >= 0.0) & (duties <= 1.0)), duties
        best = np.min(np.abs(flows[:, None] - demands[None, :]), axis=0)  # the dense grid's nearest flow
        # no duty of the grid comes nearer than 1e-10 kg/s (1e-7 of the flows); the grid's step is 3e-8 kg/s
        np.testing.assert_array_less(np.abs(reached - demands), best + 1e-10)
    vertex = float(_command_for_flow(valve, np.asarray([-7e-4]), np.asarray(7e5))[0])
    assert vertex == pytest.approx(0.951, abs=1e-3)


def test_exact_mode_refuses_gradient_with_respect_to_duty():
    with pytest.raises(pamjax.PamjaxInputError, match="exact"):
        jax.grad(lambda u: EXACT.mass_flow(0.005, u, 3e5, AIR))(jnp.asarray(0.5))
    system = presets.mas10_tank_system("exact")
    ts = np.linspace(0.0, 0.04, 3)
    with pytest.raises(pamjax.PamjaxInputError, match="exact"):
        jax.grad(lambda u: pamjax.simulate(system, pamjax.Constant(u), ts).pressure[-1])(jnp.asarray(0.5))
    # The smooth mode differentiates fine with respect to the duty (jitted: an eager grad compiles the solve piecewise).
    smooth = presets.mas10_tank_system("smooth")
    g = jax.jit(jax.grad(lambda u: pamjax.simulate(smooth, pamjax.Constant(u), ts).pressure[-1]))(jnp.asarray(0.5))
    g = np.asarray(g)  # compared on the host (a comparison of the array would compile a program)
    assert np.isfinite(g) and g > 0


@pytest.mark.parametrize("kwargs, match", [
    # 300 Hz with the 2 ms delays: the three steppings gave a tank 650, 124 and 105 kPa (exact/adaptive,
    # smooth/adaptive, exact/pwm), all "succeeded"
    (dict(pwm_frequency=300.0), r"switch_on_delay \(2 ms\) \+ switch_off_delay \(2 ms\) = 4 ms must be shorter than "
                                r"the PWM period 1/pwm_frequency = 3\.33333 ms \(pwm_frequency = 300 Hz\)"),
    # a switch-on delay longer than the 20 ms period: duty 1 never opened the valve
    (dict(switch_on_delay=0.025), r"switch_on_delay \(25 ms\) \+ switch_off_delay \(2 ms\) = 27 ms .* 20 ms"),
    (dict(pwm_frequency=250.0), r"= 4 ms must be shorter than the PWM period 1/pwm_frequency = 4 ms"),  # equal
])
def test_switching_delays_that_outlast_the_pwm_period_are_refused(kwargs, match):
    # The valve's timing (opening, edge_schedule, the PWM grid's open_at_start) takes each period to open or close
    # the valve within itself: t_on + t_off < T. Refused by the constructor, by simulate for a valve changed with
    # eqx.tree_at, and by a sweep for one of its lanes, before anything is compiled.
    for mode in ("smooth", "exact"):
        with pytest.raises(pamjax.PamjaxInputError, match=match + r".*each delay plays out within one period"):
            presets.mas10_valve(mode, **kwargs)
    system = presets.mas10_tank_system("exact")
    fields = tuple(kwargs)
    changed = eqx.tree_at(lambda s: tuple(getattr(s.valve, f) for f in fields), system,
                          tuple(jnp.asarray(v) for v in kwargs.values()))
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        pamjax.simulate(changed, pamjax.Constant(1.0), np.linspace(0.0, 0.3, 31))
    presets.mas10_valve("smooth", pwm_frequency=249.0)  # 4.016 ms > 4 ms: accepted


def test_a_sweep_over_the_pwm_frequency_names_the_lane_whose_period_the_delays_outlast():
    system = presets.mas10_tank_system("smooth")
    over = {"valve.pwm_frequency": np.array([50.0, 100.0, 300.0])}
    with pytest.raises(pamjax.PamjaxInputError, match=r"over\['valve\.pwm_frequency'\]: OnOffValve: .* = 4 ms must be "
                                                       r"shorter than .* 3\.33333 ms .*at index \(2,\)"):
        pamjax.sweep(system, pamjax.Constant(0.5), np.linspace(0.0, 0.1, 11), over, progress=False)


def test_smooth_pwm_trajectory_converges_to_exact_edges():
    # Tank charging at 50 % duty for ~0.1 s (5 periods). The exact-edge solve is the reference (jump times handed to
    # the solver). Compared half-way between edges (edges at 2 ms and 12 ms of each period): symmetric logistic edges
    # then leave an O(w²) error. Tolerance: at the default w = 1e-4 s the max error must be < 100 Pa
    # (2.5e-4 of the ~4e5 Pa reached) and it must fall at least 3× per 4× smaller width.
    ts = np.concatenate([np.zeros(1), 0.007 + 0.01 * np.arange(10)])
    kw = dict(rtol=1e-9, atol=1e-9)
    ref = np.asarray(pamjax.simulate(presets.mas10_tank_system("exact"), pamjax.Constant(0.5), ts, **kw).pressure)
    errors = []
    for width in (4e-4, 1e-4, 2.5e-5):
        system = presets.mas10_tank_system(presets.mas10_valve("smooth", edge_width=width))
        p = np.asarray(pamjax.simulate(system, pamjax.Constant(0.5), ts, **kw).pressure)
        errors.append(np.max(np.abs(p - ref)))
    print("max |p_smooth - p_exact| [Pa] for w = 4e-4, 1e-4, 2.5e-5 s:", errors)
    assert errors[0] > 3 * errors[1] > 9 * errors[2]
    assert errors[1] < 100.0, errors


def test_fit_averaged_valve_reports_quality():
    fitted, report = pamjax.fit_averaged_valve(EXACT, AIR, np.linspace(0, 1, 11), np.linspace(P_ATM, 6.5e5, 11))
    assert isinstance(fitted, pamjax.AveragedValve)
    assert 0 < report["rmse_percent"] < report["max_error_percent"] < 30


@pytest.mark.parametrize("grid, match", [
    (dict(pressures=np.linspace(1.01325, 6.5, 21)), r"pressures is 6.5 Pa at most: that looks like bar"),
    (dict(pressures=np.linspace(0.0, 5.487e5, 21)), r"pressures drops to 0 Pa, .* GAUGE pressure"),
    (dict(pressures=np.array([P_ATM])), r"pressures must hold at least two distinct pressures above atmosphere"),
    (dict(pressures=np.array([P_ATM, 3e5, 3e5])), r"pressures must hold at least two distinct pressures"),
    (dict(pressures=np.array([np.nan, 3e5, 4e5])), r"pressures must be finite"),
    (dict(pressures=np.ones((3, 3)) * 3e5), r"pressures must be a 1-D, non-empty grid, got shape \(3, 3\)"),
    (dict(commands=np.linspace(0.0, 100.0, 21)), r"commands must lie within the valve's command range \[0, 1\] .* "
                                                 r"got \[0, 100\]; that looks like percent"),
    (dict(commands=np.linspace(-1.0, 1.0, 21)), r"commands must lie within .* got \[-1, 1\]"),
    (dict(commands=np.array([])), r"commands must be a 1-D, non-empty grid, got shape \(0,\)"),
    (dict(commands=np.ones((3, 3)) * 0.5), r"commands must be a 1-D, non-empty grid, got shape \(3, 3\)"),
    (dict(commands=np.array([0.5, np.inf])), r"commands must be finite"),
    (dict(commands=[0.3, 0.6]), r"commands must hold at least three distinct duties: eq. 13 is quadratic"),
    (dict(commands=[0.5, 0.5, 0.5]), r"commands must hold at least three distinct duties"),
])
def test_fit_averaged_valve_refuses_a_grid_in_other_units_by_name(grid, match):
    # bar, gauge pressures, percent or ±1 commands were fitted silently, and fewer than three distinct duties
    # (eq. 13 underdetermined in u); NaN, one pressure at atmosphere, an empty or a 2-D grid gave unnamed or raw
    # errors. Refused before anything is computed.
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        pamjax.fit_averaged_valve(EXACT, AIR, **grid)


def test_fit_averaged_valve_refuses_a_valve_that_does_not_switch_before_reading_its_supply():
    # the default pressure grid read valve.supply_pressure first: a raw AttributeError for an AveragedValve
    with pytest.raises(pamjax.PamjaxInputError, match=r"valve: fit_averaged_valve fits eq\. 13 to the cycle average.*"
                                                      r"AveragedValve does not switch"):
        pamjax.fit_averaged_valve(presets.mas10_averaged_valve(), AIR)


@pytest.mark.parametrize("width, frequency", [(0.1, 50.0), (2e-3, 50.0), (3e-4, 249.0)])
def test_an_edge_width_not_well_below_the_pwm_period_is_refused(width, frequency):
    # edge_width = 0.1 (0.1 ms typed in s) passed: the magnitude check let anything up to 0.1 s through, and a
    # logistic edge of 100 ms smears a 20 ms period's switching into a constant half-open valve. An edge is at most
    # 5 % of the period (1 ms at 50 Hz): refused by the constructor and, set with eqx.tree_at, before the solve.
    match = r"OnOffValve\.edge_width \(.* s = .* ms\) must not exceed 5% of the PWM period"
    for mode in ("smooth", "exact"):
        with pytest.raises(pamjax.PamjaxInputError, match=match):
            presets.mas10_valve(mode, edge_width=width, pwm_frequency=frequency)
    changed = eqx.tree_at(lambda s: s.valve.edge_width, presets.mas10_tank_system(), width)
    changed = eqx.tree_at(lambda s: s.valve.pwm_frequency, changed, frequency)
    with pytest.raises(pamjax.PamjaxInputError, match=match + (r".*looks like ms" if width == 0.1 else "")):
        pamjax.simulate(changed, pamjax.Constant(0.25), np.linspace(0.0, 0.1, 3))
    presets.mas10_valve("smooth", edge_width=4e-4)  # 2 % of 20 ms (the convergence test's widest): accepted
    presets.mas10_valve("smooth", pwm_frequency=249.0)  # the default 1e-4 s at the fastest PWM the delays allow


def test_the_smooth_opening_stays_within_0_and_1_with_unequal_delays():
    # A 2 ms switch-on and a zero switch-off delay: a pulse just short of 2 ms (duty ~0.1) half-opens the valve
    # through the smooth gate while its off edge u T + t_off comes before the on edge t_on; the sum of logistic
    # steps dipped to -0.055 (flow reversed through the supply path) between the two edges.
    valve = presets.mas10_valve("smooth", switch_on_delay=2e-3, switch_off_delay=0.0)
    ts = np.linspace(0.0, T, 2001)
    for duty in np.linspace(0.07, 0.13, 25):
        for previous in (0.0, 0.5, 1.0):
            o = np.asarray(_openings(valve, ts, np.array([duty, previous])))
            assert o.min() >= 0.0 and o.max() <= 1.0, (duty, previous, o.min(), o.max())


def test_a_zero_length_pulse_switches_nothing_with_zero_delays():
    # switch_on_delay = 0 (accepted) opened the valve at duty 0 in every period: the gate u T - t_on >= 0 held for a
    # zero-length pulse (exact: open, smooth: half open, a tank at duty 0 charged to supply); with both delays 0 the
    # smooth opening at duty 1 dipped to 0.75 at each period end. Duty 0 must never open it, duty 1 never close it.
    ts = np.linspace(0.0, 2 * T, 401)
    for mode in ("smooth", "exact"):
        valve = presets.mas10_valve(mode, switch_on_delay=0.0, switch_off_delay=0.0)
        assert not bool(valve.switching_gates(0.0)[0]) and not bool(valve.switching_gates(1.0)[1])
        np.testing.assert_array_equal(np.asarray(_openings(valve, ts, np.asarray(0.0))), 0.0)
        np.testing.assert_array_equal(np.asarray(_openings(valve, ts, np.asarray(1.0))), 1.0)
    edges, _ = presets.mas10_valve("exact", switch_on_delay=0.0).edge_schedule(pamjax.Constant(0.0), 0.0, 0.1)
    assert edges.size == 0


def test_cycle_averaged_flow_is_elementwise_in_duty_and_pressure():
    # jnp.mean over every axis: an array of pressures or duties returned ONE number, the mean of the right ones
    p, u = np.array([1.5e5, 3e5, 6e5]), np.array([0.25, 0.5, 0.75])
    flows = np.asarray(_cycle_averaged_flow(SMOOTH, u[:, None], p[None, :], AIR, samples=200))
    assert flows.shape == (3, 3)
    each = [[float(_cycle_averaged_flow(SMOOTH, np.asarray(ui), np.asarray(pi), AIR, samples=200)) for pi in p]
            for ui in u]
    np.testing.assert_allclose(flows, each, rtol=1e-12)


@pytest.mark.parametrize("kwargs, match", [
    (dict(command=50.0), r"command must lie in \[0\.0, 1\.0\] .*got \[50\.\]; that looks like percent"),
    (dict(command=-0.5), r"command must lie in \[0\.0, 1\.0\]"),
    (dict(pressure=3.0), r"pressure is 3 Pa at most: that looks like bar"),
    (dict(pressure=float("nan")), r"pressure \(absolute\) \[Pa\] must be > 0 and finite"),
    (dict(samples=0), r"samples must be a positive integer"),
    (dict(valve=presets.mas10_averaged_valve()), r"valve: the cycle average is a switching valve's flow .*"
     r"AveragedValve does not switch"),
    # 3 duties beside 2 pressures: a raw broadcasting ValueError
    (dict(command=np.array([0.2, 0.3, 0.5]), pressure=np.array([2e5, 3e5])),
     r"cycle_averaged_flow: command of shape \(3,\) and pressure of shape \(2,\) do not broadcast"),
])
def test_cycle_averaged_flow_refuses_what_flow_surface_refuses(kwargs, match):
    # duty 50 (percent) gave duty 1's flow, a pressure in bar or NaN a number, an averaged valve a raw TypeError
    args = {**dict(valve=SMOOTH, command=0.5, pressure=3e5, samples=400), **kwargs}
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        pamjax.cycle_averaged_flow(args["valve"], args["command"], args["pressure"], AIR, samples=args["samples"])


@pytest.mark.parametrize("args, match", [
    ((float("nan"), 3e5), r"equivalent_duty: mass_flow must be finite"),
    ((1e-3, float("nan")), r"equivalent_duty: pressure \(absolute\) \[Pa\] must be > 0 and finite"),
    ((1e-3, 3.0), r"equivalent_duty: pressure is 3 Pa at most: that looks like bar"),
    # 3 flows beside 2 pressures: a raw TypeError
    ((np.array([1e-3, 2e-3, 0.0]), np.array([3e5, 4e5])),
     r"equivalent_duty: mass_flow of shape \(3,\) and pressure of shape \(2,\) do not broadcast"),
])
def test_equivalent_duty_refuses_nan_and_bar(args, match):
    # a NaN flow or pressure gave duty 0.0, a pressure in bar the duty for 3 Pa abs
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        pamjax.equivalent_duty(presets.mas10_averaged_valve(), *args, AIR)
    with pytest.raises(pamjax.PamjaxInputError, match=r"equivalent_duty: valve must be an averaged valve .*got "
                                                       r"OnOffValve"):  # a raw AttributeError (no command_for_flow)
        pamjax.equivalent_duty(SMOOTH, 1e-3, 3e5, AIR)


@pytest.mark.parametrize("kwargs, match", [
    (dict(inflate=0.36), r"OnOffValve\.inflate must be an AbstractRestriction .*got float"),
    (dict(inflate=None), r"OnOffValve\.inflate must be an AbstractRestriction .*got NoneType"),
    (dict(exhaust="silencer"), r"OnOffValve\.exhaust must be an AbstractRestriction .*got str"),
])
def test_on_off_valve_refuses_a_path_that_is_no_restriction(kwargs, match):
    # a number, None or a string was accepted and the solve died with a raw AttributeError naming no argument
    port = pamjax.EllipseRestriction(0.39, 0.49, 3.14e-6)
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        pamjax.OnOffValve(**{**dict(inflate=port, exhaust=port), **kwargs})
