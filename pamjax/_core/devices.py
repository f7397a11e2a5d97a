"""Where pamjax's work runs: single trajectories on the CPU, batched sweeps on an accelerator when there is one.

Why two answers. A single-trajectory solve (`simulate`, a fit's residuals and Jacobian, an identification, a design's
gradient) is a loop of small steps on a handful of numbers: each RODAS5 or RK4 step is ~100 tiny kernels. On the
CPU, pamjax compiles that loop into one function (docs/performance.md, "On CPU: each solve loop runs as one compiled
function"): ~1-2 µs per step. On a GPU every kernel is a launch of a few microseconds, and the loop's condition is
read back by the host every iteration, so the same solve runs tens of times slower there, whatever the GPU. A
batched sweep does the same steps for thousands of lanes at once, each kernel working on all of them: there an
accelerator wins by two orders of magnitude (100,000 points of the MAS-10 map: 0.065 s on one H100 against ~7 s on
this project's 2-core CPU; benchmarks/RESULTS.md, `## sweep`). At ~1,000 points the two are about even (the GPU's
per-step launches dominate: 0.021 s on the H100 against 0.04-0.08 s on the CPU).

So by default (`device="auto"`):

- `work="single"`: the first CPU device. A GPU, if any, is left alone (the `pamjax` command does not even start
  it: `jax_platforms="cpu"`, which also spares its start-up and memory reservation).
- `work="batched"`: every device of the first accelerator platform JAX finds (GPU, TPU), else every CPU device
  (`pamjax sweep` splits the CPU into one device per core).

`device="cpu"`, `"gpu"` (CUDA or ROCm) or `"tpu"` overrides it (the command line's `--device`); a platform that is
not there is a `PamjaxInputError` naming it and listing what is. A GPU measurement of the single-trajectory claim on
this project's code: benchmarks/RESULTS.md, `### Which device` (an H100: the fit 20.7 s on its CPU, > 140 s on the GPU).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from .errors import PamjaxInputError

if TYPE_CHECKING:  # annotations only: this module is read before JAX is imported
    import jax

WORKS = ("single", "batched")
CHOICES = ("auto", "cpu", "gpu", "tpu")
# JAX platform names that count as each choice (jax.Device.platform; "gpu" is JAX's alias for CUDA and ROCm).
_PLATFORMS = {"cpu": ("cpu",), "gpu": ("gpu", "cuda", "rocm"), "tpu": ("tpu",)}

SINGLE_REASON = ("single-trajectory work: each solver step is ~100 tiny kernels, one compiled loop on the CPU but a "
                 "kernel launch each on a GPU, so the CPU is faster")
BATCHED_REASON = "batched work: each kernel runs every lane at once, so an accelerator is faster when there is one"


def _check(work, device):
    if work not in WORKS:
        raise PamjaxInputError(f"work must be one of {WORKS}, got {work!r}")
    if device is None:
        return "auto"
    name = str(device).strip().lower()
    if name not in CHOICES:
        raise PamjaxInputError(f"device must be one of {CHOICES}, got {device!r}")
    return name


def _kind(platform):
    """'cpu', 'gpu' or 'tpu' for a JAX platform name (another platform is an accelerator of its own name)."""
    return next((kind for kind, names in _PLATFORMS.items() if platform in names), platform)


@dataclass(frozen=True)
class DeviceChoice:
    """The devices a piece of work runs on, and why (`statement()`: the line the command line prints)."""

    devices: tuple[jax.Device, ...]
    reason: str
    requested: str  # "auto" or the override

    @property
    def platform(self):
        return self.devices[0].platform

    def statement(self):
        where = f"{len(self.devices)} {self.platform} device{'s' if len(self.devices) > 1 else ''}"
        how = f"--device {self.requested}" if self.requested != "auto" else self.reason
        return f"running on {where} ({how})"

    def default(self):
        """A context in which computations without placed inputs run on the choice's first device
        (`jax.default_device`)."""
        import jax

        return jax.default_device(self.devices[0])


def select_devices(work: Literal["single", "batched"], device: str | None = "auto",
                   available: Sequence[jax.Device] | None = None) -> DeviceChoice:
    """The devices for `work` ("single": one trajectory at a time, as `simulate`, fits, identification, design;
    "batched": a sweep's lanes), by default the fastest kind (module docstring), or the `device` asked for
    ("cpu", "gpu", "tpu"). `available`: the devices to choose from (default: every device of every platform JAX
    can start, e.g. `jax.devices("cpu") + jax.devices("gpu")`).

    Raises `PamjaxInputError` for an unknown `work` or `device`, or a `device` platform that is not available."""
    requested = _check(work, device)
    available = _all_devices() if available is None else _checked_available(available)
    by_kind = {}
    for d in available:
        by_kind.setdefault(_kind(d.platform), []).append(d)
    if not by_kind:  # nothing to choose from: a choice without devices has no platform and places nothing
        raise PamjaxInputError("select_devices: available holds no device; pass JAX devices (e.g. jax.devices()), "
                               "or leave available=None for every device JAX can start")
    if requested != "auto":
        if requested not in by_kind:
            have = ", ".join(sorted(by_kind)) or "none"
            raise PamjaxInputError(f"device={requested!r}: JAX finds no {requested.upper()} here (available: {have})")
        chosen = by_kind[requested]
        return DeviceChoice(tuple(chosen if work == "batched" else chosen[:1]), f"--device {requested}", requested)
    if work == "single":
        if "cpu" in by_kind:
            return DeviceChoice((by_kind["cpu"][0],), SINGLE_REASON, requested)
        first = next(iter(by_kind.values()))  # no CPU device (a process limited to an accelerator): what there is
        return DeviceChoice((first[0],), "no CPU device in this process", requested)
    accelerators = [k for k in by_kind if k != "cpu"]
    if accelerators:
        return DeviceChoice(tuple(by_kind[accelerators[0]]), BATCHED_REASON, requested)
    return DeviceChoice(tuple(by_kind["cpu"]), "batched work: no accelerator here, every CPU device", requested)


def _checked_available(available):
    """`available` as a tuple of devices; one device rather than a list (a raw TypeError: "'Device' object is not
    iterable"), platform names ("'str' object has no attribute 'platform'") or anything else: a `PamjaxInputError`
    saying what to pass. A device is what has a `platform` name (a `jax.Device`; the tests' stand-ins)."""
    how = ("pass a list of JAX devices, e.g. jax.devices() or [jax.devices()[0]], or leave available=None for every "
           "device JAX can start")
    if _is_device(available):
        raise PamjaxInputError(f"select_devices: available must be a list of JAX devices, got the one device "
                               f"{available!r}: pass it in a list, available=[{available!r}], or leave "
                               "available=None for every device JAX can start")
    if isinstance(available, str | bytes | Mapping) or not isinstance(available, Iterable):
        raise PamjaxInputError(f"select_devices: available must be a list of JAX devices, got {available!r}; {how}")
    available = tuple(available)
    for d in available:
        if not _is_device(d):
            platform = " (a platform name: choose it with device=..., e.g. device='cpu')" if isinstance(d, str) else ""
            raise PamjaxInputError(f"select_devices: available holds {d!r}, not a JAX device{platform}; {how}")
    return available


def _is_device(obj):
    return isinstance(getattr(obj, "platform", None), str)


def _all_devices():
    """Every device of every platform JAX can start (the CPU always; GPU and TPU where present)."""
    import jax

    devices = []
    for platform in ("cpu", "gpu", "tpu"):
        try:
            devices += jax.devices(platform)
        except STARTUP_ERRORS:  # not installed or not present
            continue
    return devices


def platforms_before_start(work: str, device: str | None = "auto"):
    """The `jax_platforms` value to set before JAX starts for `work` on `device` (None: leave it; "": JAX's default,
    every platform present, even where the environment's `JAX_PLATFORMS` named fewer), and the line that says where
    the work will run. Starts nothing: for the `pamjax` command, which picks its platforms before any JAX computation
    (a sweep first splits the CPU into one device per core)."""
    requested = _check(work, device)
    if requested == "cpu":
        return "cpu", "running on the CPU (--device cpu)"
    if requested == "gpu":  # JAX's own choice of every platform present (GPU first, the CPU kept for host work): a
        # "gpu,cpu" list makes JAX 0.11 start CUDA *and* ROCm and fail on the one not installed (seen on an H100)
        return "", "running on the GPU (--device gpu)"
    if requested == "tpu":  # the CPU stays available for host-side work; JAX fails clearly without one
        return "tpu,cpu", "running on the TPU (--device tpu)"
    if work == "single":
        return "cpu", f"running on the CPU ({SINGLE_REASON}; --device gpu to use one)"
    return None, f"running on the GPU/TPU if JAX finds one, else every CPU core ({BATCHED_REASON}; --device cpu " \
                 "to stay on the CPU)"


# What JAX raises when a platform cannot start: a RuntimeError ("Unable to initialize backend 'tpu'"), or, for
# JAX_PLATFORMS=cuda without a CUDA plugin (jax 0.10.2 on this project's CPU machine), a bare AssertionError from
# `xla_bridge.backends()` ("assert _default_backend is not None"): the same user error, not an internal one.
STARTUP_ERRORS = (RuntimeError, AssertionError)


def _first_line(err):
    """JAX's error in one line (a bare AssertionError: what it means)."""
    text = str(err).strip()
    if text:
        return text.splitlines()[0]
    return "no backend of it started" if isinstance(err, AssertionError) else type(err).__name__


def unavailable_message(device, err):
    """The user's message when the platform `device` asked for cannot start (JAX's own error appended)."""
    return f"--device {device}: JAX cannot start a {str(device).upper()} here ({_first_line(err)})"


def _start_users_platforms(users):
    """Start the platforms the environment's `JAX_PLATFORMS` names (`users`), so that one that cannot start is a
    `PamjaxInputError` naming the variable and the platforms there are, not an internal error at the first
    computation. A CPU-only list is never tried (it starts; a sweep still splits the CPU into devices after this)."""
    import jax

    try:
        jax.devices()
    except STARTUP_ERRORS as err:
        first = _first_line(err)
        before = jax.config.jax_platforms
        jax.config.update("jax_platforms", "")  # every platform JAX can start, to name them
        try:
            have = ", ".join(sorted({_kind(d.platform) for d in _all_devices()})) or "none"
        finally:
            jax.config.update("jax_platforms", before)
        raise PamjaxInputError(f"JAX_PLATFORMS={users} (set in the environment): JAX cannot start it here ({first}); "
                               f"available: {have}. Unset JAX_PLATFORMS or set it to one of those, or choose with "
                               "--device") from None


def for_command(work: Literal["single", "batched"], device: str | None = "auto",
                environ: Mapping[str, str] | None = None,
                check: bool = True) -> tuple[contextlib.AbstractContextManager, str]:
    """Set up the `pamjax` command's devices before JAX starts, and return `(context, line)`: a context to run the
    command in (placing its computations) and the line that says where it runs. A `JAX_PLATFORMS` the user set in
    the environment wins over `"auto"` (it is said); `--device` wins over it. When JAX is already running (the
    command called as `main(argv)` from a program), its platforms stay and the choice is made among its devices
    with `jax.default_device`. An asked-for platform that cannot start is a `PamjaxInputError` (`check=False`: not
    tried here, for a process that must join a multi-process run before JAX starts; JAX then says so itself)."""
    import os

    import jax

    from .private import jax_backends_initialized

    environ = os.environ if environ is None else environ
    requested = _check(work, device)
    users = environ.get("JAX_PLATFORMS", "").strip()
    if requested == "auto" and users:
        if check and any(p.strip() not in ("", "cpu") for p in users.split(",")):  # the CPU is always there
            _start_users_platforms(users)
        return contextlib.nullcontext(), f"running on JAX_PLATFORMS={users} (set in the environment; --device " \
                                         "overrides it)"
    if jax_backends_initialized():
        choice = select_devices(work, requested)
        return choice.default(), choice.statement()
    platforms, line = platforms_before_start(work, requested)
    before = jax.config.jax_platforms
    if platforms is not None:
        jax.config.update("jax_platforms", platforms)
    if check and requested in ("gpu", "tpu"):  # say it now, not as an internal error at the first computation
        try:
            jax.devices(requested)
        except STARTUP_ERRORS as err:
            jax.config.update("jax_platforms", before)  # a program that called main(argv) keeps its platforms
            raise PamjaxInputError(unavailable_message(requested, err)) from None
    return contextlib.nullcontext(), line
