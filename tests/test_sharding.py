"""`sweep` sharded over devices (Mesh + NamedSharding over the batch axis) equals the single-device sweep.

Runs in a subprocess: the fake CPU devices (`XLA_FLAGS=--xla_force_host_platform_device_count=2`) must be set
before JAX starts, and this test session's JAX has already started.
"""

import os
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent(
    """
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import jax.numpy as jnp
    import pamjax
    from pamjax import presets
    from pamjax._sweep import sharding

    assert len(jax.devices()) == 2, jax.devices()
    system = presets.mas10_system(valve="averaged")
    ts = np.linspace(0.0, 0.5, 11)
    over = {"signal.value": np.array([0.2, 0.4, 0.6, 0.8, 0.9]), "payload_mass": np.array([5.0, 7.0, 9.6, 11.0, 13.0])}
    sharded = pamjax.sweep(system, pamjax.Constant(0.5), ts, over, channels=("pressure", "position"))
    single = pamjax.sweep(system, pamjax.Constant(0.5), ts, over, channels=("pressure", "position"),
                          devices=[jax.devices()[0]])
    for c in ("pressure", "position"):
        np.testing.assert_allclose(sharded[c], single[c], rtol=1e-12, atol=0)
    assert np.all(sharded.succeeded)

    # the compiled call really runs on both devices: its inputs and outputs are split over the batch axis
    mesh = sharding.mesh_of(None)
    values = sharding.put(np.array([0.2, 0.4, 0.6, 0.8]), mesh)
    assert len(values.sharding.device_set) == 2
    assert [s.data.shape for s in values.addressable_shards] == [(2,), (2,)]

    # devices=[one device] runs there (it ran on the default device before): its inputs and outputs are put there
    import pamjax._sweep.sweep as sweep_module
    seen, program = [], sweep_module.chunk_program

    def spied(platform):
        def call(system, signal, y0, vals, *args, **kwargs):
            out = program(platform)(system, signal, y0, vals, *args, **kwargs)
            seen.append({d for v in (*vals.values(), out[0]) for d in v.devices()})
            return out
        return call

    sweep_module.chunk_program = spied
    second = jax.devices()[1]
    there = pamjax.sweep(system, pamjax.Constant(0.5), ts, over, channels=("pressure", "position"), devices=[second])
    sweep_module.chunk_program = program
    assert seen == [{second}], seen
    for c in ("pressure", "position"):
        np.testing.assert_allclose(there[c], single[c], rtol=1e-12, atol=0)
    print("SHARDING OK")
    """
)


def test_sweep_sharded_over_two_cpu_devices_equals_single_device_and_one_device_given_runs_there():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "SHARDING OK" in proc.stdout
