"""pamjax's XLA CPU settings: small while loops compile to one CPU function (always, when pamjax is imported), and,
on request, XLA's classic CPU code generator for faster compilation (`PAMJAX_FAST_COMPILE`).

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
`XLA_FLAGS` alone. `pamjax.runtime.xla_cpu_status()` says whether it is active. Other backends ignore it: only the CPU
compiler reads the key, and XLA hands LLVM only extra options whose names do not start with `xla_`
(`llvm_ir::ExtractXlaBackendExtraOptions`).

**Faster compilation** (`prefer_fast_compilation`; the `pamjax` command for everything but `sweep`, and any process
with `PAMJAX_FAST_COMPILE=1` when pamjax is imported): `--xla_cpu_use_fusion_emitters=false`, i.e. XLA's classic
element-wise code generator for fused kernels instead of its MLIR fusion emitters, which compile every fused kernel
through an MLIR pipeline of its own (a new MLIR context with all its dialects per compilation; ~8 % of the test
suite's CPU time went to setting those up and tearing them down). Measured on this project's 2-core CPU
(docs/performance.md, "Faster compilation"): compilation of single-trajectory solves, gradients and fit Jacobians
13-30 % shorter, their run times unchanged within the noise (the 20-parameter fit: same iterations, same cost, same
seconds; `simulate` of the 25 s triangle within ~10 %); the test suite 384 -> 308 s. Not the default because
batched work runs slower with it: a 1,024-lane `sweep` RK4 2.5x, ROS2 1.6x, PWM 1.3x (the MLIR emitters vectorise
over the lanes better), so `pamjax sweep` and a plain `import pamjax` keep XLA's default. XLA aborts the process on
a flag it does not know, so it is only set for jaxlib versions known to have it (`FAST_COMPILE_JAXLIB`); elsewhere
the request is declined with the reason in `xla_cpu_status()`.

**Per program** (`single_trajectory_options`): a process without that flag (a plain `import pamjax`, `pamjax sweep`)
still compiles `pamjax.simulate`'s solve with the classic emitters when `simulate` is called outside any
transformation, through JAX's per-program `compiler_options` (the same XLA option, for that one program): the 25 s
triangle's `simulate` compiles 10-20 % faster (its XLA part 25-35 %) at the same run time, while a vmapped `simulate`
(a batched program, compiled by the enclosing transformation) and the sweeps keep XLA's default. An unknown option is
an error there, not an abort, but the same jaxlib range and opt-outs apply.

**Batched programs** (`batched_options`): a `sweep`'s compiled call over its lanes and a fit's forward-mode Jacobian
(a tangent per parameter) ask LLVM for 512-bit vectors (`xla_cpu_prefer_vector_width=512`, XLA's default 256) on a
CPU with AVX-512, per program; see `VECTOR_WIDTH`.
"""

import functools
import os
import re
import warnings
from collections.abc import MutableMapping

from .private import jax_backends_initialized

KEY = "xla_cpu_small_while_loop_byte_threshold"
THRESHOLD_BYTES = 100_000
OPT_OUT = "PAMJAX_XLA_CPU_TUNING"
FAST_COMPILE = "PAMJAX_FAST_COMPILE"  # "1": prefer_fast_compilation() at import; "0": never (the command line too)
EMITTER_FLAG = "xla_cpu_use_fusion_emitters"
# jaxlib releases whose XLA knows `xla_cpu_use_fusion_emitters` (XLA aborts the process on an unknown flag in
# XLA_FLAGS): (first, last) (major, minor), both included. The flag's name is in the shared libraries of the wheels of
# 0.5.3 and of every release from 0.6.0 to 0.10.2, not in 0.4.38's or 0.5.0's (searched 2026-11-25); XLA accepted it
# on 0.6.0, 0.8.0 and 0.10.2 (a computation run with it). A later minor release is declined until it is checked.
FAST_COMPILE_JAXLIB = ((0, 6), (0, 10))

# Batched programs on a CPU with AVX-512 (`batched_options`): LLVM's preferred vector width for XLA's code. XLA asks
# for 256-bit vectors by default, so a sweep's lanes ran 4 doubles per instruction on this project's AVX-512 host; at
# 512 bits, 8. Measured there (2026-11-26, the 1,024-duty x 5 s MAS-10 map, medians of 11, alternated): rodas5a
# 0.078 -> 0.061 s, rk4 0.31 -> 0.21 s, ros2 0.19 -> 0.17 s, the 128-duty PWM map 0.84 -> 0.57 s, same results and
# compilation; single trajectories (`simulate`) ran no faster or up to 10 % slower with it, so it is a per-program
# option for the batched programs only.
VECTOR_FLAG = "xla_cpu_prefer_vector_width"
VECTOR_WIDTH = 512

_status = {"active": False, "reason": "not applied yet", "fast_compile": False,
           "fast_compile_reason": f"not requested ({FAST_COMPILE} unset)"}
_applied = {}  # "flags": XLA_FLAGS as prefer_fast_compilation left them


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


def _off(value) -> bool:
    return str(value).strip().lower() in ("0", "false", "no", "off")


def _unknown_flag(environ, name):
    """Warn (at import: not an error) about an on/off variable set to a word that is neither, which is then left at
    its default: `PAMJAX_FAST_COMPILE=disabled` turned fast compilation ON (anything not "0"/"off" did); the command
    line refuses such a value (`pamjax._core.env.env_flag`)."""
    value = environ.get(name, "").strip()
    known = value.lower() in ("", "1", "true", "yes", "on", "0", "false", "no", "off")
    if not known:
        warnings.warn(f"pamjax: environment variable {name}={value!r} is neither on (1/true/yes/on) nor off "
                      "(0/false/no/off): left at its default", stacklevel=4)
    return not known


def apply(environ=os.environ) -> dict:
    """Add the setting to `environ["XLA_FLAGS"]` unless the user set the key, opted out, or JAX is already running;
    with `PAMJAX_FAST_COMPILE=1`, `prefer_fast_compilation` too."""
    flags = environ.get("XLA_FLAGS", "")
    users = re.search(rf"{KEY}=(\d+)", flags)
    if users is not None:  # the user's value is what XLA uses, whatever else is set
        value = int(users.group(1))
        _status.update(active=value >= THRESHOLD_BYTES, reason=(
            f"set by the user in XLA_FLAGS: {KEY}={value} (pamjax's value: {THRESHOLD_BYTES})"))
    elif not _unknown_flag(environ, OPT_OUT) and _off(environ.get(OPT_OUT, "1")):
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
    requested = "" if _unknown_flag(environ, FAST_COMPILE) else environ.get(FAST_COMPILE, "").strip()
    if requested and not _off(requested):
        prefer_fast_compilation(environ)
    else:
        users = _users_emitter_flag(environ)
        _status.update(fast_compile=users is not None and _off(users), fast_compile_reason=(
            f"not requested ({FAST_COMPILE}={requested or 'unset'}): XLA's default emitters" if users is None
            else f"set by the user in XLA_FLAGS: --{EMITTER_FLAG}={users}"))
    return dict(_status)


def _users_emitter_flag(environ):
    users = re.search(rf"--{EMITTER_FLAG}=(\S+)", environ.get("XLA_FLAGS", ""))
    return None if users is None else users.group(1)


def _opted_out(environ):
    """The variable that turns the classic emitters off (`PAMJAX_FAST_COMPILE=0` or `PAMJAX_XLA_CPU_TUNING=0`), or
    None."""
    return next((name for name in (FAST_COMPILE, OPT_OUT) if _off(environ.get(name, "1"))), None)


def _known_jaxlib(version) -> bool:
    return version is not None and FAST_COMPILE_JAXLIB[0] <= version <= FAST_COMPILE_JAXLIB[1]


@functools.cache
def _jaxlib_version():
    from importlib.metadata import PackageNotFoundError, version

    try:
        return tuple(int(part) for part in re.findall(r"\d+", version("jaxlib"))[:2])
    except (PackageNotFoundError, ValueError):
        return None


def prefer_fast_compilation(environ: MutableMapping[str, str] = os.environ) -> dict[str, bool | str]:
    """XLA's classic CPU code generator for fused kernels (`--xla_cpu_use_fusion_emitters=false` in XLA_FLAGS):
    single-trajectory solves, gradients and fits compile 13-30 % faster and run as fast; batched sweeps run
    1.3-2.5x slower (see the module's docstring). Call before JAX starts (the `pamjax` command does, for all its
    commands but `sweep`); a process started with `PAMJAX_FAST_COMPILE=1` gets it when pamjax is imported. Declined,
    with the reason in `xla_cpu_status()["fast_compile_reason"]`, when the user set the flag themselves, opted out
    (`PAMJAX_FAST_COMPILE=0` or `PAMJAX_XLA_CPU_TUNING=0`), JAX is already running, or this jaxlib is not one known
    to have the flag. Returns `xla_cpu_status()`."""
    flags = environ.get("XLA_FLAGS", "")
    if flags and flags == _applied.get("flags"):  # asked again (a script after the command line): already set here
        return dict(_status)
    users = _users_emitter_flag(environ)
    version = _jaxlib_version()
    if users is not None:
        _status.update(fast_compile=_off(users), fast_compile_reason=(
            f"set by the user in XLA_FLAGS: --{EMITTER_FLAG}={users}"))
    elif (which := _opted_out(environ)) is not None:
        _status.update(fast_compile=False, fast_compile_reason=f"{which}={environ[which]}: XLA's default emitters")
    elif _backends_initialised():
        _status.update(fast_compile=False, fast_compile_reason=(
            "JAX's backend was already running (XLA had read its flags): set it before JAX starts"))
    elif not _known_jaxlib(version):
        _status.update(fast_compile=False, fast_compile_reason=(
            f"jaxlib {'not found' if version is None else '.'.join(map(str, version))} is not one known to have "
            f"--{EMITTER_FLAG} (checked: {'.'.join(map(str, FAST_COMPILE_JAXLIB[0]))} to "
            f"{'.'.join(map(str, FAST_COMPILE_JAXLIB[1]))}; XLA aborts on a flag it does not know)"))
    else:
        environ["XLA_FLAGS"] = _applied["flags"] = f"{flags} --{EMITTER_FLAG}=false".strip()
        _status.update(fast_compile=True, fast_compile_reason=f"set by pamjax: --{EMITTER_FLAG}=false in XLA_FLAGS")
    return dict(_status)


def single_trajectory_options(environ=os.environ):
    """XLA compile options for one program that runs a single trajectory (`jax.jit(..., compiler_options=...)`;
    `pamjax.simulate` called outside any transformation): `{"xla_cpu_use_fusion_emitters": False}`, XLA's classic
    CPU code generator for that program alone. Its compilation is 25-35 % shorter (the 25 s triangle's solve 1.3 ->
    0.9 s) at the same run time, while batched programs compiled in the same process (a `sweep`, a vmapped `simulate`)
    keep XLA's default, under which they run 1.3-2.5x faster (module docstring). None, for XLA's default, when the
    process already compiles everything that way (`prefer_fast_compilation`), the user chose the emitters in
    XLA_FLAGS or opted out (`PAMJAX_FAST_COMPILE=0`, `PAMJAX_XLA_CPU_TUNING=0`), this jaxlib is not one known to have
    the option (`FAST_COMPILE_JAXLIB`; XLA refuses an unknown one), or the backend is not the CPU."""
    if (_status["fast_compile"] or _users_emitter_flag(environ) is not None or _opted_out(environ) is not None
            or not _known_jaxlib(_jaxlib_version()) or not _on_cpu()):
        return None
    return {EMITTER_FLAG: False}


def batched_options(platform: str, environ=os.environ) -> dict[str, int] | None:
    """XLA compile options for a batched program (a `sweep`'s lanes under `vmap`) on `platform`:
    `{VECTOR_FLAG: 512}` on a CPU with AVX-512 (see `VECTOR_WIDTH`), else None: another platform, a CPU without
    AVX-512, the user's own `--xla_cpu_prefer_vector_width` in XLA_FLAGS (theirs applies), `PAMJAX_XLA_CPU_TUNING=0`,
    or a jaxlib outside the checked range (`FAST_COMPILE_JAXLIB`; XLA refuses an option it does not know)."""
    if (platform != "cpu" or _off(environ.get(OPT_OUT, "1")) or f"--{VECTOR_FLAG}=" in environ.get("XLA_FLAGS", "")
            or not _known_jaxlib(_jaxlib_version()) or not _has_avx512()):
        return None
    return {VECTOR_FLAG: VECTOR_WIDTH}


def compiled_with(programs: dict, jit, fn, options: dict | None):
    """`jit(fn, compiler_options=options)` (`jit(fn)` for None options), made once and kept in `programs` under the
    options as a sorted tuple (or None): the one program per set of options of `simulate`'s solve, a sweep's lanes
    and a fit's Jacobian."""
    key = None if options is None else tuple(sorted(options.items()))
    program = programs.get(key)
    if program is None:
        program = programs[key] = jit(fn) if options is None else jit(fn, compiler_options=options)
    return program


@functools.cache
def _has_avx512() -> bool:
    """Whether this CPU has AVX-512 (its foundation, avx512f), from Linux's /proc/cpuinfo; False where that cannot
    be read (another OS: XLA's default width)."""
    try:
        with open("/proc/cpuinfo") as f:
            return re.search(r"^flags\s*:.*\bavx512f\b", f.read(), re.MULTILINE) is not None
    except OSError:
        return False


def xla_cpu_status() -> dict[str, bool | str]:
    """Whether pamjax's XLA CPU settings are in effect: `{"active": bool, "reason": str}` for the loop setting,
    `"fast_compile"`, `"fast_compile_reason"` for the classic code generator (`prefer_fast_compilation`; see
    `pamjax._core.xla_cpu`).

    Without the loop setting, single-trajectory solves and fits on CPU run about 4x slower (same results)."""
    return dict(_status)
