"""Runtime knobs: the persistent compilation cache, XLA's CPU settings, the device work runs on, and processes of a
distributed run.

    import pamjax.runtime
    pamjax.runtime.enable_compilation_cache()   # compiled programs kept on disk for the next process
    pamjax.runtime.disable_compilation_cache()  # none, JAX's own included (JAX_COMPILATION_CACHE_DIR)
    pamjax.runtime.xla_cpu_status()             # whether importing pamjax set its XLA CPU option
    placed, line = pamjax.runtime.for_command("single", "auto")  # before JAX starts: a fit's devices, said

None of these changes a result; they change how fast it comes (docs/performance.md, docs/sweeps.md).
"""

from ._core.cache import (
    CompileStats as CompileStats,
    disable_compilation_cache as disable_compilation_cache,
    enable_compilation_cache as enable_compilation_cache,
)
from ._core.devices import DeviceChoice as DeviceChoice, for_command as for_command, select_devices as select_devices
from ._core.distributed import (
    PamjaxDistributedError as PamjaxDistributedError,
    ProcessInfo as ProcessInfo,
    initialize_distributed as initialize_distributed,
)
from ._core.xla_cpu import prefer_fast_compilation as prefer_fast_compilation, xla_cpu_status as xla_cpu_status
