"""JAX's persistent compilation cache for pamjax's command line: a second run of a workflow starts at once.

Compilation is most of a first run's time (a joint fit's residual and Jacobian programs, a sweep's batched loop:
seconds to tens of seconds; docs/performance.md). JAX can keep compiled programs on disk, keyed by the program, the
compiler options (the `XLA_FLAGS` included) and the JAX/XLA versions, and reuse them in the next process. The `pamjax`
command line turns that on by default; a Python program that imports pamjax decides for itself (call
`enable_compilation_cache()`).

Where: `$PAMJAX_CACHE_DIR` if set, else the user's cache directory (`$XDG_CACHE_HOME` or `~/.cache` on Linux,
`~/Library/Caches` on macOS, `%LOCALAPPDATA%` on Windows) under `pamjax/jax-compilation`. Off: `PAMJAX_COMPILATION_CACHE=0`
(or the CLI's `--no-cache`). Stale entries are harmless (a new key misses and compiles); the directory can be
deleted at any time.
"""

import os
import pathlib
import sys

OPT_OUT = "PAMJAX_COMPILATION_CACHE"
DIR_ENV = "PAMJAX_CACHE_DIR"
# s: programs that compiled faster than this are not written (reading a tiny entry costs about as much as compiling
# it; every pamjax solve, fit or sweep program takes longer than this to compile).
MIN_COMPILE_SECONDS = 0.5


def default_cache_dir() -> pathlib.Path:
    """The directory the CLI caches compiled programs in (see the module docstring)."""
    if os.environ.get(DIR_ENV):
        return pathlib.Path(os.environ[DIR_ENV]).expanduser()
    if sys.platform == "darwin":
        base = pathlib.Path.home() / "Library" / "Caches"
    elif sys.platform.startswith("win"):
        base = pathlib.Path(os.environ.get("LOCALAPPDATA", pathlib.Path.home() / "AppData" / "Local"))
    else:
        base = pathlib.Path(os.environ.get("XDG_CACHE_HOME") or pathlib.Path.home() / ".cache")
    return base / "pamjax" / "jax-compilation"


def cache_disabled() -> bool:
    return os.environ.get(OPT_OUT, "1").strip().lower() in ("0", "false", "no", "off")


def enable_compilation_cache(path=None):
    """Turn on JAX's persistent compilation cache in `path` (default `default_cache_dir()`). Returns the directory,
    or None when `PAMJAX_COMPILATION_CACHE=0` turns it off or the directory cannot be created (the run then just
    compiles, and says why)."""
    if cache_disabled():
        return None
    import jax

    path = pathlib.Path(path) if path is not None else default_cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".pamjax-write-test"
        probe.write_text("ok")
        probe.unlink()
    except OSError as err:
        print(f"pamjax: compilation cache off: cannot write {path} ({err.strerror}); set {DIR_ENV} to a writable "
              f"directory or {OPT_OUT}=0", file=sys.stderr)
        return None
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path


_PHASES = {  # jax.monitoring duration events → phase
    "/jax/core/compile/jaxpr_trace_duration": "trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
    "/jax/core/compile/backend_compile_duration": "compile",
}


class CompileStats:
    """What JAX compiles while active (a context manager): per phase ("trace": Python to jaxpr, "lower": jaxpr to
    StableHLO, "compile": XLA, or a persistent-cache read) the number of programs and the seconds, and of the
    persistent cache's `requests` its `hits` (`misses` = programs compiled anew). From `jax.monitoring`'s events;
    listeners cannot be removed, so an inactive one ignores events."""

    def __init__(self):
        self.count = dict.fromkeys(_PHASES.values(), 0)
        self.seconds = dict.fromkeys(_PHASES.values(), 0.0)
        self.requests = 0
        self.hits = 0
        self._active = False

    def _event(self, event, **kwargs):
        if not self._active:
            return
        if event == "/jax/compilation_cache/compile_requests_use_cache":
            self.requests += 1
        elif event == "/jax/compilation_cache/cache_hits":
            self.hits += 1

    def _duration(self, event, seconds, **kwargs):
        phase = _PHASES.get(event)
        if self._active and phase is not None:
            self.count[phase] += 1
            self.seconds[phase] += float(seconds)

    @property
    def misses(self):
        return self.requests - self.hits

    def summary(self):
        return (f"traced {self.count['trace']} in {self.seconds['trace']:.1f} s, lowered {self.count['lower']} in "
                f"{self.seconds['lower']:.1f} s, compiled {self.count['compile']} in {self.seconds['compile']:.1f} s"
                + (f" ({self.hits} of {self.requests} from the persistent cache)" if self.requests else ""))

    def __enter__(self):
        import jax

        jax.monitoring.register_event_listener(self._event)
        jax.monitoring.register_event_duration_secs_listener(self._duration)
        self._active = True
        return self

    def __exit__(self, *exc):
        self._active = False
        return False
