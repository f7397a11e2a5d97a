"""Synthetic recordings from any system, with seeded Gaussian noise: for tests, demos and benchmarks."""

from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import numpy as np

from .._core.custom_types import RealScalarLike, TimesLike
from .._core.errors import PamjaxInputError
from .._physics.signals import AbstractSignal
from .._solve.simulate import simulate
from .._systems.base import AbstractSystem
from .experiment import check_scale_against_data
from .recording import Recording

DEFAULT_CHANNELS = ("pressure", "position", "command")  # those of them the system outputs


def _checked_noise(noise, seed, channels):
    """`noise` as {channel: standard deviation} (each a finite number >= 0, of a channel recorded) and `seed` (an
    int >= 0), before the simulation: a NaN level gave noise-free data, a level for a channel not recorded was
    dropped, both silently; a negative or fractional seed was NumPy's raw error."""
    if not (isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_)) and seed >= 0):
        raise PamjaxInputError(f"seed must be an int >= 0 (NumPy's random generator's seed), got {seed!r}")
    if noise is not None and not isinstance(noise, Mapping):
        raise PamjaxInputError(f"noise must be a dict channel → standard deviation (e.g. {{'pressure': 2e3}}), got "
                               f"{noise!r}")
    levels = {}
    for c, std in dict(noise or {}).items():
        if c not in channels:
            raise PamjaxInputError(f"noise names channel {c!r}, which is not recorded; the recorded channels are "
                                   f"{list(channels)} (add it to channels=[...] to record it)")
        try:
            levels[c] = float(std)
        except (TypeError, ValueError):
            levels[c] = float("nan")
        if not (np.isfinite(levels[c]) and levels[c] >= 0):
            raise PamjaxInputError(f"noise[{c!r}] must be a finite standard deviation >= 0 in the channel's SI unit "
                                   f"(0: noise-free), got {std!r}")
    return levels


def synthetic_recording(system: AbstractSystem, signal: AbstractSignal, ts: TimesLike, *,
                        noise: Mapping[str, RealScalarLike] | None = None, seed: int = 0,
                        channels: Sequence[str] | None = None, y0: eqx.Module | None = None,
                        t0: RealScalarLike | None = None, name: str = "synthetic", **solver_kwargs: Any) -> Recording:
    """Simulate `system` under `signal` at times `ts` [s] and return a `Recording` with noise added.

    **Arguments:** `noise`: dict channel → standard deviation in the channel's SI unit (e.g. `{"pressure": 2e3,
    "position": 1e-4}`, the hybrid bench's levels); channels not named are noise-free; a level for a channel not
    recorded, or one the clean data contradict (as `Experiment`'s `scales`: a pressure noise below 1 Pa, one larger
    than the channel's whole range: another unit) is refused. `seed`: NumPy seed (an int >= 0).
    `channels`: the channels recorded (default: pressure, plus position for muscle systems, plus command).
    `y0`, `t0` and other keywords go to `simulate`.
    """
    if isinstance(channels, str):
        raise PamjaxInputError(f"channels must be a list of channel names, got {channels!r}")
    # before the solve: a level for a channel that cannot be recorded (the defaults: at most these three)
    noise = _checked_noise(noise, seed, DEFAULT_CHANNELS if channels is None else list(channels))
    traj = simulate(system, signal, ts, y0=y0, t0=t0, **solver_kwargs)
    available = traj.channels()
    if channels is None:
        channels = [c for c in DEFAULT_CHANNELS if c in available]
    for c in list(channels) + list(noise):
        if c not in available:
            raise PamjaxInputError(f"channel {c!r} is not an output of this system; it has {available}")
    rng = np.random.default_rng(seed)
    data = {}
    for c in channels:
        v = np.asarray(traj.channel(c), dtype=float)
        std = noise.get(c, 0.0)
        if std > 0:
            check_scale_against_data(c, std, v, "noise")  # as Experiment's scales: 0.02 (bar) or 0.1 (mm) refused
        data[c] = v + std * rng.standard_normal(v.shape) if std > 0 else v
    return Recording(np.asarray(ts, dtype=float), data, name=name)
