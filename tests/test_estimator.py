"""The state estimator (`pamjax._control.estimator`: `ExtendedKalmanFilter` on paper 000's discrete-time model, eq.
18-21) and the noisy sensors of the closed loop.

Oracles: a textbook Kalman filter in NumPy (SI units, no scaling) on a linear system, which the extended filter must
reproduce exactly; the true states of a simulated plant with exact stick-slip and exact valve edges (the filter's
averaged model is not that plant: its errors must stay below the sensors' noise and grow with it); central finite
differences for a gradient through the filter. Horizons are short (2 s offline, 1.5 s in the loop).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import initial_state

import pamjax as pj
from pamjax import presets

PLANT = presets.mas10_system("pwm", friction="karnopp")  # the identified plant: exact edges, stick-slip
MODEL = presets.mas10_system("averaged")  # the filter's and the SMC's model (paper 000: eq. 13 valve)
BENCH_NOISE = np.array([2e3, 1e-4])  # Pa, m: the hybrid bench's sensors (meta.json)
CHANNELS = ("pressure", "position")


# --- a linear system for the textbook comparison ---------------------------------------------------------------------
class _LinearState(eqx.Module):
    pressure: jax.Array
    position: jax.Array
    velocity: jax.Array


class _Command(pj.AbstractControlElement):
    """A command passed through as it is (the linear system's input)."""


class _LinearSystem(pj.AbstractSystem):
    """ẏ = A y + b u on a (pressure, position, velocity) state; its discrete model is explicit Euler."""

    a: jax.Array
    b: jax.Array
    valve: pj.AbstractControlElement = eqx.field(default_factory=_Command)
    air: pj.Air = eqx.field(default_factory=pj.Air)

    def initial_state(self):
        return _LinearState(jnp.zeros(()), jnp.zeros(()), jnp.zeros(()))

    def vector_field(self, t, state, command):
        y = jnp.stack([state.pressure, state.position, state.velocity])
        dy = self.a @ y + self.b * command
        return _LinearState(dy[0], dy[1], dy[2])

    def outputs(self, t, state, command):
        return dict(pressure=state.pressure, position=state.position, velocity=state.velocity)

    def state_scale(self):
        return _LinearState(jnp.asarray(1e5), jnp.asarray(1e-2), jnp.asarray(1e-2))


def numpy_kalman(f, g, h, q, r, m0, p0, commands, readings):
    """The textbook Kalman filter (predict, then update), in SI units: x' = F x + G u + w, y = H x + v."""
    m, p, means, covs = m0.copy(), p0.copy(), [], []
    for u, y in zip(commands, readings):
        m, p = f @ m + g * u, f @ p @ f.T + q
        s = h @ p @ h.T + r
        k = p @ h.T @ np.linalg.inv(s)
        m = m + k @ (y - h @ m)
        p = (np.eye(len(m)) - k @ h) @ p
        means.append(m.copy())
        covs.append(p.copy())
    return np.array(means), np.array(covs)


def test_linear_case_is_the_textbook_kalman_filter():
    rng = np.random.default_rng(1)
    scale = np.diag([1e5, 1e-2, 1e-2])
    a = scale @ np.array([[-3.0, -1.0, 0.5], [0.0, 0.0, 1.0], [2.0, -40.0, -4.0]]) @ np.linalg.inv(scale)
    b = np.array([2e5, 0.0, 1e-1])
    system = _LinearSystem(a=jnp.asarray(a), b=jnp.asarray(b))
    q = dict(pressure=3e4, position=1e-4, velocity=0.02)
    std0 = dict(pressure=1e4, position=5e-3, velocity=1e-2)
    ekf = pj.ExtendedKalmanFilter(system, process_noise=q, initial_std=std0)
    dt, n = 1e-3, 300
    commands = 0.5 + 0.4 * np.sin(np.arange(n) * dt * 7.0)
    f, g, hm = np.eye(3) + dt * a, dt * b, np.array([[1.0, 0, 0], [0, 1.0, 0]])
    x, readings = np.zeros(3), []
    for u in commands:  # a noisy truth
        x = f @ x + g * u + rng.normal(0, 1, 3) * np.array([3e4, 1e-4, 0.02]) * np.sqrt(dt)
        readings.append(hm @ x + rng.normal(0, 1, 2) * BENCH_NOISE)
    readings = np.array(readings)
    signal = pj.Sampled(np.arange(n) * dt, commands)
    means, stds, final = eqx.filter_jit(ekf.filter)(signal, readings, dt, CHANNELS, BENCH_NOISE)
    q_si = np.diag(np.array([3e4, 1e-4, 0.02]) ** 2 * dt)
    m_np, p_np = numpy_kalman(f, g, hm, q_si, np.diag(BENCH_NOISE**2), np.zeros(3),
                              np.diag(np.array([1e4, 5e-3, 1e-2]) ** 2), commands, readings)
    got = np.stack([means.pressure, means.position, means.velocity], axis=-1)
    # Same algebra in other coordinates (scaled states, normalised readings, Joseph form): agreement to rounding.
    for j in range(3):  # per state, relative to its own magnitude
        np.testing.assert_allclose(got[:, j], m_np[:, j], rtol=1e-9, atol=1e-9 * np.abs(m_np[:, j]).max())
    np.testing.assert_allclose(np.asarray(ekf.covariance(final)), p_np[-1], rtol=1e-8,
                               atol=1e-10 * np.abs(p_np[-1]).max())
    np.testing.assert_allclose(np.asarray(stds.velocity), np.sqrt(p_np[:, 2, 2]), rtol=1e-8)


@pytest.fixture(scope="module")
def triangle_run():
    """The identified plant (exact edges, stick-slip) under a 0.5 Hz duty triangle, 2 s at 1 kHz: stick at both
    ends, 60 mm of travel between."""
    signal = pj.Triangle(0.05, 0.95, 0.5)
    ts = np.arange(0.0, 2.0005, 1e-3)
    return signal, pj.simulate(PLANT, signal, ts)


_filter = eqx.filter_jit(lambda ekf, signal, readings, noise: ekf.filter(signal, readings, 1e-3, CHANNELS, noise))


def _errors(ekf, signal, traj, noise, seed=0):
    rng = np.random.default_rng(seed)
    truth = np.c_[traj.pressure[1:], traj.position[1:]]
    readings = truth + noise * rng.standard_normal(truth.shape)
    est, std, _ = _filter(ekf, signal, readings, noise)
    window = slice(100, None)  # after the first 0.1 s (the initial belief is 5 mm wide)
    errors = {k: (np.asarray(getattr(est, k)) - np.asarray(getattr(traj, k))[1:])[window]
              for k in ("pressure", "position", "velocity")}
    return errors, {k: np.asarray(getattr(std, k))[window] for k in errors}


def test_estimation_error_on_the_stick_slip_plant_is_below_the_noise_and_grows_with_it(triangle_run):
    """The filter's model (averaged valve, smooth sign) is not the plant; still, with the bench's noise its position
    error is a fraction of the sensor's (measured 22 µm against 100 µm), its velocity error ~1 mm/s (a difference
    quotient of the readings: 141 mm/s), and the errors grow with the noise (measured 9 / 22 / 65 µm at 0.25 / 1 / 4
    × the bench's noise). The filter's own standard deviations cover its errors (≥ 97 % within 3σ, measured
    ≥ 98.4 %)."""
    signal, traj = triangle_run
    ekf = pj.ExtendedKalmanFilter(MODEL)
    rms = {}
    for level in (0.25, 1.0, 4.0):
        errors, stds = _errors(ekf, signal, traj, level * BENCH_NOISE)
        rms[level] = {k: float(np.sqrt(np.mean(e**2))) for k, e in errors.items()}
        assert rms[level]["position"] < 0.5 * level * BENCH_NOISE[1], rms
        assert rms[level]["pressure"] < 2.0 * level * BENCH_NOISE[0], rms
        for k in errors:
            assert np.mean(np.abs(errors[k]) < 3 * stds[k]) > 0.97, (level, k)
    assert rms[1.0]["velocity"] < 3e-3, rms
    assert rms[0.25]["position"] < rms[1.0]["position"] < rms[4.0]["position"], rms
    assert rms[0.25]["velocity"] < rms[4.0]["velocity"], rms


def test_gradient_through_the_filter_matches_finite_difference(triangle_run):
    """d(velocity error²)/d(log q_v) through the whole filter (reverse mode) against a central difference (rel.
    1e-5: the filter is smooth in its settings)."""
    signal, traj = triangle_run
    rng = np.random.default_rng(3)
    truth = np.c_[traj.pressure[1:], traj.position[1:]]
    readings = truth + BENCH_NOISE * rng.standard_normal(truth.shape)
    velocity = np.asarray(traj.velocity)[1:]

    @jax.jit
    def loss(log_qv):
        ekf = pj.ExtendedKalmanFilter(MODEL, process_noise=dict(pressure=1.5e5, position=1e-4,
                                                                velocity=jnp.exp(log_qv)))
        est, _, _ = ekf.filter(signal, readings, 1e-3, CHANNELS, BENCH_NOISE)
        return jnp.mean((est.velocity - velocity) ** 2)

    x0 = np.log(0.02)
    grad = float(jax.grad(loss)(x0))
    h = 1e-4
    fd = (float(loss(x0 + h)) - float(loss(x0 - h))) / (2 * h)
    assert abs(grad - fd) <= 1e-5 * abs(fd), (grad, fd)


def test_sliding_mode_with_estimator_tracks_with_the_bench_noise():
    """The SMC fed by the filter from 2 kPa / 0.1 mm readings at 1 kHz on the identified plant, from the pressure
    for 30 mm (the filter told where it starts): it tracks the 1 rad/s sine better than the paper's PI with the same
    potentiometer noise, and the estimate it reads is better than a raw reading."""
    y0 = initial_state(PLANT, pressure=np.asarray(4.3e5))
    start = initial_state(MODEL, pressure=np.asarray(4.3e5))
    ref = pj.Sine(0.03, 0.01, 1.0 / (2 * np.pi))
    smc = pj.ClosedLoop(PLANT, pj.SlidingModeController(MODEL), ref, estimator=pj.ExtendedKalmanFilter(MODEL))
    traj = pj.simulate_closed_loop(smc, 1.5, y0=smc.initial_state(y0, estimate=start))
    pi = pj.ClosedLoop(PLANT, pj.PIDController(measurement_noise=1e-4), ref)
    traj_pi = pj.simulate_closed_loop(pi, 1.5, y0=pi.initial_state(y0))
    assert int(traj.result) == 0 and int(traj_pi.result) == 0
    rmse = float(traj.tracking_error(0.5)[0])
    assert rmse < 0.5 * float(traj_pi.tracking_error(0.5)[0])
    errors = traj.estimation_error(0.5)
    assert float(errors["position"]) < 0.5 * BENCH_NOISE[1] and float(errors["velocity"]) < 5e-3, errors
    # the sensors are seeded: the same loop gives the same run, another seed another (similar) one
    again = pj.simulate_closed_loop(smc, 1.5, y0=smc.initial_state(y0, estimate=start))
    np.testing.assert_array_equal(np.asarray(again.duty), np.asarray(traj.duty))
    other = eqx.tree_at(lambda lp: lp.sensors, smc, pj.LoopSensors(seed=1))
    traj_other = pj.simulate_closed_loop(other, 1.5, y0=other.initial_state(y0, estimate=start))
    assert not np.array_equal(np.asarray(traj_other.duty), np.asarray(traj.duty))
    assert abs(float(traj_other.tracking_error(0.5)[0]) - rmse) < 0.5 * rmse


def test_noise_free_sensors_and_no_estimator_read_the_true_state():
    """Without an estimator the controller reads the plant's true state (`observed` is the state at the period
    start)."""
    loop = pj.ClosedLoop(PLANT, pj.PIController(), pj.Sine(0.03, 0.01, 0.2))
    traj = pj.simulate_closed_loop(loop, 0.1)
    np.testing.assert_array_equal(np.asarray(traj.observed.position), np.asarray(traj.period_start_state.position))
    assert all(float(v) == 0.0 for v in traj.estimation_error().values())


def test_bad_estimator_and_sensor_input_raises():
    ref = pj.Sine(0.03, 0.01, 0.2)
    with pytest.raises(pj.PamjaxInputError, match="hybrid"):
        pj.ExtendedKalmanFilter(PLANT)
    with pytest.raises(pj.PamjaxInputError, match="unknown state"):
        pj.ExtendedKalmanFilter(MODEL, process_noise=dict(temperature=1.0))
    with pytest.raises(pj.PamjaxInputError, match="process_noise"):
        pj.ExtendedKalmanFilter(MODEL, process_noise=dict(pressure=-1.0))
    with pytest.raises(pj.PamjaxInputError, match="channel"):
        pj.LoopSensors(channels=("pressure",), noise=(2e3, 1e-4))
    with pytest.raises(pj.PamjaxInputError, match="states of the plant"):
        pj.ClosedLoop(PLANT, pj.PIController(), ref, estimator=pj.ExtendedKalmanFilter(MODEL),
                      sensors=pj.LoopSensors(channels=("force",), noise=(1.0,)))
    with pytest.raises(pj.PamjaxInputError, match="estimator"):
        pj.ClosedLoop(PLANT, pj.PIController(), ref, sensors=pj.LoopSensors())
    with pytest.raises(pj.PamjaxInputError, match="measurement_noise"):
        pj.ClosedLoop(PLANT, pj.PIController(), ref, estimator=pj.ExtendedKalmanFilter(MODEL),
                      sensors=pj.LoopSensors(noise=(0.0, 0.0)))
    with pytest.raises(pj.PamjaxInputError, match="samples_per_period"):
        pj.LoopSensors(samples_per_period=0)


def test_measurement_noise_must_match_the_sensor_channels():
    """`measurement_noise=[2e3]` with the two default channels was broadcast (2 km of noise on the position) and
    three values failed at run time with a raw TypeError; a 2-D or scalar one was taken too. The loop, which knows the
    sensors, refuses another length; the filter refuses any shape but 1-D."""
    ref = pj.Sine(0.03, 0.01, 0.2)
    for noise in ([2e3], [2e3, 1e-4, 1.0]):
        ekf = pj.ExtendedKalmanFilter(MODEL, measurement_noise=noise)
        with pytest.raises(pj.PamjaxInputError, match=r"measurement_noise must have one σ_R per sensor channel "
                                                      r"\('pressure', 'position'\)"):
            pj.ClosedLoop(PLANT, pj.SlidingModeController(MODEL), ref, estimator=ekf)
    pj.ClosedLoop(PLANT, pj.SlidingModeController(MODEL), ref,  # one channel, one value
                  estimator=pj.ExtendedKalmanFilter(MODEL, measurement_noise=[1e4]),
                  sensors=pj.LoopSensors(channels=("pressure",), noise=(2e3,)))
    for noise in (2e3, [[2e3, 1e-4]], []):
        with pytest.raises(pj.PamjaxInputError, match="measurement_noise must be a 1-D array"):
            pj.ExtendedKalmanFilter(MODEL, measurement_noise=noise)


@pytest.mark.parametrize("substeps", [0, -1, 2.5, True])
def test_substeps_must_be_a_positive_int(substeps):
    """0 divided by zero in `predict`, -1 made it the identity (no prediction at all), 2.5 ran with 2 steps of T/2.5."""
    with pytest.raises(pj.PamjaxInputError, match="substeps must be an int >= 1"):
        pj.ExtendedKalmanFilter(MODEL, substeps=substeps)


_short_filter = eqx.filter_jit(lambda ekf, noise: ekf.filter(pj.Constant(0.6), np.tile([1.5e5, 1e-3], (3, 1)), 1e-3,
                                                             CHANNELS, noise))


def test_filter_uses_its_noise_argument_over_measurement_noise():
    """`filter(..., noise=...)` was ignored where `measurement_noise` was set (the docstring: `noise` defaults to
    `measurement_noise`); the argument given wins, so 100× the noise weights the readings less: a larger spread."""
    ekf = pj.ExtendedKalmanFilter(MODEL, measurement_noise=BENCH_NOISE)
    _, std, _ = _short_filter(ekf, BENCH_NOISE)
    _, std_wide, _ = _short_filter(ekf, 100 * BENCH_NOISE)
    assert float(std_wide.position[-1]) > 10 * float(std.position[-1]), (std_wide.position, std.position)
    _, std_default, _ = ekf.filter(pj.Constant(0.6), np.tile([1.5e5, 1e-3], (3, 1)), 1e-3, CHANNELS)
    np.testing.assert_allclose(np.asarray(std_default.position), np.asarray(std.position), rtol=1e-12)


def test_filter_refuses_bad_noise_sample_time_and_channels():
    """Zeros gave NaN estimates, negative noise and a sample time <= 0 ran, a wrong length or an unknown channel
    failed with raw TypeError / AttributeError. Each refused, naming the argument, before filtering."""
    ekf = pj.ExtendedKalmanFilter(MODEL)
    readings = np.tile([1.5e5, 0.0], (4, 1))
    signal = pj.Constant(0.6)
    cases = [
        (dict(noise=[2e3, 1e-4, 5.0]), r"filter: noise must have one σ_R per sensor channel"),
        (dict(noise=[2e3]), r"filter: noise must have one σ_R per sensor channel"),
        (dict(noise=[0.0, 1e-4]), r"filter: noise must be > 0"),
        (dict(noise=[-2e3, 1e-4]), r"filter: noise must be > 0"),
        (dict(noise=[np.inf, 1e-4]), r"filter: noise must be finite"),
        (dict(noise=BENCH_NOISE, sample_time=0.0), r"filter: sample_time must be > 0"),
        (dict(noise=BENCH_NOISE, sample_time=-1e-3), r"filter: sample_time must be > 0"),
        (dict(noise=BENCH_NOISE, channels=("pressure", "force")), r"filter: channels \['force'\] are not states"),
        (dict(noise=BENCH_NOISE[:1], channels="pressure"), r"filter: channels must be a non-empty tuple"),
    ]
    for kwargs, match in cases:
        args = dict(sample_time=1e-3, channels=CHANNELS) | kwargs
        with pytest.raises(pj.PamjaxInputError, match=match):
            ekf.filter(signal, readings, **args)
    with pytest.raises(pj.PamjaxInputError, match="measurement_noise must have one σ_R"):  # the default checked too
        pj.ExtendedKalmanFilter(MODEL, measurement_noise=[2e3]).filter(signal, readings, 1e-3, CHANNELS)


def test_filter_refuses_a_signal_simulate_refuses():
    """A duty triangle of 20-80 (meant in percent) was filtered as a valve held open (final pressure 239 kPa against
    102 kPa at 0.2-0.8) and a number for a signal failed with a raw TypeError; `simulate`'s check of the signal
    against the valve names both."""
    ekf = pj.ExtendedKalmanFilter(MODEL)
    readings = np.tile([1.5e5, 0.0], (4, 1))
    with pytest.raises(pj.PamjaxInputError, match=r"filter: signal .* must stay within \[0\.0, 1\.0\].* looks like "
                                                  r"percent"):
        ekf.filter(pj.Triangle(20.0, 80.0, 1.0), readings, 1e-3, CHANNELS, BENCH_NOISE)
    with pytest.raises(pj.PamjaxInputError, match=r"filter: signal must be a pamjax signal"):
        ekf.filter(0.5, readings, 1e-3, CHANNELS, BENCH_NOISE)


_gap_filter = eqx.filter_jit(lambda ekf, readings: ekf.filter(pj.Constant(0.6), readings, 1e-3, CHANNELS,
                                                               BENCH_NOISE))


def test_a_nan_reading_is_a_missing_sample_and_the_start_must_be_finite():
    """One NaN reading (a dropped sample) turned 40 of 50 later estimates NaN, silently; it is now skipped: the
    estimates stay finite, those before it unchanged, the pressure's spread grows at the gap and the position still
    updates there. A t0 or an initial mean that is not finite, or an infinite reading, is refused, named."""
    ekf = pj.ExtendedKalmanFilter(MODEL)
    clean = np.tile([1.2e5, -0.004], (12, 1)) + np.outer(np.arange(12), [1e3, 1e-4])
    gap = clean.copy()
    gap[5, 0] = np.nan
    est, std, _ = _gap_filter(ekf, clean)
    est_gap, std_gap, final = _gap_filter(ekf, gap)
    assert all(np.all(np.isfinite(np.asarray(getattr(est_gap, k)))) for k in ("pressure", "position", "velocity"))
    np.testing.assert_array_equal(np.asarray(est_gap.pressure)[:5], np.asarray(est.pressure)[:5])
    assert float(std_gap.pressure[5]) > 1.2 * float(std.pressure[5])
    assert abs(float(est_gap.position[5]) - float(est.position[5])) < 1e-6  # its own reading still used
    assert np.all(np.isfinite(np.asarray(final.covariance)))
    signal = pj.Constant(0.6)
    with pytest.raises(pj.PamjaxInputError, match=r"filter: t0 must be finite"):
        ekf.filter(signal, clean, 1e-3, CHANNELS, BENCH_NOISE, t0=np.nan)
    bad = clean.copy()
    bad[7, 1] = np.inf
    with pytest.raises(pj.PamjaxInputError, match=r"filter: readings\[7, 1\] \(position\) is inf"):
        ekf.filter(signal, bad, 1e-3, CHANNELS, BENCH_NOISE)
    with pytest.raises(pj.PamjaxInputError, match=r"initial_state: mean.pressure must be finite"):
        ekf.initial_state(jax.tree_util.tree_map(lambda a: a * np.nan, MODEL.initial_state()))


def test_bad_shapes_and_types_of_the_filters_inputs_are_named():
    """Each of these failed with a raw TypeError / ValueError (or, a negative-definite covariance, ran): now a
    `PamjaxInputError` naming the argument, before filtering."""
    ekf = pj.ExtendedKalmanFilter(MODEL)
    belief = ekf.initial_state()
    readings = np.tile([1.5e5, 0.0], (4, 1))
    signal = pj.Constant(0.6)
    cases = [
        (dict(initial=pj.KalmanState(belief.mean, np.eye(2))), r"initial.covariance must have shape \(3, 3\)"),
        (dict(initial=pj.KalmanState(np.zeros(2), belief.covariance)), r"initial.mean must have shape \(3,\)"),
        (dict(initial=pj.KalmanState(belief.mean, -belief.covariance)),
         r"initial.covariance must be symmetric positive semi-definite"),
        (dict(sample_time=[1e-3, 1e-3]), r"filter: sample_time must be one number"),
        (dict(noise=[0.02, 1e-4]), r"filter: noise\['pressure'\] = 0\.02 Pa is below 1 Pa"),  # bar
        (dict(noise=[2e3, 0.1]), r"filter: noise\['position'\] = 0\.1 m is 1\.1 of the muscle's whole stroke"),
    ]
    for kwargs, match in cases:
        args = dict(sample_time=1e-3, noise=BENCH_NOISE) | kwargs
        with pytest.raises(pj.PamjaxInputError, match=match):
            ekf.filter(signal, readings, channels=CHANNELS, **args)
    with pytest.raises(pj.PamjaxInputError, match=r"process_noise\['pressure'\] must be one value .* got shape \(2,\)"):
        pj.ExtendedKalmanFilter(MODEL, process_noise=dict(pressure=[1e5, 2e5]))
    with pytest.raises(pj.PamjaxInputError, match=r"measurement_noise must be numbers, got 'abc'"):
        pj.ExtendedKalmanFilter(MODEL, measurement_noise="abc")
    with pytest.raises(pj.PamjaxInputError, match=r"initial_state: mean must be a state of the filter's model"):
        ekf.initial_state(dict(pressure=2e5))


@pytest.mark.parametrize("kwargs, match", [
    (dict(seed=1.5), r"LoopSensors.seed must be an integer"),  # was truncated to 1
    (dict(seed="a"), r"LoopSensors.seed must be an integer"),
    (dict(samples_per_period=True), r"samples_per_period must be an int >= 1"),
    (dict(noise=(0.02, 1e-4)), r"LoopSensors.noise\['pressure'\] = 0\.02 Pa is below 1 Pa"),  # bar
])
def test_loop_sensors_refuse_a_fractional_seed_a_bool_count_and_a_noise_in_bar(kwargs, match):
    with pytest.raises(pj.PamjaxInputError, match=match):
        pj.LoopSensors(**kwargs)
    assert int(pj.LoopSensors(seed=np.int64(3)).seed) == 3 and int(pj.LoopSensors(seed=2.0).seed) == 2


def test_a_loop_refuses_sensor_and_filter_noise_in_mm():
    """LoopSensors(noise=(2e3, 0.1)): 0.1 m of position noise, more than the stroke (0.1 meant in mm), ran; so did a
    filter's measurement_noise of [2e3, 0.1]. The loop knows the plant's stroke: refused, naming each table."""
    ref = pj.Sine(0.03, 0.01, 0.2)
    with pytest.raises(pj.PamjaxInputError, match=r"LoopSensors.noise\['position'\] = 0.1 m"):
        pj.ClosedLoop(PLANT, pj.SlidingModeController(MODEL), ref, estimator=pj.ExtendedKalmanFilter(MODEL),
                      sensors=pj.LoopSensors(noise=(2e3, 0.1)))
    with pytest.raises(pj.PamjaxInputError, match=r"ExtendedKalmanFilter.measurement_noise\['position'\] = 0.1 m"):
        pj.ClosedLoop(PLANT, pj.SlidingModeController(MODEL), ref,
                      estimator=pj.ExtendedKalmanFilter(MODEL, measurement_noise=[2e3, 0.1]))


@pytest.mark.parametrize("column, scale, shift, match", [
    (0, 1.0, -101325.0, r"channel 'pressure' of readings drops to .* looks like a GAUGE pressure"),  # gauge Pa
    (0, 1e-3, 0.0, r"channel 'pressure' of readings is 300 Pa at most: that looks like kPa"),
    (0, 1e-5, 0.0, r"channel 'pressure' of readings is 3 Pa at most: that looks like bar"),
    (1, 1e3, 0.0, r"channel 'position' of readings spans \[10, 75\] m, past the stroke \[-0\.02, 0\.075\] m"),  # mm
    (1, 1e6, 0.0, r"channel 'position' of readings spans \[1e\+04, 7\.5e\+04\] m, past the stroke"),  # µm
])
def test_filter_refuses_readings_in_another_unit(column, scale, shift, match):
    """Gauge pressure readings were filtered to estimates an atmosphere off, positions in mm to x = 52 m and in µm to
    NaN everywhere (the filter refused the same slips in its initial mean and noise). Refused before filtering,
    naming the channel; absolute readings at the stroke's ends, a few σ_R beyond them and a missing (NaN) reading
    pass the check."""
    ekf = pj.ExtendedKalmanFilter(MODEL)
    fine = np.array([[1.2e5, 0.01], [3e5, 0.075 + 3e-4], [np.nan, -0.02 - 3e-4], [2e5, np.nan]])
    ekf._filter_inputs(pj.Constant(0.6), fine, 1e-3, CHANNELS, BENCH_NOISE, 0.0, None)  # no error
    bad = fine.copy()
    bad[:, column] = scale * fine[:, column] + shift
    if column == 1:
        bad[:, 1] = scale * np.array([0.01, 0.075, np.nan, 0.05])
    with pytest.raises(pj.PamjaxInputError, match=match):
        ekf.filter(pj.Constant(0.6), bad, 1e-3, CHANNELS, BENCH_NOISE)


def test_a_partial_noise_or_spread_dict_keeps_the_other_defaults_and_strings_are_named():
    """process_noise=dict(pressure=...) (or initial_std=dict(position=...)) set the other states' values to 0, not
    their defaults: the filter then claimed a certainty it lacked (80 % 3σ coverage). The others keep their
    documented defaults; a string ("5 mm") raised a raw ValueError from the converter, now named."""
    default = pj.ExtendedKalmanFilter(MODEL)
    assert {k: float(v) for k, v in default.process_noise.items()} == dict(pressure=1.5e5, position=1e-4,
                                                                           velocity=0.02)
    partial = pj.ExtendedKalmanFilter(MODEL, process_noise=dict(pressure=3e4), initial_std=dict(position=1e-3))
    assert {k: float(v) for k, v in partial.process_noise.items()} == dict(pressure=3e4, position=1e-4, velocity=0.02)
    std, std_default = partial.std(partial.initial_state()), default.std(default.initial_state())
    np.testing.assert_allclose(float(std.position), 1e-3, rtol=1e-12)
    for field in ("pressure", "velocity"):
        np.testing.assert_allclose(float(getattr(std, field)), float(getattr(std_default, field)), rtol=1e-12)
    with pytest.raises(pj.PamjaxInputError, match=r"ExtendedKalmanFilter.initial_std\['position'\] must be numbers, "
                                                  r"got '5 mm'"):
        pj.ExtendedKalmanFilter(MODEL, initial_std=dict(position="5 mm"))


def test_loop_sensors_take_a_seed_of_any_size():
    """LoopSensors(seed=2**31) (and 2**32, 2**40, -2**31 - 1, as NumPy's generators take them) was a raw
    OverflowError. Accepted, folded into the int32 seed deterministically: distinct from each other and from small
    seeds, reproducible, and every seed that fits int32 kept as it was (its noise unchanged)."""
    from pamjax._control.controllers import fold_seed

    big = (2**31, 2**32, 2**40, -(2**31) - 1, 2**64, np.uint64(2**63))
    seeds = [int(pj.LoopSensors(seed=s).seed) for s in big]
    assert len(set(seeds) | {0, 1, -1, 2**31 - 1}) == len(big) + 4
    assert seeds == [int(pj.LoopSensors(seed=s).seed) for s in big]
    assert [int(pj.LoopSensors(seed=s).seed) for s in (0, -1, 2**31 - 1, -(2**31))] == [0, -1, 2**31 - 1, -(2**31)]
    assert fold_seed(2**40, 64) == 2**40 and -(2**63) <= fold_seed(2**64, 64) < 2**63  # PIDController's 64 bits
