"""JAX's persistent compilation cache for pamjax's command line: a second run of a workflow starts at once.

Compilation is most of a first run's time (a joint fit's residual and Jacobian programs, a sweep's batched loop:
seconds to tens of seconds; docs/performance.md). JAX can keep compiled programs on disk, keyed by the program, the
compiler options (the `XLA_FLAGS` included) and the JAX/XLA versions, and reuse them in the next process. The `pamjax`
command line turns that on by default; a Python program that imports pamjax decides for itself (call
`enable_compilation_cache()`).

Where: `$PAMJAX_CACHE_DIR` if set, else the user's cache directory (`$XDG_CACHE_HOME` or `~/.cache` on Linux,
`~/Library/Caches` on macOS, `%LOCALAPPDATA%` on Windows) under `pamjax/jax-compilation`.
Off: `PAMJAX_COMPILATION_CACHE=0` (or the CLI's `--no-cache`; in the CLI both turn JAX's own off too,
`disable_compilation_cache()`, also where `JAX_COMPILATION_CACHE_DIR` turned it on). Stale entries are harmless (a
new key misses and compiles); the directory can be deleted at any time. `PAMJAX_CACHE_MIN_COMPILE_SECONDS`
(default 0.1) sets the shortest compilation kept. A value these variables do not take is refused, named.
"""

import os
import pathlib
import sys
import threading

from .cache_switch import point_jax_cache, turn_off_jax_cache
from .code_stamp import code_stamp
from .compile_stats import CompileStats as CompileStats  # public in pamjax.runtime
from .env import env_flag, env_seconds
from .errors import PamjaxInputError

OPT_OUT = "PAMJAX_COMPILATION_CACHE"
DIR_ENV = "PAMJAX_CACHE_DIR"
# s: programs that compiled faster than this are not written (reading a tiny entry costs about as much as compiling
# it). Low enough to keep the helpers a workflow compiles beside its solve (start states, statistics: 0.1-0.5 s).
MIN_COMPILE_SECONDS = 0.1


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
    return not env_flag(OPT_OUT, True)  # a value other than on/off words is refused (`env_flag`)


def enable_compilation_cache(path: str | os.PathLike[str] | None = None) -> pathlib.Path | None:
    """Turn on JAX's persistent compilation cache in `path` (default, also for "" as for an empty `PAMJAX_CACHE_DIR`:
    `default_cache_dir()`). Returns the directory, or None when `PAMJAX_COMPILATION_CACHE=0` turns it off or the
    directory cannot be created (the run then just compiles, and says why). A `path` that is no path, or a bad
    environment variable, is a `PamjaxInputError`."""
    if path is not None and not isinstance(path, str | os.PathLike):
        raise PamjaxInputError(f"enable_compilation_cache: path must be a folder (str or os.PathLike) or None for "
                               f"the default, got {path!r}")
    path = None if path is None or not str(os.fspath(path)).strip() else path
    if cache_disabled():
        return None
    minimum = env_seconds("PAMJAX_CACHE_MIN_COMPILE_SECONDS", MIN_COMPILE_SECONDS)  # before anything is made
    import jax

    path = pathlib.Path(path).expanduser() if path is not None else default_cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".pamjax-write-test"
        probe.write_text("ok")
        probe.unlink()
    except OSError as err:
        print(f"pamjax: compilation cache off: cannot write {path} ({err.strerror}); set {DIR_ENV} to a writable "
              f"directory or {OPT_OUT}=0", file=sys.stderr)
        if not jax.config.jax_compilation_cache_dir:  # off, as said (a fit then said "enable_compilation_cache()")
            disable_compilation_cache()
        return None
    point_jax_cache(str(path), minimum)  # on again after `disable_compilation_cache`, moved after compilations
    return path


def disable_compilation_cache() -> None:
    """Turn off, for this process, both JAX's persistent compilation cache and pamjax's traced programs beside it
    (`program_cache()` then returns None), also where `JAX_COMPILATION_CACHE_DIR` in the environment turned JAX's on:
    the CLI's `--no-cache` and `PAMJAX_COMPILATION_CACHE=0`. From the next compilation on, also after programs were
    compiled with it (`cache_switch.py`)."""
    turn_off_jax_cache()


def cache_turned_off():
    """Whether this process turned JAX's persistent compilation cache off (`disable_compilation_cache`)."""
    import jax

    return not jax.config.jax_enable_compilation_cache


class ProgramCache:
    """Traced programs kept on disk beside the compiled ones, so that a second run skips tracing too.

    JAX's persistent cache keeps XLA's compiled code, keyed by the lowered program: a second run still traces and
    lowers its Python functions to find that key (a fit's forward-mode Jacobian through the stick-slip grid: seconds).
    `call(name, fn, args)` looks for `fn` already traced for arguments of this structure (`jax.export`, serialized
    StableHLO); if found it calls that, compiling through the persistent cache; if not it traces, exports, saves and
    calls. The key is a SHA-256 of the arguments' structure (classes, static fields, array shapes and dtypes, never
    array values), the function's name, the pamjax, jax and jaxlib versions, the XLA flags and the platform and
    devices it runs on (an export is lowered for one platform: a program exported on a GPU is refused on the CPU, as
    `JAX_PLATFORMS=cpu` makes it): another structure, version or platform traces anew. An entry that cannot be used
    all the same (foreign, stale, damaged) is traced anew and replaced, never an error. Active only where the
    persistent compilation cache is on (the CLI); otherwise `call` is `fn(*args)`. `fn` must be a pure function of
    its array arguments (as every jitted pamjax function is).

    Loading an exported program still lowers it (StableHLO → XLA, ~0.3 s for a fit's Jacobian) before the persistent
    cache can find its compiled code; so the compiled executable itself is kept too (`executables/`, JAX's
    `serialize_executable`, keyed as the program plus this machine: platform, its version, devices, the process's own
    devices, CPU), and a later run loads it directly. Any failure there falls back to the exported program."""

    def __init__(self, directory):
        self.directory = pathlib.Path(directory) / "programs"
        self.executables = pathlib.Path(directory) / "executables"
        self.memory = {}  # key → jitted caller of the exported program
        self.keys = {}  # (name, argument ids or array shapes) → (key, the arguments, their flattening)

    @staticmethod
    def key(name, args):
        """The SHA-256 (32 hex digits) of what the program traced from `args` depends on: the pytree structure,
        every static field and non-array value (tracing bakes them in), the arrays' shapes and dtypes (never their
        values: they are the program's arguments), `name`, the versions, the XLA flags and the x64 setting, and the
        code (`code_stamp`: pamjax's source files and those of every class and function in `args`, by their contents
        — an edited model, pamjax's own in an editable install or a user's component, traces anew). A
        canonical description (`describe(args, values=False)`), not a `repr`: equinox's pretty-printer cost ~50 ms
        per call. None where some code in `args` has no source file (a class defined in a notebook or at the
        prompt): such a program is compiled in this process only."""
        import hashlib

        import jax

        from .describe import describe

        code = code_stamp(args)
        if code is None:  # code whose source cannot be told apart from an edited one: never from or to the disk
            return None
        text = repr((name, describe(args, values=False), _versions(), os.environ.get("XLA_FLAGS", ""),
                     bool(jax.config.jax_enable_x64), _platform(), code))
        return hashlib.sha256(text.encode()).hexdigest()[:32]

    @staticmethod
    def _named(name, options):
        """The program's name with its compile options (another executable, another file)."""
        return name if not options else name + "".join(f"-{k}={v}" for k, v in sorted(options.items()))

    def has(self, name, args, options=None):
        """Whether `name` is already traced for arguments of this structure (on disk or in this process)."""
        name = self._named(name, options)
        key = self._entry(name, args)[0]  # the key `call` then reuses (describing the arguments: ~15 ms)
        return key in self.memory or (not key.startswith(_LOCAL) and (self.directory / f"{name}-{key}.bin").exists())

    def _entry(self, name, args):
        """(key, args, treedef, static, parts) of `args` for program `name`, computed once in this process per set of
        non-array argument objects (a fit's parameter space and experiments; θ is a new array at every call) and
        array shapes: the key describes the whole structure (a few ms). The entry keeps the objects alive, so that no
        other object can later reuse one of their ids (they are immutable pytrees)."""
        import equinox as eqx
        import jax

        ids = (name, tuple(("array", a.shape, str(a.dtype), bool(getattr(a, "weak_type", False))) if eqx.is_array(a)
                           else id(a) for a in args))
        entry = self.keys.get(ids)
        if entry is None:
            dynamic, static = eqx.partition(args, eqx.is_array)
            treedef = jax.tree_util.tree_structure(dynamic)
            parts = [None if eqx.is_array(a) else jax.tree_util.tree_leaves(d) for a, d in zip(args, dynamic)]
            key = self.key(name, args)
            if key is None:  # this process's own: `_local` keys never name a file
                key = f"{_LOCAL}{len(self.keys)}"
            entry = self.keys[ids] = (key, args, treedef, static, parts)
        return entry

    def call(self, name, fn, args, ready=None, options=None):
        """`fn(*args)`, compiled once per argument structure (see the class docstring). `ready`, if given, is called
        once the Python side of a first call is done (traced, exported, lowered), before XLA compiles or loads the
        program: the moment another thread's Python work no longer competes with this one. `options`: XLA compile
        options of the program (part of its name: kept apart from the same program without them)."""
        import equinox as eqx
        import jax

        name = self._named(name, options)
        key, _, treedef, static, parts = self._entry(name, args)  # the key and flattening, once per structure
        leaves = [x for a, part in zip(args, parts) for x in ((a,) if part is None else part)]
        caller = self.memory.get(key)
        if caller is None:

            def flat(*xs):
                return fn(*eqx.combine(jax.tree_util.tree_unflatten(treedef, xs), static))

            caller = self.memory[key] = self._caller(name, key, flat, leaves, ready or (lambda: None), options)
        elif ready is not None:
            ready()
        return caller(*leaves)

    def preload(self, name, args, options=None):
        """Load the executable kept for program `name` and arguments of this structure, if any, so that `call` finds
        it in memory; True if it is there now. Nothing is traced or compiled, and the loading (~0.1 s for a fit's
        Jacobian) releases Python's lock: another thread's Python (an import) runs meanwhile."""
        name = self._named(name, options)
        key = self._entry(name, args)[0]
        if key not in self.memory:
            if key.startswith(_LOCAL):
                return False
            compiled = self._load_executable(self.executables / f"{name}-{key}-{_machine()}.exe")
            if compiled is None:
                return False
            self.memory.setdefault(key, compiled)
        return True

    def structural(self, name, fn, args):
        """`fn(*args)` for a `fn` whose result depends on the arguments' structure alone (what `key` describes: shape
        inference, e.g. `jax.eval_shape`; never array values) and pickles: kept on disk per structure, so that a
        second run does not trace it again (a fit's set-up checks: ~0.1 s of tracing in a warm `pamjax fit`).
        An error is raised as `fn` raises it, and nothing is kept; an entry that cannot be read is computed anew."""
        import pickle

        key = self._entry(name, args)[0]
        path = self.directory / f"{name}-{key}.pkl"
        if key in self.memory:
            return self.memory[key]
        if key.startswith(_LOCAL):
            result = self.memory[key] = fn(*args)
            return result
        try:
            result = pickle.loads(path.read_bytes())
        except Exception:  # noqa: BLE001 - missing, damaged or stale: computed anew (and replaced)
            result = fn(*args)
            try:
                data = pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL)
            except Exception:  # noqa: BLE001 - a result that does not pickle: used in this process only
                data = None
            if data is not None:
                self._save(path, data)
        self.memory[key] = result
        return result

    def _caller(self, name, key, flat, leaves, ready, options=None):
        """The compiled program: this machine's executable if kept, else the exported program (traced and exported
        now if not kept either) compiled through the persistent cache, its executable then kept."""
        import jax

        if key.startswith(_LOCAL):  # compiled through JAX's own cache only (keyed by the lowered program: safe)
            ready()
            return jax.jit(flat, compiler_options=options)
        executable = self.executables / f"{name}-{key}-{_machine()}.exe"
        if executable.exists():
            ready()
            compiled = self._load_executable(executable)
            if compiled is not None:
                return compiled
        path = self.directory / f"{name}-{key}.bin"
        exported = self._load(path)
        lowered = None
        if exported is not None:
            try:  # an entry exported for another platform, or by another jax, cannot be lowered here: trace anew
                lowered = jax.jit(exported.call).lower(*leaves)
            except Exception:  # noqa: BLE001 - whatever the entry's fault, the remedy is to trace again
                exported = None
        if exported is None:
            try:
                exported = jax.export.export(jax.jit(flat))(*leaves)
            except NotImplementedError:  # e.g. a host callback in the program: not exportable, jit it as usual
                ready()
                return jax.jit(flat, compiler_options=options)
            self._save(path, exported.serialize())
        hits = _persistent_hits()
        if lowered is None:
            lowered = jax.jit(exported.call).lower(*leaves)
        ready()
        compiled = lowered.compile(options)
        if _persistent_hits() == hits:  # compiled here: an executable read from JAX's cache does not serialize whole
            self._save_executable(executable, compiled)
        return compiled

    @staticmethod
    def _load(path):
        import jax

        if not path.exists():
            return None
        try:
            return jax.export.deserialize(bytearray(path.read_bytes()))
        except Exception:  # an unreadable or stale entry: trace anew (and replace it)
            return None

    @staticmethod
    def _save(path, data):
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(path.name + f".{os.getpid()}.{threading.get_ident()}.tmp")
            tmp.write_bytes(data)
            tmp.replace(path)
        except OSError:
            pass  # a read-only cache: the program is still used in this process

    @staticmethod
    def _load_executable(path):
        if not path.exists():
            return None
        try:
            import pickle
            import zlib

            from jax.experimental.serialize_executable import deserialize_and_load

            payload, in_tree, out_tree = pickle.loads(zlib.decompress(path.read_bytes()))
            return deserialize_and_load(payload, in_tree, out_tree)
        except Exception:  # unreadable, stale or not loadable here: compile from the exported program (and replace)
            return None

    def _save_executable(self, path, compiled):
        try:
            import pickle
            import zlib

            from jax.experimental.serialize_executable import serialize

            data = zlib.compress(pickle.dumps(serialize(compiled), protocol=pickle.HIGHEST_PROTOCOL), 1)
        except Exception:  # an executable this backend cannot serialize: the exported program is kept
            return
        self._save(path, data)


_LOCAL = "local-"  # the prefix of a key that `ProgramCache.key` could not make (see there)


def _versions():
    """The pamjax, jax and jaxlib versions (read once per process: ~5 ms each from the package metadata)."""
    if "versions" not in _PROGRAMS:
        import importlib.metadata

        versions = []
        for package in ("pamjax", "jax", "jaxlib"):
            try:
                versions.append(importlib.metadata.version(package))
            except importlib.metadata.PackageNotFoundError:  # a source checkout without metadata
                versions.append("?")
        _PROGRAMS["versions"] = tuple(versions)
    return _PROGRAMS["versions"]


_HITS = {}  # thread → JAX persistent-cache hits seen in it


def _persistent_hits():
    """How many programs this thread has read from JAX's persistent cache (a listener counts them)."""
    if "listener" not in _PROGRAMS:
        import jax

        def listener(event, **kwargs):
            if event == "/jax/compilation_cache/cache_hits":
                _HITS[threading.get_ident()] = _HITS.get(threading.get_ident(), 0) + 1

        jax.monitoring.register_event_listener(listener)
        _PROGRAMS["listener"] = listener
    return _HITS.get(threading.get_ident(), 0)


def _platform():
    """What an exported program is specific to: the default backend's platform ("cpu", "cuda", ...), its version,
    and the kinds and number of its devices (read once per process)."""
    if "platform" not in _PROGRAMS:
        import jax

        devices = jax.devices()
        _PROGRAMS["platform"] = (jax.default_backend(), getattr(devices[0].client, "platform_version", "?"),
                                 sorted({d.device_kind for d in devices}), len(devices))
    return _PROGRAMS["platform"]


def _machine():
    """A digest of what a compiled executable is specific to: the platform and its version, the devices, the
    process's own devices (an executable runs on the device it was compiled for: in a multi-process run, process 1
    loading process 0's executable failed with "Expected args to execute_sharded_on_local_devices to have 1 shards,
    got: [0, …]" — tests/test_distributed.py, whichever process compiled first), and on Linux the CPU's model and
    instruction-set flags (XLA compiles for the host CPU)."""
    if "machine" not in _PROGRAMS:
        import hashlib
        import platform

        import jax

        devices = jax.devices()
        parts = [platform.machine(), devices[0].platform, getattr(devices[0].client, "platform_version", "?"),
                 [d.device_kind for d in devices], jax.process_index(), [d.id for d in jax.local_devices()]]
        try:
            with open("/proc/cpuinfo") as f:
                parts += [line.strip() for line in f if line.startswith(("model name", "flags"))][:2]
        except OSError:
            pass
        _PROGRAMS["machine"] = hashlib.sha256(repr(parts).encode()).hexdigest()[:12]
    return _PROGRAMS["machine"]


_PROGRAMS = {"cache": None}


def program_cache():
    """The `ProgramCache` of the persistent compilation cache's directory, or None when that cache is off (no
    directory, or `jax_enable_compilation_cache` false: `disable_compilation_cache()`)."""
    import jax

    directory = jax.config.jax_compilation_cache_dir
    if not directory or not jax.config.jax_enable_compilation_cache:
        return None
    cache = _PROGRAMS["cache"]
    if cache is None or cache.directory.parent != pathlib.Path(directory):
        cache = _PROGRAMS["cache"] = ProgramCache(directory)
    return cache


def structural(name, fn, *args):
    """`fn(*args)`, kept per argument structure by the CLI's `ProgramCache` where the persistent cache is on
    (`ProgramCache.structural`: `fn`'s result must depend on the arguments' structure alone), else computed."""
    programs = program_cache()
    return fn(*args) if programs is None else programs.structural(name, fn, args)


class announce_compilation:  # noqa: N801 - used as a context manager, like contextlib's
    """Say when a piece of work is compiling (a context manager for the CLI's commands): once it has been busy for
    `after` seconds, one line "LABEL: compiling … (first run; cached afterwards)" as soon as JAX is compiling: with
    the persistent cache empty (or off), as soon as JAX has done any work; with programs in it, once a program that
    the cache would keep (≥ `MIN_COMPILE_SECONDS`) was compiled anew instead of read. Never for a run whose programs
    all come from the cache, nor for work that does not involve JAX. At the end, when tracing, lowering and
    compilation took more than `after` seconds (or were announced), "LABEL: compiled in N s" (or, when every
    program came from the cache, "LABEL: traced its programs and read them from the cache in N s") with what
    was traced, lowered, compiled and read from the cache."""

    POLL_S = 0.25  # how often the condition is checked once `after` has passed

    def __init__(self, label, after=2.0, stream=None):
        self.label, self.after = label, after
        self.stream = stream if stream is not None else sys.stdout
        self.stats = CompileStats()
        self._said = False

    @staticmethod
    def _cache_directory():
        """JAX's persistent cache directory, None when it is off (`PAMJAX_COMPILATION_CACHE=0`, `--no-cache`)."""
        import jax

        directory = jax.config.jax_compilation_cache_dir
        off = cache_disabled() or not directory or not jax.config.jax_enable_compilation_cache
        return None if off else pathlib.Path(directory)

    @staticmethod
    def _cache_is_empty(directory):
        """Whether the persistent cache is off (`directory` None) or holds no program yet (no file of its own)."""
        try:
            return directory is None or not any(p.is_file() for p in directory.iterdir())
        except OSError:
            return True

    def compiling(self):
        """Whether JAX is compiling anew (rather than reading its persistent cache, or not working at all)."""
        if self._first_run:
            return any(self.stats.count.values())
        return self.stats.longest_anew_s >= MIN_COMPILE_SECONDS

    def _watch(self):
        if self._done.wait(self.after):
            return
        while not self._done.is_set():
            if self.compiling():
                why = "first run; cached afterwards" if self._directory is not None else "the cache is off"
                print(f"{self.label}: compiling … ({why})", file=self.stream, flush=True)
                self._said = True
                return
            self._done.wait(self.POLL_S)

    def __enter__(self):
        self._directory = self._cache_directory()
        self._first_run = self._cache_is_empty(self._directory)
        self.stats.__enter__()
        self._done = threading.Event()
        self._watcher = threading.Thread(target=self._watch, daemon=True)
        self._watcher.start()
        return self

    def __exit__(self, *exc):
        self._done.set()
        self._watcher.join()
        self.stats.__exit__(*exc)
        seconds = sum(self.stats.seconds.values())
        if exc[0] is None and (self._said or seconds > self.after):
            done = ("compiled in" if self._said or self._first_run or self.compiling()
                    else "traced its programs and read them from the cache in")
            print(f"{self.label}: {done} {seconds:.1f} s ({self.stats.summary()})", file=self.stream, flush=True)
        return False
