"""The one XLA setting pamjax makes when it is imported: small while loops compile to one CPU function.

Why: XLA's CPU runtime executes a compiled program as a sequence of "thunks", one per fused kernel, matrix product
or loop. A single-trajectory ODE solve is a while loop whose body is ~150 tiny kernels on 3-4 numbers, so the
per-kernel dispatch is most of its cost: paper 000's 25 s triangle run (averaged valve, RODAS5, ~800 steps) took
4.9 ms as thunks and 1.1 ms as one function (benchmarks/simulate.py, RESULTS.md runs s4-s7); the 20-parameter
joint fit 10.1-11.7 s and 2.0-2.8 s after compilation (benchmarks/fit.py). XLA already compiles a loop to one
function when it touches fewer than `xla_cpu_small_while_loop_byte_threshold` bytes per iteration (default 1,024,
XLA's `SmallWhileLoopHoistingPass`); pamjax raises that threshold to `THRESHOLD_BYTES`.

Why not higher: a batched loop (a `sweep` over many lanes) is faster as thunks, whose kernels are vectorised over the
lanes (1,024-lane sweep measured both ways: RODAS5 0.054 s as thunks vs 0.078 s as one function, PWM RK4 2.8 s vs
8.5 s). Measured per-iteration sizes: `simulate`'s loops < 30 kB (any number of output times: the output buffer
is written one slice per step), the 20-parameter fit's forward-mode Jacobians through them are hoisted at 100 kB,
`sweep` loops of 16 lanes or more exceed 1 MB.

XLA reads its flags once, when JAX initialises its backend (the first array or computation), so the setting only
takes effect if pamjax is imported before that. It is added to the `XLA_FLAGS` environment variable (merged into an
existing `--xla_backend_extra_options`), never replacing a value the user set; `PAMJAX_XLA_CPU_TUNING=0` leaves
`XLA_FLAGS` alone. `pamjax.xla_cpu_status()` says whether it is active. Other backends ignore it: only the CPU
compiler reads the key, and XLA hands LLVM only extra options whose names do not start with `xla_`
(`llvm_ir::ExtractXlaBackendExtraOptions`).
"""

import os
import re
import warnings

from .private import jax_backends_initialized

KEY = "xla_cpu_small_while_loop_byte_threshold"
THRESHOLD_BYTES = 100_000
OPT_OUT = "PAMJAX_XLA_CPU_TUNING"

_status = {"active": False, "reason": "not applied yet"}


def _backends_initialised() -> bool:
    return jax_backends_initialized()  # False if the private name moved (the setting may then silently not apply)


def _on_cpu() -> bool:
    try:
        import jax

        return jax.default_backend() == "cpu"
    except Exception:
        return False


def merged_flags(flags: str, threshold: int = THRESHOLD_BYTES) -> str:
    """`flags` (an XLA_FLAGS value) with `KEY=threshold` added to its `--xla_backend_extra_options`."""
    entry = f"{KEY}={int(threshold)}"
    match = re.search(r"--xla_backend_extra_options=(\S*)", flags)
    if match is None:
        return f"{flags} --xla_backend_extra_options={entry}".strip()
    existing = match.group(1)
    joined = f"{existing},{entry}" if existing else entry
    return flags[: match.start(1)] + joined + flags[match.end(1):]


def apply(environ=os.environ) -> dict:
    """Add the setting to `environ["XLA_FLAGS"]` unless the user set the key, opted out, or JAX is already running."""
    flags = environ.get("XLA_FLAGS", "")
    users = re.search(rf"{KEY}=(\d+)", flags)
    if users is not None:  # the user's value is what XLA uses, whatever else is set
        value = int(users.group(1))
        _status.update(active=value >= THRESHOLD_BYTES, reason=(
            f"set by the user in XLA_FLAGS: {KEY}={value} (pamjax's value: {THRESHOLD_BYTES})"))
    elif environ.get(OPT_OUT, "1").strip().lower() in ("0", "false", "no", "off"):
        _status.update(active=False, reason=f"{OPT_OUT}={environ[OPT_OUT]}: XLA_FLAGS left as they are")
    elif _backends_initialised():
        _status.update(active=False, reason=(
            "JAX's backend was initialised before pamjax was imported, so XLA had already read its flags: import "
            f"pamjax first, or start Python with XLA_FLAGS=--xla_backend_extra_options={KEY}={THRESHOLD_BYTES}"))
        if _on_cpu():
            warnings.warn(f"pamjax: single-trajectory solves and fits will run ~4x slower on this CPU: "
                          f"{_status['reason']} (or set {OPT_OUT}=0 to silence this)", stacklevel=3)
    else:
        environ["XLA_FLAGS"] = merged_flags(flags)
        _status.update(active=True, reason=f"set by pamjax: {KEY}={THRESHOLD_BYTES} in XLA_FLAGS")
    return dict(_status)


def xla_cpu_status() -> dict:
    """Whether pamjax's XLA CPU loop setting is in effect: `{"active": bool, "reason": str}` (see
    `pamjax._core.xla_cpu`).

    Without it, single-trajectory solves and fits on CPU run about 4x slower (same results)."""
    return dict(_status)
