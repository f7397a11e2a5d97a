"""pamjax's XLA CPU loop setting (`pamjax/_core/xla_cpu.py`): how it merges into XLA_FLAGS, when it stands back, and
that it reaches XLA (a single-trajectory solve compiles to one function on CPU)."""

import functools
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax
from pamjax import presets
from pamjax._core import xla_cpu as _xla_cpu
from pamjax._solve.simulate import solve

ENTRY = f"{_xla_cpu.KEY}={_xla_cpu.THRESHOLD_BYTES}"


@pytest.fixture
def keep_status():
    saved = dict(_xla_cpu._status)
    yield
    _xla_cpu._status.clear()
    _xla_cpu._status.update(saved)


def test_merged_flags_adds_or_extends_the_extra_options():
    assert _xla_cpu.merged_flags("") == f"--xla_backend_extra_options={ENTRY}"
    assert _xla_cpu.merged_flags("--xla_force_host_platform_device_count=2") == (
        f"--xla_force_host_platform_device_count=2 --xla_backend_extra_options={ENTRY}")
    got = _xla_cpu.merged_flags("--a=1 --xla_backend_extra_options=xla_cpu_disable_loop_unrolling --b=2")
    assert got == f"--a=1 --xla_backend_extra_options=xla_cpu_disable_loop_unrolling,{ENTRY} --b=2"
    assert _xla_cpu.merged_flags("--xla_backend_extra_options=") == f"--xla_backend_extra_options={ENTRY}"


def test_apply_respects_the_user(keep_status, monkeypatch):
    env = {"XLA_FLAGS": f"--xla_backend_extra_options={_xla_cpu.KEY}=5"}
    status = _xla_cpu.apply(env)
    assert not status["active"] and "user" in status["reason"] and "=5" in status["reason"]  # below pamjax's value
    assert env["XLA_FLAGS"] == f"--xla_backend_extra_options={_xla_cpu.KEY}=5"  # untouched
    env = {"XLA_FLAGS": f"--xla_backend_extra_options=a,{_xla_cpu.KEY}=500000", _xla_cpu.OPT_OUT: "0"}
    status = _xla_cpu.apply(env)
    assert status["active"] and "user" in status["reason"]  # the user's flag is in effect, opt-out or not
    assert env["XLA_FLAGS"] == f"--xla_backend_extra_options=a,{_xla_cpu.KEY}=500000"
    env = {"XLA_FLAGS": "--foo", _xla_cpu.OPT_OUT: "0"}
    status = _xla_cpu.apply(env)
    assert not status["active"] and _xla_cpu.OPT_OUT in status["reason"]
    assert env["XLA_FLAGS"] == "--foo"


def test_apply_sets_the_flag_before_jax_starts(keep_status, monkeypatch):
    monkeypatch.setattr(_xla_cpu, "_backends_initialised", lambda: False)
    env = {}
    status = _xla_cpu.apply(env)
    assert status["active"] and env["XLA_FLAGS"] == f"--xla_backend_extra_options={ENTRY}"
    assert pamjax.runtime.xla_cpu_status() == status


def test_apply_after_jax_started_says_so(keep_status):
    jnp.zeros(1).block_until_ready()  # the backend is up in this process
    env = {}
    if jax.default_backend() == "cpu":
        with pytest.warns(UserWarning, match="4x slower"):
            status = _xla_cpu.apply(env)
    else:
        status = _xla_cpu.apply(env)
    assert not status["active"] and "import pamjax first" in status["reason"]
    assert "XLA_FLAGS" not in env  # too late to matter: not written


def test_fast_compilation_is_set_only_where_xla_knows_the_flag(keep_status, monkeypatch):
    # XLA aborts the process on a flag it does not know, so the classic emitters are asked for only on a jaxlib known
    # to have the flag, before JAX starts, and never against the user's own choice or opt-out.
    flag = f"--{_xla_cpu.EMITTER_FLAG}=false"
    monkeypatch.setattr(_xla_cpu, "_backends_initialised", lambda: False)
    monkeypatch.setattr(_xla_cpu, "_jaxlib_version", lambda: _xla_cpu.FAST_COMPILE_JAXLIB[0])
    env = {"XLA_FLAGS": "--a=1"}
    status = _xla_cpu.prefer_fast_compilation(env)
    assert status["fast_compile"] and "set by pamjax" in status["fast_compile_reason"]
    assert env["XLA_FLAGS"] == f"--a=1 {flag}"
    assert pamjax.runtime.xla_cpu_status() == status
    assert _xla_cpu.prefer_fast_compilation(env) == status and env["XLA_FLAGS"] == f"--a=1 {flag}"  # asked twice
    for users in ("true", "false"):  # the user's value stands, whichever it is
        env = {"XLA_FLAGS": f"--{_xla_cpu.EMITTER_FLAG}={users}"}
        status = _xla_cpu.prefer_fast_compilation(env)
        assert status["fast_compile"] == (users == "false") and "user" in status["fast_compile_reason"]
        assert env["XLA_FLAGS"] == f"--{_xla_cpu.EMITTER_FLAG}={users}"
    for name in (_xla_cpu.FAST_COMPILE, _xla_cpu.OPT_OUT):
        env = {name: "0"}
        status = _xla_cpu.prefer_fast_compilation(env)
        assert not status["fast_compile"] and f"{name}=0" in status["fast_compile_reason"] and "XLA_FLAGS" not in env
    newer = (_xla_cpu.FAST_COMPILE_JAXLIB[1][0], _xla_cpu.FAST_COMPILE_JAXLIB[1][1] + 1)
    for version in (newer, (0, 4), None):
        monkeypatch.setattr(_xla_cpu, "_jaxlib_version", lambda v=version: v)
        env = {}
        status = _xla_cpu.prefer_fast_compilation(env)
        assert not status["fast_compile"] and "not one known" in status["fast_compile_reason"] and not env
    monkeypatch.setattr(_xla_cpu, "_jaxlib_version", lambda: _xla_cpu.FAST_COMPILE_JAXLIB[1])
    monkeypatch.setattr(_xla_cpu, "_backends_initialised", lambda: True)
    env = {}
    status = _xla_cpu.prefer_fast_compilation(env)
    assert not status["fast_compile"] and "already running" in status["fast_compile_reason"] and not env


def test_import_asks_for_fast_compilation_when_the_environment_does(keep_status, monkeypatch):
    monkeypatch.setattr(_xla_cpu, "_backends_initialised", lambda: False)
    monkeypatch.setattr(_xla_cpu, "_jaxlib_version", lambda: _xla_cpu.FAST_COMPILE_JAXLIB[0])
    for value, wanted in (("1", True), ("0", False), ("", False)):
        env = {_xla_cpu.FAST_COMPILE: value}
        status = _xla_cpu.apply(env)
        assert status["active"] and status["fast_compile"] is wanted
        assert (f"--{_xla_cpu.EMITTER_FLAG}=false" in env["XLA_FLAGS"]) is wanted


def test_an_on_off_variable_set_to_another_word_is_warned_about_and_left_at_its_default(keep_status, monkeypatch):
    # PAMJAX_FAST_COMPILE=disabled turned fast compilation ON (anything but 0/off did), silently
    monkeypatch.setattr(_xla_cpu, "_backends_initialised", lambda: False)
    monkeypatch.setattr(_xla_cpu, "_jaxlib_version", lambda: _xla_cpu.FAST_COMPILE_JAXLIB[0])
    env = {_xla_cpu.FAST_COMPILE: "disabled"}
    with pytest.warns(UserWarning, match=r"PAMJAX_FAST_COMPILE='disabled' is neither on .* nor off"):
        status = _xla_cpu.apply(env)
    assert status["active"] and not status["fast_compile"]
    assert f"--{_xla_cpu.EMITTER_FLAG}=false" not in env["XLA_FLAGS"]


def test_this_jaxlib_knows_the_flag_when_the_suite_asks_for_it():
    # The suite asks for fast compilation (tests/conftest.py): on a jaxlib of the checked range it is in effect here,
    # which also shows that XLA accepted the flag (it would have aborted the process otherwise).
    status = pamjax.runtime.xla_cpu_status()
    version = _xla_cpu._jaxlib_version()
    known = version is not None and _xla_cpu.FAST_COMPILE_JAXLIB[0] <= version <= _xla_cpu.FAST_COMPILE_JAXLIB[1]
    if os.environ.get(_xla_cpu.FAST_COMPILE) != "1" or not known or "user" in status["fast_compile_reason"]:
        pytest.skip(f"not asked for, or not this jaxlib: {status['fast_compile_reason']}")
    assert status["fast_compile"], status
    assert f"--{_xla_cpu.EMITTER_FLAG}=false" in os.environ["XLA_FLAGS"]
    assert float(jnp.tanh(jnp.asarray(0.5))) == pytest.approx(np.tanh(0.5), rel=1e-15)  # XLA runs with it


_USER_CHOICE = os.environ.get(_xla_cpu.OPT_OUT, "1") == "0" or "by the user" in _xla_cpu.xla_cpu_status()["reason"]


@pytest.mark.skipif(_USER_CHOICE, reason="the user opted out or chose their own threshold")
@pytest.mark.skipif(jax.default_backend() != "cpu", reason="a CPU-runtime setting")
def test_single_trajectory_solve_compiles_to_one_function():
    """The setting reached XLA: simulate's solve loop is hoisted into a single compiled call (XLA marks it
    `xla_cpu_small_call`). Without the setting it runs as ~150 thunks per step, ~4x slower."""
    assert pamjax.runtime.xla_cpu_status()["active"], pamjax.runtime.xla_cpu_status()["reason"]
    system = presets.mas10_system("averaged")
    ts = jnp.linspace(0.0, 1.0, 101)
    text = jax.jit(lambda s: solve(s, pamjax.Constant(0.5), ts, None, 0.0, solver=pamjax.Rodas5()).position
                   ).lower(system).compile().as_text()
    loops, hoisted = text.count(" while("), text.count("xla_cpu_small_call")
    assert loops >= 1 and hoisted == loops, (loops, hoisted)  # every loop, the solver's included


def test_late_import_warns_in_a_fresh_process():
    code = "import jax, jax.numpy as jnp; jnp.zeros(1).block_until_ready(); import pamjax; " \
           "print(pamjax.runtime.xla_cpu_status()['active'])"
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", _xla_cpu.OPT_OUT)}
    env["JAX_PLATFORMS"] = "cpu"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
    assert "import pamjax first" in out.stderr


def test_importing_pamjax_does_not_start_jax():
    """The setting (and JAX's device options, e.g. `pamjax sweep --cpu-devices`) can only apply if importing pamjax
    leaves JAX's backend unstarted: no arrays, no computations at import."""
    code = ("import pamjax, pamjax.presets; from jax._src import xla_bridge; "
            "print(xla_bridge.backends_are_initialized(), pamjax.runtime.xla_cpu_status()['active'])")
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", _xla_cpu.OPT_OUT)}
    env["JAX_PLATFORMS"] = "cpu"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "True"]


def test_single_trajectory_options_stand_back_where_the_process_setting_does(keep_status, monkeypatch):
    # The per-program classic emitters (`pamjax.simulate` called outside any transformation) follow the same rules as
    # the process-wide flag: not against the user's own choice or opt-out, not on an unchecked jaxlib, CPU only, and
    # not at all when the whole process already compiles that way.
    wanted = {_xla_cpu.EMITTER_FLAG: False}
    monkeypatch.setattr(_xla_cpu, "_jaxlib_version", lambda: _xla_cpu.FAST_COMPILE_JAXLIB[0])
    monkeypatch.setattr(_xla_cpu, "_on_cpu", lambda: True)
    _xla_cpu._status["fast_compile"] = False
    assert _xla_cpu.single_trajectory_options({}) == wanted
    assert _xla_cpu.single_trajectory_options({_xla_cpu.FAST_COMPILE: "1", "XLA_FLAGS": "--a=1"}) == wanted
    for env in ({_xla_cpu.FAST_COMPILE: "0"}, {_xla_cpu.OPT_OUT: "0"},
                {"XLA_FLAGS": f"--{_xla_cpu.EMITTER_FLAG}=true"}, {"XLA_FLAGS": f"--{_xla_cpu.EMITTER_FLAG}=false"}):
        assert _xla_cpu.single_trajectory_options(env) is None, env
    newer = (_xla_cpu.FAST_COMPILE_JAXLIB[1][0], _xla_cpu.FAST_COMPILE_JAXLIB[1][1] + 1)
    for version in (newer, (0, 4), None):
        monkeypatch.setattr(_xla_cpu, "_jaxlib_version", lambda v=version: v)
        assert _xla_cpu.single_trajectory_options({}) is None, version
    monkeypatch.setattr(_xla_cpu, "_jaxlib_version", lambda: _xla_cpu.FAST_COMPILE_JAXLIB[1])
    monkeypatch.setattr(_xla_cpu, "_on_cpu", lambda: False)
    assert _xla_cpu.single_trajectory_options({}) is None
    monkeypatch.setattr(_xla_cpu, "_on_cpu", lambda: True)
    _xla_cpu._status["fast_compile"] = True
    assert _xla_cpu.single_trajectory_options({}) is None


def test_top_level_simulate_compiles_with_the_options_and_transformed_simulate_without(keep_status, monkeypatch):
    from pamjax._solve import simulate as simulate_module

    system = presets.mas10_system("averaged")
    signal = pamjax.Triangle(0.05, 0.95, 0.25)
    ts = jnp.linspace(0.0, 2.0, 101)
    monkeypatch.setenv(_xla_cpu.FAST_COMPILE, "0")
    plain = pamjax.simulate(system, signal, ts)
    # As in a process without the process-wide flag (`import pamjax` alone): XLA_FLAGS is read once, at JAX's start,
    # so changing it now only changes what single_trajectory_options sees.
    monkeypatch.delenv(_xla_cpu.FAST_COMPILE)
    flags = os.environ.get("XLA_FLAGS", "").replace(f"--{_xla_cpu.EMITTER_FLAG}=false", "")
    monkeypatch.setenv("XLA_FLAGS", flags)
    _xla_cpu._status["fast_compile"] = False
    options = _xla_cpu.single_trajectory_options()
    if options is None:
        pytest.skip("not a CPU backend, or not a jaxlib known to have the option")
    key = tuple(sorted(options.items()))
    simulate_module._SOLVE_TOP.pop(key, None)
    fast = pamjax.simulate(system, signal, ts)
    assert key in simulate_module._SOLVE_TOP  # compiled by the program with the options
    np.testing.assert_allclose(np.asarray(fast.position), np.asarray(plain.position), rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(np.asarray(fast.pressure), np.asarray(plain.pressure), rtol=1e-9)
    # Inside jit, vmap or grad (JAX refuses compiler options on a nested jit), even with every argument concrete:
    # the plain program, the same numbers.
    end = float(plain.position[-1])
    inside_jit = jax.jit(lambda y: pamjax.simulate(system, signal, ts).position[-1] + y)(0.0)
    inside_vmap = jax.vmap(lambda y: pamjax.simulate(system, signal, ts).position[-1] + y)(jnp.zeros(2))
    assert float(inside_jit) == pytest.approx(end, rel=1e-9)
    np.testing.assert_allclose(np.asarray(inside_vmap), end, rtol=1e-9)


def test_batched_options_ask_for_wide_vectors_only_on_an_avx512_cpu_unless_the_user_decides(monkeypatch):
    monkeypatch.setattr(_xla_cpu, "_has_avx512", lambda: True)
    monkeypatch.setattr(_xla_cpu, "_jaxlib_version", lambda: _xla_cpu.FAST_COMPILE_JAXLIB[1])
    env = {"XLA_FLAGS": ""}
    assert _xla_cpu.batched_options("cpu", env) == {_xla_cpu.VECTOR_FLAG: 512}
    assert _xla_cpu.batched_options("gpu", env) is None and _xla_cpu.batched_options("tpu", env) is None
    assert _xla_cpu.batched_options("cpu", {"XLA_FLAGS": f"--{_xla_cpu.VECTOR_FLAG}=256"}) is None  # the user's
    assert _xla_cpu.batched_options("cpu", {_xla_cpu.OPT_OUT: "0"}) is None
    monkeypatch.setattr(_xla_cpu, "_jaxlib_version", lambda: (99, 0))
    assert _xla_cpu.batched_options("cpu", env) is None  # an unchecked jaxlib
    monkeypatch.setattr(_xla_cpu, "_jaxlib_version", lambda: _xla_cpu.FAST_COMPILE_JAXLIB[1])
    monkeypatch.setattr(_xla_cpu, "_has_avx512", lambda: False)
    assert _xla_cpu.batched_options("cpu", env) is None


def test_the_avx512_check_reads_this_cpu():
    flags = ""
    if os.path.exists("/proc/cpuinfo"):
        with open("/proc/cpuinfo") as f:
            flags = next((line for line in f if line.startswith("flags")), "")
    assert _xla_cpu._has_avx512() == (" avx512f" in flags)


def test_a_sweep_with_the_batched_options_equals_one_without(monkeypatch):
    from pamjax._sweep import lanes

    system = presets.mas10_system("averaged")
    ts = np.linspace(0.0, 1.0, 11)
    duties = np.linspace(0.05, 0.95, 24)

    def run():
        return pamjax.sweep(system, pamjax.Constant(0.5), ts, {"signal.value": duties},
                            channels=("pressure", "position"), progress=False)

    monkeypatch.setattr(lanes, "batched_options", lambda platform: {_xla_cpu.VECTOR_FLAG: 512})
    wide = run()
    assert lanes._CHUNK_PROGRAMS  # compiled with the option
    monkeypatch.setattr(lanes, "batched_options", lambda platform: None)
    plain = run()
    assert np.all(wide.status == 0) and np.all(plain.status == 0)
    for channel in ("pressure", "position"):
        np.testing.assert_allclose(wide[channel], plain[channel], rtol=1e-10, atol=1e-15)


def test_a_sweep_on_the_cpu_takes_the_vectorised_softplus_log_and_agrees_with_xla_s(monkeypatch):
    # On a CPU the fixed-scheme lanes trace the softplus with `smooth.log1p_exp` (XLA's float64 log is not vectorised
    # there); elsewhere with jnp.logaddexp. Both programs give the same map to round-off.
    from pamjax._physics import smooth
    from pamjax._sweep import lanes, sweep as sweep_module

    assert lanes.chunk_program("cpu").keywords["vector_log"] is True
    assert lanes.chunk_program("gpu").keywords["vector_log"] is False
    system = presets.mas10_system("averaged")
    ts = np.linspace(0.0, 1.0, 9)  # shapes of its own, so both programs are traced here (no other test's reused)
    duties = np.linspace(0.05, 0.95, 19)
    used = []
    series = smooth.log1p_exp
    monkeypatch.setattr(smooth, "log1p_exp", lambda a: used.append(1) or series(a))

    def run(platform):  # `sweep` calls `chunk_program(platform)` (the platform where the lanes are)
        monkeypatch.setattr(sweep_module, "chunk_program", lambda _: functools.partial(
            lanes.run_chunk, vector_log=lanes.chunk_program(platform).keywords["vector_log"]))
        return pamjax.sweep(system, pamjax.Constant(0.5), ts, {"signal.value": duties},
                            channels=("pressure", "position"), progress=False)

    vector = run("cpu")
    assert used  # traced with the series
    used.clear()
    xla = run("gpu")
    assert not used
    assert np.all(vector.status == 0) and np.all(xla.status == 0)
    for channel in ("pressure", "position"):
        np.testing.assert_allclose(vector[channel], xla[channel], rtol=1e-10, atol=1e-15)


def test_a_fit_whose_jacobian_has_the_batched_options_equals_one_without(monkeypatch):
    from pamjax._fit import problem

    muscle = presets.mas10_muscle()
    x, p = np.meshgrid(np.linspace(-0.01, 0.07, 5), 101325.0 + np.linspace(0.5e5, 6e5, 4), indexing="ij")
    force = np.asarray(muscle.static_force(jnp.asarray(x.ravel()), jnp.asarray(p.ravel()), pamjax.Air()))
    exp = pamjax.bench.ForceMapExperiment(x.ravel(), p.ravel(), np.maximum(force * 1.03, 0.0), scale=2.0)
    free = ["force_law.k0", "force_law.k1"]
    results, asked = {}, []

    def options_of(options):
        def ask():
            asked.append(options)
            return options

        return ask

    for label, options in (("wide", {_xla_cpu.VECTOR_FLAG: 512}), ("plain", None)):
        monkeypatch.setattr(problem, "_jacobian_options", options_of(options))
        results[label] = pamjax.fit(muscle, [exp], free, progress=False)
    assert {_xla_cpu.VECTOR_FLAG: 512} in asked and None in asked  # each fit's Jacobian compiled as asked
    assert results["wide"].converged and results["plain"].converged
    np.testing.assert_allclose(results["wide"].values, results["plain"].values, rtol=1e-9)
    assert results["wide"].cost == pytest.approx(results["plain"].cost, rel=1e-10)
