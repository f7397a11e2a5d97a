"""Two CPU processes on localhost, joined by `pamjax.runtime.initialize_distributed` (JAX's multi-process runtime, CPU
collectives over gloo), compute a sweep and a multistart fit that equal the single-process results bitwise, and
`pamjax sweep --distributed` writes what one process writes.

The processes run `tests/distributed_worker.py`, each with its own single CPU device; a third runs it alone as the
reference, at the same time, with 4 CPU devices (and two more run `pamjax sweep --distributed`). On 2 of the
reference's devices (the distributed run's mesh size) a sweep is the same program per device and gives the same
bits; with `chunk_size` given, on all 4 too; on 1, XLA compiles the sweep without its SPMD partitioner, which
changes the last bit of some results (round-off). Every process is started in its own session and killed by its
id if the test fails or runs past `TIMEOUT_S`, so a stuck collective cannot hang the suite.
"""

import json
import os
import pathlib
import re
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

import pamjax
from pamjax._core.distributed import PamjaxDistributedError

ROOT = pathlib.Path(__file__).resolve().parents[1]
WORKER = ROOT / "tests" / "distributed_worker.py"
TIMEOUT_S = 150  # the five processes together take ~25-50 s on the shared 2-core CPU


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _environment():
    """This environment for the workers: CPU only, this checkout's pamjax, and no settings of an enclosing
    distributed job (a CI runner under SLURM) or forced device count."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "OMPI_", "PMI_"))
           and k not in ("JAX_COORDINATOR_ADDRESS", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID", "JAX_NUM_CPU_DEVICES")}
    env["XLA_FLAGS"] = re.sub(r"--xla_force_host_platform_device_count=\S*", "", env.get("XLA_FLAGS", ""))
    env["JAX_PLATFORMS"] = "cpu"
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    return env


def _run_all(commands, envs):
    """Start every command, wait for all (at most TIMEOUT_S in all), kill what is left; (returncode, output)s."""
    procs = [subprocess.Popen(c, env=e, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                              start_new_session=True) for c, e in zip(commands, envs)]
    deadline = time.monotonic() + TIMEOUT_S
    outputs = []
    try:
        for proc in procs:
            try:
                out, _ = proc.communicate(timeout=max(deadline - time.monotonic(), 1))
            except subprocess.TimeoutExpired:
                out = f"(killed after {TIMEOUT_S} s)"
            outputs.append((proc.returncode, out))
    finally:
        for proc in procs:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)  # its own session: the worker and nothing else
                proc.wait()
    return outputs


CONFIG = """kind = "steady_state"
[system]
valve = "averaged"
[sweep]
commands = { start = 0.1, stop = 0.9, num = 12 }
horizon = 0.5
window = 0.1
method = "rk4"
dt = 1e-3
"""


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Five processes at once: the reference (4 CPU devices), the worker on 2 processes, and `pamjax sweep
    --distributed` on 2 processes (its settings from the JAX_* environment)."""
    out = tmp_path_factory.mktemp("distributed")
    env = _environment()
    base = [sys.executable, str(WORKER), str(out)]
    port, cli_port = str(_free_port()), str(_free_port())
    (out / "map.toml").write_text(CONFIG)
    cli = [sys.executable, "-m", "pamjax._cli.main", "sweep", str(out / "map.toml"), "--no-plot", "--out",
           str(out / "cli"), "--cpu-devices", "1", "--distributed"]
    joined = [dict(env, JAX_COORDINATOR_ADDRESS=f"127.0.0.1:{cli_port}", JAX_NUM_PROCESSES="2",
                   JAX_PROCESS_ID=str(i)) for i in (0, 1)]
    results = _run_all([base, base + ["0", "2", port], base + ["1", "2", port], cli, cli],
                       [dict(env, JAX_NUM_CPU_DEVICES=str(n)) for n in (4, 1, 1)] + joined)
    names = ["single", "process 0", "process 1", "cli process 0", "cli process 1"]
    for name, (code, text) in zip(names, results):
        assert code == 0, f"{name} failed ({code}):\n{text}"
    return out, [text for _, text in results]


def test_cli_sweep_distributed_equals_single_process(runs):
    """`pamjax sweep --distributed` on 2 processes writes, from process 0, the steady-state map of one process with
    as many devices (`pamjax.steady_state_map`, computed by the reference)."""
    out, texts = runs
    assert "joined as process 1 of 2" in texts[4] and "wrote" not in texts[4]  # process 0 writes
    written = np.load(out / "cli" / "sweep.npz")
    single = np.load(out / "steady_state-single.npz")
    np.testing.assert_array_equal(written["duty"], np.linspace(0.1, 0.9, 12))
    np.testing.assert_array_equal(written["pressure_pa_abs"], single["pressure"])
    np.testing.assert_array_equal(written["position_m"], single["position"])
    np.testing.assert_array_equal(written["status"], single["status"])


def test_cli_sweep_distributed_says_why_it_cannot_join(monkeypatch, tmp_path, capsys):
    # once a SystemExit(text): status 1 with no "pamjax sweep: error:"; now the command's one-line input error
    from pamjax._cli.main import main

    for name in ("JAX_COORDINATOR_ADDRESS", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID", "SLURM_JOB_ID",
                 "OMPI_MCA_orte_hnp_uri", "OMPI_COMM_WORLD_RANK"):
        monkeypatch.delenv(name, raising=False)
    (tmp_path / "map.toml").write_text(CONFIG)
    assert main(["sweep", str(tmp_path / "map.toml"), "--no-plot", "--out", str(tmp_path / "x"), "--distributed"]) == 2
    assert re.search(r"^pamjax sweep: error: --distributed: nothing to join: none of JAX_COORDINATOR_ADDRESS",
                     capsys.readouterr().err, re.M)


def test_processes_say_what_they_joined(runs):
    _, texts = runs
    assert "joined as process 0 of 2" in texts[1] and "joined as process 1 of 2" in texts[2]
    assert "2 in all" in texts[1]


def test_sweep_on_two_processes_equals_single_process_bitwise(runs):
    out, _ = runs
    single, p0, p1 = (np.load(out / f"sweep-{t}.npz") for t in ("single", "0", "1"))
    for key in ("status", "pressure", "position", "split_position"):
        np.testing.assert_array_equal(p0[key], single[key])  # bitwise (NaN where failed, in the same places)
        np.testing.assert_array_equal(p1[key], single[key])  # every process holds the whole result
        if key != "split_position":
            np.testing.assert_array_equal(p0[key], single[key + "4"])  # chunk_size given: 4 devices alike
    assert single["status"].tolist() == [0] * 5 + [1] + [0] * 6  # the injected failure, reported per point
    assert np.all(np.isnan(single["position"][5])) and np.all(np.isfinite(single["position"][[0, 4, 6, 11]]))
    # one device: the same results to round-off (XLA's one-device program; tolerance ~50 ulp)
    ok = single["status"] == 0
    np.testing.assert_allclose(single["position1"][ok], single["position"][ok], rtol=1e-14, atol=0)


def test_sweep_shards_are_disjoint_and_merge_to_the_whole(runs):
    out, _ = runs
    single = np.load(out / "sweep-single.npz")
    shards = [np.load(out / f"sweep-{t}.npz") for t in ("0", "1")]
    points = [s["shard_points"] for s in shards]
    assert len(points[0]) > 0 and len(points[1]) > 0, "each process computes a part"
    assert sorted(np.concatenate(points).tolist()) == list(range(12))
    for s, pts in zip(shards, points):
        np.testing.assert_array_equal(s["shard_position"], single["position"][pts])
        np.testing.assert_array_equal(s["shard_status"], single["status"][pts])


def test_multistart_on_two_processes_equals_single_process(runs):
    out, _ = runs
    single, p0, p1 = (json.loads((out / f"multistart-{t}.json").read_text()) for t in ("single", "0", "1"))
    assert single["processes"] == [0, 0, 0, 0]
    assert p0["processes"] == [0, 1, 0, 1]  # start i on process i mod 2
    for multi in (p0, p1):
        # every field but wall times: values, cost, history, standard errors (floats exact through JSON)
        assert multi["results"] == single["results"]
        assert multi["errors"] == single["errors"] and multi["best_index"] == single["best_index"]
        assert multi["best_model_k0"] == single["best_model_k0"]
    assert single["results"][2] is None and "non-finite" in single["errors"][2]  # recorded, not fatal
    finished = [r for r in single["results"] if r is not None]
    assert len(finished) == 3 and all(r["converged"] for r in finished)


def test_initialize_distributed_says_why_it_cannot_join():
    """Checked in this (already running) process: nothing to join; incomplete or bad settings are named."""
    info = pamjax.runtime.initialize_distributed(environ={})
    assert not info.distributed and "single process" in str(info) and "JAX_COORDINATOR_ADDRESS" in str(info)
    with pytest.raises(PamjaxDistributedError, match="nothing to join"):
        pamjax.runtime.initialize_distributed(required=True, environ={})
    with pytest.raises(pamjax.PamjaxInputError, match="num_processes, process_id not given"):
        pamjax.runtime.initialize_distributed(environ={"JAX_COORDINATOR_ADDRESS": "10.0.0.1:1234"})
    with pytest.raises(pamjax.PamjaxInputError, match="JAX_PROCESS_ID must be an integer"):
        pamjax.runtime.initialize_distributed(environ={"JAX_COORDINATOR_ADDRESS": "h:1", "JAX_NUM_PROCESSES": "2",
                                               "JAX_PROCESS_ID": "one"})
    with pytest.raises(pamjax.PamjaxInputError, match=r"process_id .* in \[0, 1\], got 2"):
        pamjax.runtime.initialize_distributed("h:1", 2, 2)
    with pytest.raises(pamjax.PamjaxInputError, match="PAMJAX_DISTRIBUTED_TIMEOUT must be .* > 0, got 0"):
        pamjax.runtime.initialize_distributed("h:1", 2, 1, environ={"PAMJAX_DISTRIBUTED_TIMEOUT": "0"})  # not 300 s
    for bad in (float("inf"), True):
        with pytest.raises(pamjax.PamjaxInputError, match="timeout must be"):
            pamjax.runtime.initialize_distributed("h:1", 2, 1, timeout=bad)
    with pytest.raises(PamjaxDistributedError, match="already started its backend"):
        pamjax.runtime.initialize_distributed("127.0.0.1:1", 2, 1)


def test_initialize_distributed_names_a_bad_address_and_takes_numpy_integers():
    # a port-like int as the address was a raw TypeError; np.int64(2) processes "must be an integer >= 1"
    with pytest.raises(pamjax.PamjaxInputError, match=r"coordinator_address must be a string \"host:port\" \(the "
                                                      r"address of process 0\), got 1234"):
        pamjax.runtime.initialize_distributed(1234, 2, 0)
    with pytest.raises(pamjax.PamjaxInputError, match=r"process_id .* in \[0, 1\], got 5"):
        pamjax.runtime.initialize_distributed("h:1", np.int64(2), np.int64(5))
    with pytest.raises(pamjax.PamjaxInputError, match=r"num_processes .* integer >= 1, got True"):
        pamjax.runtime.initialize_distributed("h:1", True, 0)
    np.asarray(pamjax.presets.mas10_system(valve="averaged").payload_mass)  # JAX's backend started, whatever ran
    with pytest.raises(PamjaxDistributedError, match="already started its backend"):  # taken: checks passed
        pamjax.runtime.initialize_distributed("127.0.0.1:1", np.int64(2), np.int32(1))


def test_local_shards_merge_to_the_whole_sweep():
    """In one process: `gather="local"` returns every point with its index; shards split from it (as two processes
    would hold them) merge back to the gathered result, bitwise; a missing or repeated shard is named."""
    system = pamjax.presets.mas10_system(valve="averaged")
    ts = np.linspace(0.0, 0.2, 5)
    over = {"signal.value": np.linspace(0.2, 0.8, 3)[:, None], "payload_mass": np.array([5.0, 9.6])[None, :]}
    kwargs = dict(channels=("pressure", "position"), progress=False)
    whole = pamjax.sweep(system, pamjax.Constant(0.5), ts, over, **kwargs)
    local = pamjax.sweep(system, pamjax.Constant(0.5), ts, over, gather="local", **kwargs)
    assert local.points.tolist() == list(range(6)) and local.batch_shape == (3, 2)
    assert local["position"].shape == (6, 5)

    def part(keep):
        return pamjax.SweepResult(
            over={k: v[keep] for k, v in local.over.items()}, t=local.t, channels=local.channels,
            outputs={c: v[keep] for c, v in local.outputs.items()}, status=local.status[keep], dt=local.dt,
            method=local.method, points=local.points[keep], batch_shape=local.batch_shape)

    shards = [part(np.array([1, 3, 5])), part(np.array([4, 0, 2]))]
    merged = pamjax.merge_sweep_shards(shards)
    for c in whole.channels:
        np.testing.assert_array_equal(merged[c], whole[c])
    np.testing.assert_array_equal(merged.status, whole.status)
    for k in over:
        np.testing.assert_array_equal(merged.over[k], whole.over[k])
    with pytest.raises(pamjax.PamjaxInputError, match="shards hold 3 points"):
        pamjax.merge_sweep_shards(shards[:1])
    with pytest.raises(pamjax.PamjaxInputError, match="pass every process's shard once"):
        pamjax.merge_sweep_shards([shards[0], shards[0], shards[1]])
    with pytest.raises(pamjax.PamjaxInputError, match="from sweep"):
        pamjax.merge_sweep_shards([whole])


def test_a_coordinator_that_never_comes_up_is_named_not_an_abort(tmp_path):
    # process 1 joining a coordinator nobody started was aborted by XLA at the timeout (SIGABRT, a C++ fatal log)
    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    code = (f"import pamjax\ntry:\n    pamjax.runtime.initialize_distributed('127.0.0.1:{port}', 2, 1, timeout=1)\n"
            "except pamjax.runtime.PamjaxDistributedError as e:\n    print('NAMED', e)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and "NAMED could not join process 1 of 2" in run.stdout, (run.returncode, run.stderr)
    assert "nothing listens there" in run.stdout
