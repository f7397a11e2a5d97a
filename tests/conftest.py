import gc
import os
import shutil
import tempfile

# The tests run single trajectories, gradients and fits, which the `pamjax` command's fit/simulate/demo compile with
# XLA's classic CPU code generator: 13-30 % faster compilation at the same run time (pamjax._core.xla_cpu,
# docs/performance.md "Faster compilation"); the suite takes about a fifth less time. The variable reaches pamjax's
# import in the xdist workers and in every subprocess the tests start (they inherit it), before JAX starts there.
# PAMJAX_FAST_COMPILE=0 runs the suite with XLA's default emitters (every test passes either way).
os.environ.setdefault("PAMJAX_FAST_COMPILE", "1")

# The suite is compilation-bound: most of its programs run for milliseconds after seconds of compiling. XLA's LLVM
# back end at optimisation level 0 compiles them faster, and the code it makes runs slower: the whole suite 483 →
# 391 s on the 2-core CPU (1,365 tests, every one passing either way; no module slower by more than a second; a user's
# 40 s rig fit would be the other way round: compilation 8.3 → 6.2 s, the fit 30 → 43 s, so pamjax itself keeps
# XLA's default). Only the back end's level changes: the same programs (XLA's own optimisations and fusions), the same
# IEEE float64 arithmetic, the same assertions. Set here, before JAX starts, for the xdist workers and every
# subprocess the tests start; a level in the user's XLA_FLAGS is kept, and PAMJAX_TEST_XLA_OPT=default keeps XLA's.
if (os.environ.get("PAMJAX_TEST_XLA_OPT") != "default"
        and "--xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", "")):
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} --xla_backend_optimization_level=0".strip()

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

# One persistent compilation cache for the whole test session, in a fresh temporary directory (never the user's
# cache): every xdist worker and every CLI or script subprocess the tests start reads and writes it, so a program
# that several test modules compile (the MAS-10 presets' solves above all) is compiled once per session instead of
# once per worker and process. This conftest is loaded by the controlling process before it starts the workers,
# which inherit the variables. PAMJAX_TEST_CACHE=0 turns it off (each process then compiles everything itself).
# The process that made the directory (the controlling one) removes it when the session ends (`pytest_unconfigure`):
# 70 MB per run were left in the temporary folder before.
_MADE_CACHE = None
if os.environ.get("PAMJAX_TEST_CACHE", "1") != "0":
    if "PAMJAX_CACHE_DIR" not in os.environ:
        os.environ["PAMJAX_CACHE_DIR"] = _MADE_CACHE = tempfile.mkdtemp(prefix="pamjax-test-cache-")
    os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.environ["PAMJAX_CACHE_DIR"])  # scripts' own processes
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")
    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update("jax_persistent_cache_min_compile_time_secs",
                      float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]))


# The suite's longest modules first (their serial seconds in a full run, heaviest first: `pytest --durations=0`,
# summed per module). xdist's `--dist loadscope --no-loadscope-reorder` hands whole modules to the workers in
# collection order (by default it would order them by their number of tests, a poor guess of their time); started
# last, a module of several minutes would run alone on one core at the end while the other core idles. Only the
# order changes: every test still runs, the tests of a module in their own order. Modules not listed follow in their
# usual (alphabetical) order.
HEAVY_FIRST = [
    "test_gallery.py", "test_design.py", "test_simulate.py", "test_simulate_edges.py",
    "test_grid.py", "test_rodas.py", "test_synchronous.py", "test_hints.py", "test_fits_regulator.py", "test_bench.py",
    "test_joint_control.py", "test_control.py", "reliability/test_nan_safety.py", "test_sweep.py",
    "reliability/test_gradients.py", "test_distributed.py", "test_fit.py", "test_joint.py", "test_valve.py",
    "test_cache.py", "test_regulator.py", "test_sweep_maps.py",
]


def pytest_collection_modifyitems(session, config, items):
    here = os.path.dirname(os.path.abspath(__file__))
    rank = {name: i for i, name in enumerate(HEAVY_FIRST)}

    def module_rank(item):
        path = os.path.relpath(str(item.path), here).replace(os.sep, "/")
        return rank.get(path, len(HEAVY_FIRST))

    items.sort(key=module_rank)  # stable: the rest keep their order, a module's tests theirs


# Python's cyclic garbage collector, tuned for a process that traces thousands of JAX programs. Tracing allocates
# millions of short-lived objects, so CPython's default thresholds (a young collection every 700 net allocations)
# start a full collection every few thousand, and each full collection walks every object the worker holds: the
# imported libraries and every compiled program and fixture kept so far. Measured with `gc.callbacks` on
# test_simulate + test_grid + test_design run serially: 11.3 s of 139 s in the collector (10.0 s of it full
# collections). What is alive once the worker has imported and collected everything is moved out of the collector's
# way (`gc.freeze`: never freed, never walked again), and the young generation is collected every 50,000 allocations:
# 3.3 s. Reference counting still frees everything that is not in a cycle at once; the cycles wait a little longer.
# Nothing a test computes depends on it. PAMJAX_TEST_GC=default keeps CPython's defaults.
def _tune_gc():
    if os.environ.get("PAMJAX_TEST_GC") != "default":
        gc.collect()
        gc.freeze()
        gc.set_threshold(50_000, 20, 100)


def pytest_configure(config):
    _tune_gc()  # the libraries imported by now (JAX, the conftest's own)


def pytest_unconfigure(config):
    if _MADE_CACHE is not None and not hasattr(config, "workerinput"):  # the workers have ended by now
        shutil.rmtree(_MADE_CACHE, ignore_errors=True)


def pytest_collection_finish(session):
    _tune_gc()  # pamjax, SciPy, matplotlib and the test modules, once collected
