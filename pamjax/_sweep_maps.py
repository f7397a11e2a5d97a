"""The sweeps users map an actuator with: steady state against duty, the valve's averaged flow surface, frequency
response. Thin recipes over `sweep` and `cycle_averaged_flow`; no physics here."""

import jax
import jax.numpy as jnp
import numpy as np

from ._errors import PamjaxInputError, check_positive
from ._inputs import Constant, Sine
from ._sweep import Harmonic, Mean, sweep
from ._valve import OnOffValve, cycle_averaged_flow


def steady_state_map(system, commands, *, horizon=5.0, window=1.0, sample_interval=0.01, over=None, **sweep_kwargs):
    """Settled outputs against a constant command (duty ratio): each channel averaged over the last `window` [s]
    of a `horizon` [s] run (with a PWM valve, a whole number of periods, e.g. 1 s = 50 periods at 50 Hz). With the
    switching valve the dead band shows: below ~10 % and above ~90 % duty the valve does not switch (paper 000).

    **Arguments:** `commands` 1-D; `over`: further swept paths, broadcast against `commands[:, None]`-style shapes
    by the caller; `sweep_kwargs` go to `sweep`. **Returns:** a `SweepResult` with `over["signal.value"]`.
    """
    commands = np.asarray(commands, dtype=float)
    if commands.ndim != 1:
        raise PamjaxInputError(f"commands must be 1-D, got shape {commands.shape}")
    check_positive(horizon, "horizon")
    if not 0 < window <= horizon:
        raise PamjaxInputError(f"window must lie in (0, horizon = {horizon}] s, got {window}")
    ts = np.linspace(0.0, horizon, int(round(horizon / sample_interval)) + 1)
    return sweep(system, Constant(0.5), ts, {"signal.value": commands, **(over or {})}, reduce=Mean(window),
                 **sweep_kwargs)


def flow_surface(valve: OnOffValve, commands, pressures, air, samples: int = 400):
    """Cycle-averaged mass flow ṁ_eq(u, p) [kg/s] into a chamber HELD at `pressures` [Pa abs] for duty `commands`:
    the surface paper 000's eq. 13 is fitted to. Shape (len(commands), len(pressures)); one vmapped call."""
    commands = jnp.asarray(commands, dtype=float)
    pressures = jnp.asarray(pressures, dtype=float)
    if commands.ndim != 1 or pressures.ndim != 1:
        raise PamjaxInputError(f"commands and pressures must be 1-D, got {commands.shape} and {pressures.shape}")
    check_positive(pressures, "pressures (absolute) [Pa]")
    lo, hi = valve.command_range
    if not bool(jnp.all((commands >= lo) & (commands <= hi))):
        raise PamjaxInputError(f"commands must lie in [{lo}, {hi}]")
    flow = jax.jit(jax.vmap(jax.vmap(lambda u, p: cycle_averaged_flow(valve, u, p, air, samples), (None, 0)),
                            (0, None)))
    return np.asarray(flow(commands, pressures))


def frequency_response(system, frequencies, *, offset=0.5, amplitude=0.2, settle_periods=3, periods=3,
                       samples_per_period=40, channels=("position", "pressure"), **sweep_kwargs):
    """Gain and phase of outputs against a sinusoidal command u = offset + amplitude sin(2π f t), at each of
    `frequencies` [Hz], from the Fourier coefficient over the last `periods` periods after `settle_periods`.

    All frequencies run in one sweep on a common time grid (as long as the lowest frequency needs, sampled as
    finely as the highest needs). **Returns:** dict with `frequency`, and per channel `gain` (|Y|/|U|, channel
    units per unit command) and `phase` [deg] (arg Y − arg U), plus the `SweepResult`.
    """
    frequencies = np.asarray(frequencies, dtype=float)
    check_positive(frequencies, "frequencies")
    horizon = (settle_periods + periods) / frequencies.min()
    n = int(np.ceil(horizon * frequencies.max() * samples_per_period))
    ts = np.linspace(0.0, horizon, n + 1)
    result = sweep(system, Sine(offset, amplitude, 1.0), ts, {"signal.frequency": frequencies},
                   reduce=Harmonic(periods), channels=(*channels, "command"), **sweep_kwargs)
    u = result["command"]
    out = dict(frequency=frequencies, result=result)
    for c in channels:
        ratio = result[c] / u
        out[c] = dict(gain=np.abs(ratio), phase=np.degrees(np.unwrap(np.angle(ratio))))
    return out
