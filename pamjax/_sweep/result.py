"""What a sweep returns (`SweepResult`, its status codes), and the whole result joined from every process's shard."""

import hashlib
import os
import pathlib
import pickle
import re
import zipfile
from collections.abc import Iterable

import equinox as eqx
import jax.tree_util as jtu
import numpy as np

from .._core.custom_types import Float, Int
from .._core.errors import PamjaxInputError
from .._core.paths import writable_path

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
    - `reduction`: the `reduce` the sweep was given, as text (`"WindowMean(window=0.5)"`; `"None"`: whole
      trajectories). `identity`: a digest of the whole sweep before it was cut into shards (`sweep_identity`: the
      system's parameters, the signal, the initial state, every swept value, the reduction, the method, step,
      tolerances and output times), the same on every process's shard of one sweep. Both None where unknown (a
      result built by hand, or a file saved before pamjax recorded them).
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
    reduction: str | None = eqx.field(static=True, default=None)
    identity: str | None = eqx.field(static=True, default=None)

    @property
    def succeeded(self):
        return self.status == SUCCESS

    def __getitem__(self, channel):
        if channel not in self.outputs:
            raise PamjaxInputError(f"unknown channel {channel!r}; this sweep has {list(self.outputs)}")
        return self.outputs[channel]

    def save(self, path: str | os.PathLike, overwrite: bool = False) -> pathlib.Path:
        """Write the whole result (a shard of `gather="local"` too: what `merge_sweep_shards` needs, its
        `identity` included) to one NPZ file at `path` (no suffix added), values exact; `SweepResult.load` reads it
        back. Refuses to replace an existing file (`FileExistsError`, as `Recording.to_npz`: a second sweep saved
        under one name, or every process's shard under a name without `jax.process_index()`, replaced the first)
        unless `overwrite=True`; returns the path written."""
        arrays = {f"over:{k}": np.asarray(v) for k, v in self.over.items()}
        arrays |= {f"out:{c}": np.asarray(self.outputs[c]) for c in self.channels}
        if self.points is not None:
            arrays["points"] = np.asarray(self.points)
        if self.batch_shape is not None:
            arrays["batch_shape"] = np.asarray(self.batch_shape, dtype=np.int64)
        for name in ("reduction", "identity"):
            if getattr(self, name) is not None:
                arrays[name] = np.str_(getattr(self, name))
        path = writable_path(path, overwrite)
        with path.open("wb") as f:  # a file object: np.savez would append ".npz" to a name without it
            np.savez(f, t=np.asarray(self.t), status=np.asarray(self.status), dt=np.float64(self.dt),
                     method=np.str_(self.method), channels=np.asarray(self.channels, dtype=str), **arrays)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> "SweepResult":
        """The `SweepResult` that `save` wrote to `path`; `PamjaxInputError` for another file (the `sweep.npz` of
        the `pamjax sweep` command line is a table of columns, read with `np.load`). A file saved before pamjax
        recorded a sweep's `identity` and `reduction` loads with them None."""
        data = _saved_arrays(path)
        channels = tuple(str(c) for c in data["channels"])
        return cls(over={k[len("over:"):]: v for k, v in data.items() if k.startswith("over:")}, t=data["t"],
                   channels=channels, outputs={c: data[f"out:{c}"] for c in channels}, status=data["status"],
                   dt=float(data["dt"]), method=str(data["method"]), points=data.get("points"),
                   batch_shape=tuple(int(n) for n in data["batch_shape"]) if "batch_shape" in data else None,
                   reduction=str(data["reduction"]) if "reduction" in data else None,
                   identity=str(data["identity"]) if "identity" in data else None)


_SAVED = ("t", "status", "dt", "method", "channels")  # what every `SweepResult.save` file holds


def _saved_arrays(path):
    """The arrays of a `SweepResult.save` file, or `PamjaxInputError` naming what `path` is not (a raw
    `KeyError('channels')` on the CLI's column file)."""
    def not_ours(why):
        return PamjaxInputError(f"{path} is not a file SweepResult.save wrote{why}; the sweep.npz that the `pamjax "
                                "sweep` command line writes is a table of columns (one per swept path and output "
                                "channel, with status): read it with np.load")

    try:
        loaded = np.load(path, allow_pickle=False)
    except (ValueError, pickle.UnpicklingError, zipfile.BadZipFile, EOFError) as err:
        raise not_ours(f" (not an NPZ archive: {err})") from None
    if not isinstance(loaded, np.lib.npyio.NpzFile):  # a .npy file: one array
        raise not_ours(" (it holds one array, not an NPZ archive)")
    with loaded as f:
        data = {k: f[k] for k in f.files}
    missing = [k for k in _SAVED if k not in data]
    if not missing:
        missing = [f"out:{c}" for c in data["channels"] if f"out:{c}" not in data]
    if missing:
        raise not_ours(f": it has no {', '.join(repr(k) for k in missing)} (it holds {sorted(data)[:8]})")
    return data


# The parts of a sweep's identity, and how a mismatch is named: one digest each, so that `merge_sweep_shards` can say
# which part two shards disagree on.
IDENTITY_PARTS = {"system": "the system's parameters", "signal": "the signal (or what its factory builds)",
                  "y0": "the initial state", "over": "the swept values (over)", "reduce": "the reduction",
                  "settings": "the method, step, tolerances, channels or output times"}


def _digest(tree):
    """A digest of a pytree's structure and leaves' values, the same in every process: arrays by dtype, shape and
    bytes; other leaves and the structure by their text, object addresses (`at 0x7f…`, a process's own) removed."""
    h = hashlib.blake2b(digest_size=8)
    leaves, treedef = jtu.tree_flatten(tree)

    def text(x):
        h.update(re.sub(r" at 0x[0-9a-fA-F]+", "", str(x)).encode())

    text(treedef)
    for leaf in leaves:
        try:
            a = np.asarray(leaf)
        except Exception:  # a leaf that is no array (a callable): its text
            a = None
        if a is None or a.dtype == object:
            text(repr(leaf))
        else:
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def sweep_identity(**parts: object) -> str:
    """`SweepResult.identity`: "system=<digest> signal=<digest> …", one digest per part of `IDENTITY_PARTS`, computed
    by `sweep` on the whole plan before it is cut into shards, so every process's shard of one sweep carries it."""
    return " ".join(f"{name}={_digest(parts[name])}" for name in IDENTITY_PARTS)


def in_point_order(points, out, status, batch_size):
    """Outputs and status placed by point index (each point computed exactly once)."""
    order = np.argsort(points, kind="stable")
    if not np.array_equal(points[order], np.arange(batch_size)):
        raise RuntimeError(f"sweep: the devices returned points {np.unique(points).size} of {batch_size} "
                           "(or some twice); this is a bug in pamjax")
    return out[order], status[order]


def _differences(s, first):
    """What tells shard `s` apart from `first` (a list of "what: theirs vs first's"), empty for shards of one sweep as
    far as they record it (the settings each holds, then the parts of their `identity` where both have one)."""
    found = []

    def differ(what, a, b):
        found.append(f"{what} ({a} vs {b})")

    if s.method != first.method:
        differ("method", repr(s.method), repr(first.method))
    if not np.array_equal(s.dt, first.dt, equal_nan=True):  # "adaptive" reports NaN
        differ("dt", f"{s.dt!r} s", f"{first.dt!r} s")
    if None not in (s.reduction, first.reduction) and s.reduction != first.reduction:
        differ("reduce", s.reduction, first.reduction)
    if tuple(s.channels) != tuple(first.channels):
        differ("channels", s.channels, first.channels)
    if s.batch_shape != first.batch_shape:
        differ("batch shape", s.batch_shape, first.batch_shape)
    if np.shape(s.t) != np.shape(first.t) or not np.array_equal(s.t, first.t):
        differ("output times t", f"{np.size(s.t)} times over [{np.min(s.t):g}, {np.max(s.t):g}] s",
               f"{np.size(first.t)} over [{np.min(first.t):g}, {np.max(first.t):g}] s")
    if set(s.over) != set(first.over):
        differ("swept paths (over)", sorted(s.over), sorted(first.over))
    else:
        for k in first.over:
            if np.shape(s.over[k])[1:] != np.shape(first.over[k])[1:]:
                differ(f"shape per point of over[{k!r}]", np.shape(s.over[k])[1:], np.shape(first.over[k])[1:])
    if not found:  # a reduced shard holds a number per point and channel, a trajectory shard a series
        for c in first.channels:
            if np.shape(s.outputs[c])[1:] != np.shape(first.outputs[c])[1:]:
                differ(f"shape per point of outputs[{c!r}] (reduced: (), trajectories: (times,))",
                       np.shape(s.outputs[c])[1:], np.shape(first.outputs[c])[1:])
    if not found and None not in (s.identity, first.identity) and s.identity != first.identity:
        mine, theirs = dict(p.split("=", 1) for p in s.identity.split()), dict(p.split("=", 1)
                                                                                for p in first.identity.split())
        parts = [p for p in IDENTITY_PARTS if mine.get(p) != theirs.get(p)] or ["identity"]
        found.append(f"{', '.join(IDENTITY_PARTS.get(p, p) for p in parts)} (identity digests "
                     f"{' '.join(f'{p}={mine.get(p)}' for p in parts)} vs "
                     f"{' '.join(f'{p}={theirs.get(p)}' for p in parts)})")
    return found


def merge_sweep_shards(shards: Iterable[SweepResult]) -> SweepResult:
    """The whole `SweepResult` from the shards that `sweep(..., gather="local")` returned on every process (for
    instance saved by each process and loaded on one machine); every point must be in exactly one shard.

    Shards of different sweeps are refused (`PamjaxInputError` naming what differs): their method, step, reduction,
    channels, batch shape, output times or swept paths, and, through their `identity`, the system, signal, initial
    state, swept values and tolerances. A shard without an `identity` (built by hand, or saved by a pamjax before it
    recorded one) cannot be checked for those: only what it holds is compared."""
    shards = list(shards)
    if not shards or any(not isinstance(s, SweepResult) or s.points is None or s.batch_shape is None for s in shards):
        raise PamjaxInputError("shards must be a non-empty list of SweepResults from sweep(..., gather='local')")
    first = shards[0]
    for i, s in enumerate(shards[1:], start=1):
        found = _differences(s, first)
        if found:
            raise PamjaxInputError(f"shards must come from one sweep: shard {i} differs from shard 0 in "
                                   f"{'; '.join(found)}")
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
    identity = next((s.identity for s in shards if s.identity is not None), None)
    reduction = next((s.reduction for s in shards if s.reduction is not None), None)
    return SweepResult(over=over, t=first.t, channels=first.channels, outputs=outputs,
                       status=status.reshape(batch_shape), dt=first.dt, method=first.method, reduction=reduction,
                       identity=identity)
