"""How a sweep's points are spread: over the devices of a `Mesh` (each device runs its own lanes), over compiled calls
of a chunk size, and over the processes of a multi-process run, and how the pieces are gathered back in point order."""

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .._core.errors import PamjaxInputError

_LANE_MULTIPLE = 8  # pad batches to a multiple of this many lanes (bitwise batch-independence, see sweep)


def check_devices(devices):
    """`sweep`'s `devices` as given (None, a `Mesh`, or a list of distinct `jax.Device`s), or `PamjaxInputError`
    naming it: a Mesh without its one "batch" axis, a string, a device listed twice (raw JAX errors, one of them
    "this is a bug in pamjax") are refused before anything runs."""
    if devices is None:
        return None
    if isinstance(devices, Mesh):
        if tuple(devices.axis_names) != ("batch",):
            raise PamjaxInputError(f"devices: a Mesh must have exactly one axis, named 'batch' (the sweep's points "
                                   f"are split along it), got axis names {tuple(devices.axis_names)} of shape "
                                   f"{dict(devices.shape)}; write Mesh(np.array(jax.devices()), ('batch',))")
        return devices
    listed = list(devices) if not isinstance(devices, str | bytes) and np.iterable(devices) else None
    if not listed or not all(isinstance(d, jax.Device) for d in listed):
        raise PamjaxInputError(f"devices must be None (all of jax.devices()), a non-empty list of jax.Device "
                               f"(e.g. jax.devices('cpu')) or a Mesh with a 'batch' axis, got {devices!r}")
    if len(set(listed)) != len(listed):
        raise PamjaxInputError(f"devices lists a device more than once: {listed}; each device runs its own lanes")
    return listed


def mesh_of(devices):
    """The `Mesh` of the batch axis over `devices` (checked by `check_devices`), or None for a single device (see
    `device_of`)."""
    if isinstance(devices, Mesh):
        return devices
    devices = jax.devices() if devices is None else list(devices)
    if len(devices) < 2:
        return None
    return Mesh(np.asarray(devices), ("batch",))


def device_of(devices):
    """The one device `devices` lists (the sweep's inputs are put there, so it runs there), or None: the default
    device, or a mesh."""
    if devices is None or isinstance(devices, Mesh) or len(devices) != 1:
        return None
    return list(devices)[0]


_CPU_CHUNK = 8192  # points per compiled call on CPU: wider batches run no faster there (measured, benchmarks/sweep.py)
# On a GPU/TPU every integration step is a few kernel launches whatever the width, so the whole batch in one call is
# fastest (100,000 points x 5 s on an H100: 0.24 s in one chunk, 1.15 s in chunks of 8,192; benchmarks/RESULTS.md);
# the default chunk is as many points as this many bytes of outputs (and at least _CPU_CHUNK).
_ACCELERATOR_CHUNK_BYTES = 1 << 30


def default_chunk_size(batch_size, values_per_point, platform, n_devices=1):
    """`sweep`'s points per compiled call when `chunk_size` is not given: 8,192 on CPU; on an accelerator as many
    as 1 GiB of outputs per device holds (`values_per_point` float64 outputs per point, counted as at least 64)."""
    if platform == "cpu":
        return min(batch_size, _CPU_CHUNK)
    fit = n_devices * _ACCELERATOR_CHUNK_BYTES // (8 * max(int(values_per_point), 64))
    return min(batch_size, max(_CPU_CHUNK, fit))


class Layout:
    """Which points each compiled call computes, on which device.

    The batch is cut into groups of `per_device` consecutive points; each device computes one group per call, in
    `lanes` lanes (`per_device` rounded up to a multiple of 8, padded with copies of point 0). Group g runs in call
    g // n_dev on the mesh's device g % n_dev. XLA's code for a batch depends on its width, and a lane's result on
    its place in it (in the last bit, ~1e-16 relative), so a point's result is fixed by its group and place and by
    the program: one SPMD program per device for any mesh of 2 or more devices (however many processes hold them),
    another, optimised without the SPMD partitioner, for a single device. So: the same mesh size gives the same
    bits, one process or several; with `chunk_size` given, `per_device` does not depend on the device count, and
    any 2 or more devices give the same bits (2, 3 and 4 CPU devices measured), one device agreeing to round-off.
    Without it, the batch (up to `default_chunk_size` points per call) is split evenly over the devices."""

    def __init__(self, batch_size, per_device, n_dev, processes):
        self.batch_size, self.per_device, self.n_dev, self.processes = batch_size, per_device, n_dev, processes
        self.lanes = int(math.ceil(per_device / _LANE_MULTIPLE) * _LANE_MULTIPLE)
        groups = int(math.ceil(batch_size / per_device))
        self.calls = int(math.ceil(groups / n_dev))

    @classmethod
    def plan(cls, batch_size, chunk_size, mesh, devices, values_per_point):
        n_dev = 1 if mesh is None else mesh.devices.size
        processes = 1 if mesh is None else len({d.process_index for d in mesh.devices.flat})
        if chunk_size is not None:
            return cls(batch_size, min(chunk_size, batch_size), n_dev, processes)
        if mesh is not None:
            platform = mesh.devices.flat[0].platform
        else:
            platform = ((list(devices) if devices is not None else []) or jax.devices())[0].platform
        total = default_chunk_size(batch_size, values_per_point, platform, n_dev)
        return cls(batch_size, int(math.ceil(total / n_dev)), n_dev, processes)

    def lanes_of_call(self, c):
        """(point index per lane, whether the lane holds a real point) of call `c`, device-major."""
        group = c * self.n_dev + np.arange(self.n_dev)[:, None]
        place = np.arange(self.lanes)[None, :]
        point = group * self.per_device + place
        valid = (place < self.per_device) & (point < self.batch_size)
        return np.where(valid, point, 0).reshape(-1), valid.reshape(-1)

    def points_of_call(self, c):
        first = c * self.n_dev * self.per_device
        return first, min(first + self.n_dev * self.per_device, self.batch_size) - 1


def local_part(out, status, index, valid):
    """(points, outputs, status) of the real lanes of one call that this process's devices computed."""
    if isinstance(out, jax.Array) and len(out.sharding.device_set) > 1:
        rows = [(shard.index[0], shard) for shard in out.addressable_shards]
        status_of = {s.device: s for s in status.addressable_shards}
        parts = []
        for lanes, shard in sorted(rows, key=lambda r: r[0].start or 0):
            keep = valid[lanes]
            parts.append((index[lanes][keep], np.asarray(shard.data)[keep],
                          np.asarray(status_of[shard.device].data)[keep]))
        return tuple(np.concatenate(p) for p in zip(*parts))
    return index[valid], np.asarray(out)[valid], np.asarray(status)[valid]


def gather_processes(points, out, status):
    """Every process's (points, outputs, status), on every process (`process_allgather` of their bytes)."""
    import io

    from .._core.distributed import gather_bytes

    buffer = io.BytesIO()
    np.savez(buffer, points=points, out=out, status=status)
    parts = []
    for payload in gather_bytes(buffer.getvalue()):
        with np.load(io.BytesIO(payload)) as f:
            parts.append((f["points"], f["out"], f["status"]))
    return tuple(np.concatenate(p) for p in zip(*parts))


def put(x, mesh, device=None):
    """A host array as a global array sharded over the mesh's batch axis (works single- and multi-host: every
    process holds the full host array and contributes its devices' slices); without a mesh, on `device` (None: the
    default device). The compiled call runs where its inputs are committed."""
    if mesh is None:
        return jnp.asarray(x) if device is None else jax.device_put(x, device)
    sharding = NamedSharding(mesh, PartitionSpec("batch"))
    return jax.make_array_from_callback(x.shape, sharding, lambda index: x[index])
