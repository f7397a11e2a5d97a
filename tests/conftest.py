import os
import tempfile

import jax

jax.config.update("jax_enable_x64", True)

# One persistent compilation cache for the whole test session, in a fresh temporary directory (never the user's
# cache): every xdist worker and every CLI or script subprocess the tests start reads and writes it, so a program
# that several test modules compile (the MAS-10 presets' solves above all) is compiled once per session instead of
# once per worker and process. This conftest is loaded by the controlling process before it starts the workers,
# which inherit the variables. PAMJAX_TEST_CACHE=0 turns it off (each process then compiles everything itself).
if os.environ.get("PAMJAX_TEST_CACHE", "1") != "0":
    if "PAMJAX_CACHE_DIR" not in os.environ:
        os.environ["PAMJAX_CACHE_DIR"] = tempfile.mkdtemp(prefix="pamjax-test-cache-")
    os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.environ["PAMJAX_CACHE_DIR"])  # scripts' own processes
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")
    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update("jax_persistent_cache_min_compile_time_secs",
                      float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]))
