"""One process of `tests/test_distributed.py`: a sweep and a multistart fit, alone or as process i of n.

    python tests/distributed_worker.py OUT_DIR                          # single process (the reference)
    python tests/distributed_worker.py OUT_DIR PROCESS_ID N PORT        # process PROCESS_ID of N, coordinator :PORT

Writes OUT_DIR/sweep-<p>.npz (whole result and this process's shard) and OUT_DIR/multistart-<p>.json, p being
"single" or the process id.
"""

import json
import pathlib
import sys
import time

started = time.perf_counter()

out = pathlib.Path(sys.argv[1])
import pamjax  # noqa: E402  (joins before JAX starts its backend)

if len(sys.argv) > 2:
    process_id, count, port = int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    info = pamjax.runtime.initialize_distributed(f"127.0.0.1:{port}", count, process_id, timeout=60)
    print(info, flush=True)
    tag = str(process_id)
else:
    tag = "single"

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402
from problems import FORCE_MAP_FREE, fit_fields, force_map  # noqa: E402  (tests/problems.py, beside this file)

from pamjax import presets  # noqa: E402

assert jax.local_device_count() == (1 if tag != "single" else 4), jax.local_devices()
assert pamjax.runtime.xla_cpu_status()["active"], pamjax.runtime.xla_cpu_status()
# the reference process has 4 CPU devices: 2 of them (the distributed run's mesh size), all 4, and 1
devices = {"": None} if tag != "single" else {"": jax.devices()[:2], "4": jax.devices(), "1": jax.devices()[:1]}

# --- sweep: 12 points, RK4 at 1 ms; point 5 has a viscous coefficient of 1e6 N s/m, whose eigenvalue (-1e5 /s)
# makes RK4 overflow there (tests/test_sweep.py): a per-point failure.
system = presets.mas10_system(valve="averaged")
ts = np.linspace(0.0, 0.3, 7)
viscous = np.full(12, 250.0)
viscous[5] = 1e6
over = {"signal.value": np.linspace(0.15, 0.85, 12), "friction.viscous_coefficient": viscous}
kwargs = dict(channels=("pressure", "position"), method="rk4", dt=1e-3, progress=False)
arrays = {}
for name, chosen in devices.items():
    whole = pamjax.sweep(system, pamjax.Constant(0.5), ts, over, chunk_size=4, devices=chosen, **kwargs)
    arrays.update({f"status{name}": whole.status, f"pressure{name}": whole["pressure"],
                   f"position{name}": whole["position"]})
split = pamjax.sweep(system, pamjax.Constant(0.5), ts, over, devices=devices[""], **kwargs)  # default chunks
arrays["split_position"] = split["position"]
shard = pamjax.sweep(system, pamjax.Constant(0.5), ts, over, chunk_size=4, gather="local",
                     devices=devices[""], **kwargs)
np.savez(out / f"sweep-{tag}.npz", shard_points=shard.points, shard_status=shard.status,
         shard_position=shard["position"], **arrays)
if tag == "single":  # the reference of `pamjax sweep --distributed` (tests/test_distributed.py's CONFIG), 2 devices
    ss = pamjax.steady_state_map(system, np.linspace(0.1, 0.9, 12), horizon=0.5, window=0.1, method="rk4", dt=1e-3,
                                 devices=devices[""], progress=False)
    np.savez(out / "steady_state-single.npz", pressure=ss["pressure"], position=ss["position"], status=ss.status)

# --- multistart: paper 000's static force map (9 lengths x 7 pressures, 2 N noise), 7 parameters; four starts,
# the third with a NaN value (its fit refuses it: a per-start failure, recorded).
muscle, experiment = force_map()
free = FORCE_MAP_FREE
truth = np.asarray(pamjax.ParameterSpace(muscle, free).initial_values())
starts = np.stack([truth * 0.7, truth * 1.3, truth, truth * 0.9])
starts[2, 0] = np.nan
result = pamjax.multistart(muscle, [experiment], free, starts=starts, max_steps=30, progress=False)


(out / f"multistart-{tag}.json").write_text(json.dumps(dict(
    best_index=result.best_index, errors=result.errors, processes=result.processes,
    results=[None if r is None else fit_fields(r) for r in result.results],
    best_model_k0=float(result.best.model.force_law.k0),
)))
print(f"worker {tag} done in {time.perf_counter() - started:.1f} s", flush=True)
