"""Joining JAX's multi-process runtime, and the few cross-process steps the workflows need.

pamjax schedules nothing itself: `jax.distributed.initialize` connects the processes (a coordinator at process 0's
address), after which `jax.devices()` lists the devices of every process and a `Mesh` over them spans the cluster
(`sweep` shards its batch over it); `jax.experimental.multihost_utils.process_allgather` moves results between
processes (on CPU over gloo, JAX's default CPU collectives). This module reads the usual settings, says what it
joined or why it could not, and gathers Python-level results (bytes) from every process.
"""

import dataclasses
import numbers
import os
from collections.abc import Mapping, Sequence

import numpy as np

from .errors import PamjaxInputError
from .private import jax_backends_initialized, jax_coordinator_address

# Environment variables read when an argument is not given (JAX itself reads JAX_COORDINATOR_ADDRESS and
# JAX_LOCAL_DEVICE_IDS; the process count and id are pamjax's, named alike).
ENV_COORDINATOR = "JAX_COORDINATOR_ADDRESS"
ENV_NUM_PROCESSES = "JAX_NUM_PROCESSES"
ENV_PROCESS_ID = "JAX_PROCESS_ID"
ENV_TIMEOUT = "PAMJAX_DISTRIBUTED_TIMEOUT"  # seconds to wait for every process to connect
DEFAULT_TIMEOUT = 300  # s, JAX's own default

# Cluster managers whose environment `jax.distributed.initialize()` reads by itself (jax/_src/clusters): the
# variables whose presence marks each, as JAX tests them.
_CLUSTERS = {
    "SLURM": ("SLURM_JOB_ID", "SLURM_STEP_NODELIST", "SLURM_NTASKS", "SLURM_PROCID", "SLURM_LOCALID"),
    "Open MPI": ("OMPI_MCA_orte_hnp_uri",),
    "Open MPI (PRRTE)": ("OMPI_MCA_ess_base_num_procs", "OMPI_COMM_WORLD_RANK"),
}


class PamjaxDistributedError(RuntimeError):
    """This process could not join (or use) JAX's multi-process runtime; the message says why."""


@dataclasses.dataclass(frozen=True)
class ProcessInfo:
    """Where this process stands: `process_index` of `process_count`, the coordinator, where the settings came
    from (`source`), and its devices (`local_devices` of `global_devices`, on `platform`)."""

    process_index: int
    process_count: int
    coordinator: str | None
    source: str
    local_devices: int
    global_devices: int
    platform: str

    @property
    def distributed(self):
        return self.process_count > 1

    def __str__(self):
        if not self.distributed:
            return (f"pamjax: single process ({self.source}): {self.local_devices} {self.platform} device(s)")
        return (f"pamjax: joined as process {self.process_index} of {self.process_count} (coordinator "
                f"{self.coordinator}, settings from {self.source}): {self.local_devices} local {self.platform} "
                f"device(s), {self.global_devices} in all")


def _env_int(name, environ):
    text = environ.get(name)
    if text is None or text.strip() == "":
        return None
    try:
        return int(text)
    except ValueError:
        raise PamjaxInputError(f"environment variable {name} must be an integer, got {text!r}") from None


def _as_int(value):
    """`value` as an int if it is an integer (NumPy's too, never a bool), else unchanged (refused by the caller)."""
    if isinstance(value, numbers.Integral) and not isinstance(value, bool | np.bool_):
        return int(value)
    return value


def _detected_cluster(environ):
    for name, keys in _CLUSTERS.items():
        if all(k in environ for k in keys):
            return name
    return None


def _backend_started():
    return jax_backends_initialized()  # False if the private name moved: then jax.distributed.initialize says it


def process_info(source="already initialised"):
    """This process's place in the runtime, without joining anything (starts JAX's backend)."""
    import jax

    coordinator = jax_coordinator_address()  # None if the private name moved: the line then names no coordinator
    return ProcessInfo(
        process_index=jax.process_index(), process_count=jax.process_count(), coordinator=coordinator, source=source,
        local_devices=jax.local_device_count(), global_devices=jax.device_count(),
        platform=jax.devices()[0].platform,
    )


def _reach(coordinator, index, count, timeout, source):
    """`PamjaxDistributedError` unless something listens at `coordinator` (host:port) within `timeout` [s]: a process
    that joins a coordinator that never comes up is aborted by XLA's coordination client at its timeout (SIGABRT, a
    C++ fatal log, exit status 134), which no Python handler sees. The coordinator (process 0) waiting for the others
    past its timeout is aborted the same way: that one cannot be checked before."""
    import socket
    import time

    host, _, port = coordinator.rpartition(":")
    deadline = time.monotonic() + timeout
    while True:
        try:
            with socket.create_connection((host.strip("[]"), int(port)), timeout=min(1.0, timeout)):
                return
        except (OSError, ValueError) as err:
            if time.monotonic() >= deadline:
                raise PamjaxDistributedError(
                    f"could not join process {index} of {count} at coordinator {coordinator} within {timeout:g} s "
                    f"({source}): nothing listens there ({type(err).__name__}: {err}); start process 0 there first, "
                    "or check the address and port") from None
            time.sleep(0.2)


def initialize_distributed(
    coordinator_address: str | None = None,
    num_processes: int | None = None,
    process_id: int | None = None,
    *,
    local_device_ids: int | Sequence[int] | None = None,
    timeout: float | int | None = None,
    required: bool = False,
    environ: Mapping[str, str] | None = None,
) -> ProcessInfo:
    """Join JAX's multi-process runtime (`jax.distributed.initialize`), reading the usual settings, and say what
    was joined; call it first, before any JAX computation, in every process.

    Settings, first found wins: the arguments; the environment variables `JAX_COORDINATOR_ADDRESS` (host:port of
    process 0), `JAX_NUM_PROCESSES` and `JAX_PROCESS_ID`; a cluster manager that JAX detects by itself (SLURM's
    `srun`, Open MPI's `mpirun`: then every setting comes from it, one process per local GPU). With none of them it
    stays a single process (or, with `required=True`, raises saying what was looked for). CPU processes exchange
    data over gloo (`jax_cpu_collectives_implementation`, set to "gloo" unless the user chose another).

    **Arguments:** `coordinator_address` ("host:port"), `num_processes`, `process_id` (0 … num_processes − 1),
    `local_device_ids` (the GPUs this process uses; default all, or the one of its local rank under a cluster
    manager), `timeout` [s] to wait for every process (default `PAMJAX_DISTRIBUTED_TIMEOUT` or 300), `required`
    (raise when there is nothing to join), `environ` (default `os.environ`).

    **Returns:** a `ProcessInfo`; `str()` of it is one line for the log ("joined as process 1 of 4 ...").

    **Raises:** `PamjaxInputError` for unusable settings (named); `PamjaxDistributedError` when JAX already
    started its backend in this process, when `required` and nothing to join was found, or when the coordinator
    could not be reached within `timeout` (JAX's message attached).
    """
    import jax

    environ = os.environ if environ is None else environ
    if jax.distributed.is_initialized():
        return process_info()
    if coordinator_address is not None and not isinstance(coordinator_address, str):  # 1234 for "host:1234"
        raise PamjaxInputError(f"coordinator_address must be a string \"host:port\" (the address of process 0), got "
                               f"{coordinator_address!r}")
    coordinator = coordinator_address or environ.get(ENV_COORDINATOR) or None
    count = _as_int(num_processes) if num_processes is not None else _env_int(ENV_NUM_PROCESSES, environ)
    index = _as_int(process_id) if process_id is not None else _env_int(ENV_PROCESS_ID, environ)
    if timeout is None:  # an environment value of 0 is refused below, not read as "unset" (it ran with 300 s)
        timeout = _env_int(ENV_TIMEOUT, environ)
        timeout, timeout_name = (DEFAULT_TIMEOUT, "timeout") if timeout is None else (timeout, ENV_TIMEOUT)
    else:
        timeout_name = "timeout"
    if not (isinstance(timeout, int | float) and not isinstance(timeout, bool) and timeout > 0
            and np.isfinite(timeout)):
        raise PamjaxInputError(f"{timeout_name} must be a number of seconds > 0, got {timeout!r}")
    given = {"coordinator_address": coordinator, "num_processes": count, "process_id": index}
    cluster = _detected_cluster(environ)
    if all(v is not None for v in given.values()):
        source = "arguments" if coordinator_address and num_processes is not None and process_id is not None \
            else f"{ENV_COORDINATOR}/{ENV_NUM_PROCESSES}/{ENV_PROCESS_ID}"
        if ":" not in coordinator:
            raise PamjaxInputError(f"coordinator address must be host:port, got {coordinator!r}")
        if not (isinstance(count, int) and not isinstance(count, bool) and count >= 1):
            raise PamjaxInputError(f"num_processes ({ENV_NUM_PROCESSES}) must be an integer >= 1, got {count!r}")
        if not (isinstance(index, int) and not isinstance(index, bool) and 0 <= index < count):
            raise PamjaxInputError(
                f"process_id ({ENV_PROCESS_ID}) must be an integer in [0, {count - 1}], got {index!r}")
    elif cluster is not None and not any(v is not None for v in given.values()):
        source = f"{cluster} environment (jax.distributed auto-detection)"
    elif any(v is not None for v in given.values()):
        missing = [k for k, v in given.items() if v is None]
        raise PamjaxInputError(
            f"incomplete distributed settings: {', '.join(missing)} not given (set them as arguments or as "
            f"{ENV_COORDINATOR}, {ENV_NUM_PROCESSES}, {ENV_PROCESS_ID}); got {given}")
    else:
        reason = (f"none of {ENV_COORDINATOR}, {ENV_NUM_PROCESSES}, {ENV_PROCESS_ID} set and no cluster manager "
                  f"({', '.join(_CLUSTERS)}) detected")
        if required:
            raise PamjaxDistributedError(f"nothing to join: {reason}")
        return process_info(source=reason)
    if count == 1:  # a one-process "cluster": nothing to connect to
        return process_info(source=f"{source}, one process")
    if _backend_started():
        raise PamjaxDistributedError(
            "cannot join a multi-process run: JAX already started its backend in this process (an array or "
            "computation was made before); call pamjax.runtime.initialize_distributed() first")
    if coordinator and index:  # not the coordinator: it must listen (else XLA aborts the process at the timeout)
        _reach(coordinator, index, count, float(timeout), source)
    if jax.config.jax_cpu_collectives_implementation is None:
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    kwargs = dict(coordinator_address=coordinator, num_processes=count, process_id=index,
                  local_device_ids=local_device_ids, initialization_timeout=int(np.ceil(timeout)))
    where = f"coordinator {coordinator}" if coordinator else source
    try:
        jax.distributed.initialize(**{k: v for k, v in kwargs.items() if v is not None})
    except Exception as err:
        what = f"process {index} of {count}" if index is not None else "the run"
        raise PamjaxDistributedError(
            f"could not join {what} at {where} within {timeout:g} s ({source}): {type(err).__name__}: {err}"
        ) from err
    return process_info(source=source)


def join_for_cli(distributed: bool) -> bool:
    """A command's `--distributed`: join (required), print what was joined, or raise a `PamjaxInputError` saying why
    it cannot (the command's one-line message, status 2: the settings, or the coordinator they name, are the user's
    to fix). True on the process that writes the outputs (process 0, or the only one)."""
    if not distributed:
        return True
    try:
        info = initialize_distributed(required=True)
    except (PamjaxDistributedError, PamjaxInputError) as err:
        raise PamjaxInputError(f"--distributed: {err}") from None
    print(info, flush=True)
    return info.process_index == 0


def gather_bytes(payload: bytes) -> list:
    """Every process's `payload`, in process order, on every process (one allgather of sizes, one of bytes)."""
    import jax

    if jax.process_count() == 1:
        return [bytes(payload)]
    from jax.experimental import multihost_utils

    sizes = np.asarray(multihost_utils.process_allgather(np.array([len(payload)], dtype=np.int64))).reshape(-1)
    buffer = np.zeros(max(int(sizes.max()), 1), dtype=np.uint8)
    buffer[: len(payload)] = np.frombuffer(payload, dtype=np.uint8)
    stacked = np.asarray(multihost_utils.process_allgather(buffer))
    return [stacked[i, : int(n)].tobytes() for i, n in enumerate(sizes)]


def my_tasks(n_tasks):
    """The indices of `n_tasks` tasks that this process runs: round robin over the processes (task i on process
    i mod P), so every process knows who runs what without asking."""
    import jax

    return list(range(jax.process_index(), n_tasks, jax.process_count()))
