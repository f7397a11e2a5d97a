"""What a sweep returns (`SweepResult`, its status codes), and the whole result joined from every process's shard."""

import os
import pathlib
from collections.abc import Iterable

import equinox as eqx
import numpy as np

from .._core.custom_types import Float, Int
from .._core.errors import PamjaxInputError

# Status codes per sweep point.
SUCCESS = 0  # finished with a finite, physical state
NON_FINITE = 1  # the state became NaN/inf (e.g. a step too large for this point's stiffness)
NON_PHYSICAL = 2  # an absolute pressure became <= 0
SOLVER_FAILED = 3  # the adaptive solver failed (max_steps, ...), method="adaptive" only
STATUS_NAMES = {SUCCESS: "success", NON_FINITE: "non-finite state", NON_PHYSICAL: "non-physical state (pressure <= 0)",
                SOLVER_FAILED: "adaptive solver failed"}


class SweepResult(eqx.Module):
    """The result of `sweep`.

    - `over`: the swept values, each broadcast to the batch shape (plus the leaf's own shape).
    - `t`: output times [s]; `channels`: names of the output channels.
    - `outputs`: channel -> array of shape batch_shape + (len(t),) for trajectories, batch_shape for reductions
      (complex for `FourierCoefficient`). Pressures absolute [Pa], positions [m], flows [kg/s], as `simulate`.
    - `status`: int per point (0 success; 1 non-finite state; 2 non-physical state; 3 adaptive solver failed);
      failed points hold NaN outputs. `dt`, `method`: the step [s] and scheme used.
    - `points`: None for a whole result; for one process's shard (`sweep(..., gather="local")`) the flat indices
      (C order over `batch_shape`) of the points it holds, which then lie along one flat axis in `over`, `outputs`
      and `status`. `merge_sweep_shards` joins the shards of every process into the whole result.
    """

    over: dict[str, np.ndarray]
    t: Float[np.ndarray, " times"]
    channels: tuple[str, ...] = eqx.field(static=True)
    outputs: dict[str, np.ndarray]
    status: Int[np.ndarray, "..."]
    dt: float = eqx.field(static=True)
    method: str = eqx.field(static=True)
    points: Int[np.ndarray, " points"] | None = None
    batch_shape: tuple[int, ...] | None = eqx.field(static=True, default=None)

    @property
    def succeeded(self):
        return self.status == SUCCESS

    def __getitem__(self, channel):
        if channel not in self.outputs:
            raise PamjaxInputError(f"unknown channel {channel!r}; this sweep has {list(self.outputs)}")
        return self.outputs[channel]

    def save(self, path: str | os.PathLike) -> pathlib.Path:
        """Write the whole result (a shard of `gather="local"` too: what `merge_sweep_shards` needs) to one NPZ
        file, values exact; `SweepResult.load` reads it back."""
        arrays = {f"over:{k}": np.asarray(v) for k, v in self.over.items()}
        arrays |= {f"out:{c}": np.asarray(self.outputs[c]) for c in self.channels}
        if self.points is not None:
            arrays["points"] = np.asarray(self.points)
        if self.batch_shape is not None:
            arrays["batch_shape"] = np.asarray(self.batch_shape, dtype=np.int64)
        path = pathlib.Path(path)
        with path.open("wb") as f:  # a file object: np.savez would append ".npz" to a name without it
            np.savez(f, t=np.asarray(self.t), status=np.asarray(self.status), dt=np.float64(self.dt),
                     method=np.str_(self.method), channels=np.asarray(self.channels, dtype=str), **arrays)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> "SweepResult":
        """The `SweepResult` that `save` wrote to `path`."""
        with np.load(path, allow_pickle=False) as f:
            data = {k: f[k] for k in f.files}
        channels = tuple(str(c) for c in data["channels"])
        return cls(over={k[len("over:"):]: v for k, v in data.items() if k.startswith("over:")}, t=data["t"],
                   channels=channels, outputs={c: data[f"out:{c}"] for c in channels}, status=data["status"],
                   dt=float(data["dt"]), method=str(data["method"]), points=data.get("points"),
                   batch_shape=tuple(int(n) for n in data["batch_shape"]) if "batch_shape" in data else None)


def in_point_order(points, out, status, batch_size):
    """Outputs and status placed by point index (each point computed exactly once)."""
    order = np.argsort(points, kind="stable")
    if not np.array_equal(points[order], np.arange(batch_size)):
        raise RuntimeError(f"sweep: the devices returned points {np.unique(points).size} of {batch_size} "
                           "(or some twice); this is a bug in pamjax")
    return out[order], status[order]


def merge_sweep_shards(shards: Iterable[SweepResult]) -> SweepResult:
    """The whole `SweepResult` from the shards that `sweep(..., gather="local")` returned on every process (for
    instance saved by each process and loaded on one machine); every point must be in exactly one shard."""
    shards = list(shards)
    if not shards or any(not isinstance(s, SweepResult) or s.points is None for s in shards):
        raise PamjaxInputError("shards must be a non-empty list of SweepResults from sweep(..., gather='local')")
    first = shards[0]
    for s in shards[1:]:
        if (s.batch_shape, s.channels, s.method) != (first.batch_shape, first.channels, first.method) or not \
                np.array_equal(s.t, first.t):
            raise PamjaxInputError("shards must come from one sweep (same batch shape, channels, times, method)")
    batch_shape = tuple(first.batch_shape)
    size = int(np.prod(batch_shape))
    points = np.concatenate([s.points for s in shards])
    out = np.stack([np.concatenate([s.outputs[c] for s in shards]) for c in first.channels], axis=-1)
    try:
        out, status = in_point_order(points, out, np.concatenate([s.status for s in shards]), size)
    except RuntimeError:
        raise PamjaxInputError(f"shards hold {points.size} points ({np.unique(points).size} distinct), the sweep "
                               f"has {size}: pass every process's shard once") from None
    order = np.argsort(points, kind="stable")
    over = {k: np.concatenate([s.over[k] for s in shards])[order] for k in first.over}
    over = {k: v.reshape(batch_shape + v.shape[1:]) for k, v in over.items()}
    outputs = {c: out[..., i].reshape(batch_shape + out.shape[1:-1]) for i, c in enumerate(first.channels)}
    return SweepResult(over=over, t=first.t, channels=first.channels, outputs=outputs,
                       status=status.reshape(batch_shape), dt=first.dt, method=first.method)
