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
from .recording import Recording


def synthetic_recording(system: AbstractSystem, signal: AbstractSignal, ts: TimesLike, *,
                        noise: Mapping[str, RealScalarLike] | None = None, seed: int = 0,
                        channels: Sequence[str] | None = None, y0: eqx.Module | None = None,
                        t0: RealScalarLike | None = None, name: str = "synthetic", **solver_kwargs: Any) -> Recording:
    """Simulate `system` under `signal` at times `ts` [s] and return a `Recording` with noise added.

    **Arguments:** `noise`: dict channel → standard deviation in the channel's unit (e.g. `{"pressure": 2e3,
    "position": 1e-4}`, the hybrid bench's levels); channels not named are noise-free. `seed`: NumPy seed.
    `channels`: the channels recorded (default: pressure, plus position for muscle systems, plus command).
    `y0`, `t0` and other keywords go to `simulate`.
    """
    traj = simulate(system, signal, ts, y0=y0, t0=t0, **solver_kwargs)
    available = traj.channels()
    if channels is None:
        channels = [c for c in ("pressure", "position") if c in available] + ["command"]
    noise = dict(noise or {})
    for c in list(channels) + list(noise):
        if c not in available:
            raise PamjaxInputError(f"channel {c!r} is not an output of this system; it has {available}")
    rng = np.random.default_rng(seed)
    data = {}
    for c in channels:
        v = np.asarray(traj.channel(c), dtype=float)
        std = float(noise.get(c, 0.0))
        if std < 0:
            raise PamjaxInputError(f"noise[{c!r}] must be >= 0, got {std}")
        data[c] = v + std * rng.standard_normal(v.shape) if std > 0 else v
    return Recording(np.asarray(ts, dtype=float), data, name=name)
