"""The CLI's persistent caches: a second run of a workflow compiles nothing new and traces nothing it traced before;
the cache can be moved and turned off."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import pamjax

SCRIPT = textwrap.dedent("""
    import json, sys
    import pamjax
    from pamjax._cli.main import main
    with pamjax.runtime.CompileStats() as stats:
        status = main(sys.argv[1:])
    print(json.dumps(dict(status=status, requests=stats.requests, hits=stats.hits, traced=stats.count["trace"],
                          compiled=stats.count["compile"])))
""")


def _config(folder):
    t = np.arange(0.0, 0.3 + 1e-9, 0.01)
    truth = pamjax.TankFromModel(5e-5)(pamjax.presets.mas10_system("pwm"))
    rec = pamjax.synthetic_recording(truth, pamjax.Constant(0.5), t, noise=dict(pressure=2e3), channels=["pressure"],
                                     y0=truth.initial_state(101325.0), seed=1)
    rec.to_csv(folder / "tank.csv")
    (folder / "fit.toml").write_text(textwrap.dedent("""
        [model]
        preset = "mas10_system"
        set = { "valve.inflate.discharge_coefficient" = 0.40 }
        [fit]
        free = ["valve.inflate.discharge_coefficient"]
        max_steps = 10
        [[experiment]]
        name = "tank"
        file = "tank.csv"
        tank_volume = 5e-5
        signal = { kind = "Constant", value = 0.5 }
        channels = ["pressure"]
        scales = { pressure = 2e3 }
        initial = { pressure = 101325.0 }
    """))
    return folder / "fit.toml"


def _run(config, out, cache, **env):
    env = dict(os.environ, PAMJAX_CACHE_DIR=str(cache), PAMJAX_CACHE_MIN_COMPILE_SECONDS="0", **env)
    proc = subprocess.run([sys.executable, "-c", SCRIPT, "fit", str(config), "--out", str(out), "--quiet",
                           "--no-plot"], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout, json.loads(proc.stdout.strip().splitlines()[-1])


def test_second_run_compiles_nothing_new(tmp_path):
    config, cache = _config(tmp_path), tmp_path / "cache"
    text, first = _run(config, tmp_path / "a", cache)
    assert first["status"] == 0 and first["requests"] > 0 and first["hits"] < first["requests"]
    assert "compiling the residuals and their Jacobian (first run; cached afterwards)" in text
    text, second = _run(config, tmp_path / "b", cache)
    assert second["status"] == 0
    # every program from the cache: its kept executables, or JAX's persistent cache; nothing compiled anew
    assert second["hits"] == second["requests"] and second["compiled"] == second["hits"], second
    assert second["traced"] == 0, second  # nothing traced again: the programs, nor the set-up's shape checks
    assert "compiling" not in text
    programs = sorted(p.name.split("-")[0] for p in (cache / "programs").iterdir())
    # the fit's programs (exported), and the experiment's output names (its set-up's shape inference, pickled)
    assert programs == ["experiment_outputs", "fit_jacobian", "fit_physical", "fit_residuals"]
    executables = sorted((cache / "executables").iterdir())  # the compiled programs, loaded without lowering
    assert [p.name.split("-")[0] for p in executables] == ["fit_jacobian", "fit_physical", "fit_residuals"]
    a = json.loads((tmp_path / "a" / "fit.json").read_text())
    b = json.loads((tmp_path / "b" / "fit.json").read_text())
    assert a["values"] == b["values"] and a["cost"] == b["cost"]  # the same fit, bitwise
    for p in executables:  # an unreadable executable: the exported program is compiled (from JAX's cache) instead
        p.write_bytes(b"not an executable")
    text, third = _run(config, tmp_path / "c", cache)
    assert third["status"] == 0 and third["hits"] == third["requests"] and "compiling" not in text
    c = json.loads((tmp_path / "c" / "fit.json").read_text())
    assert c["values"] == a["values"] and c["cost"] == a["cost"]


SIMULATE = """
[model]
preset = "mas10_system"
options = { valve = "pwm" }
[input]
signal = { kind = "Triangle", low = 0.05, high = 0.95, frequency = 1.0 }
[simulate]
t_end = 0.5
dt = 0.01
"""
SWEEP = """
kind = "steady_state"
[system]
valve = "pwm"
[sweep]
commands = { start = 0.2, stop = 0.8, num = 3 }
horizon = 0.3
window = 0.1
"""


@pytest.mark.parametrize("command, config, output", [("simulate", SIMULATE, "trajectory.csv"),
                                                     ("sweep", SWEEP, "sweep.csv")])
def test_second_simulate_or_sweep_compiles_nothing_new(tmp_path, command, config, output):
    """A `simulate` solve holds diffrax's run-time checks; traced as host callbacks they kept its program out of JAX's
    persistent cache, so every `pamjax simulate` or `pamjax demo` compiled it again (the simulate case fails on that
    code). The second run reads every program from the cache, says nothing about compiling, and writes the same
    numbers; a sweep (lanes with status codes, no callbacks) likewise."""
    (tmp_path / "run.toml").write_text(config)
    cache = tmp_path / "cache"
    env = dict(os.environ, PAMJAX_CACHE_DIR=str(cache), PAMJAX_CACHE_MIN_COMPILE_SECONDS="0")
    runs = []
    for out in ("a", "b"):
        proc = subprocess.run([sys.executable, "-c", SCRIPT, command, str(tmp_path / "run.toml"), "--out",
                               str(tmp_path / out), "--no-plot"], env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr[-2000:]
        runs.append((proc.stdout, json.loads(proc.stdout.strip().splitlines()[-1])))
    (_, first), (text, second) = runs
    assert first["status"] == 0 and first["requests"] > 0 and first["hits"] < first["requests"]
    assert second["status"] == 0
    # every program from the cache (a program JAX will not cache is compiled without asking it: counted apart)
    assert second["requests"] > 0 and second["hits"] == second["requests"] == second["compiled"], second
    assert "compiling" not in text
    assert (tmp_path / "a" / output).read_bytes() == (tmp_path / "b" / output).read_bytes()


def test_announcement_comes_with_compilation_only(monkeypatch):
    """`announce_compilation` (every command but fit): "compiling …" once JAX compiles and the work is still busy
    after `after` seconds, then the time it took; nothing for busy work that compiles nothing."""
    import io
    import time

    import jax
    import jax.numpy as jnp

    from pamjax._core import cache as _cache

    monkeypatch.setattr(_cache.announce_compilation, "_cache_is_empty", staticmethod(lambda directory: True))
    quiet = io.StringIO()
    with _cache.announce_compilation("idle", after=0.05, stream=quiet):
        time.sleep(0.4)  # busy, no JAX
    assert quiet.getvalue() == ""
    said = io.StringIO()
    with _cache.announce_compilation("work", after=0.05, stream=said):
        offset = time.time()  # a function JAX has not seen: traced and compiled here
        jax.block_until_ready(jax.jit(lambda x: jnp.sin(x) * offset + jnp.cumsum(x))(jnp.arange(5.0)))
        time.sleep(0.4)
    lines = said.getvalue().splitlines()
    assert len(lines) == 2 and lines[0].startswith("work: compiling … (") and lines[1].startswith("work: compiled in")
    # with programs in the cache and nothing compiled anew (traced, then read): no "compiling", the time it took
    monkeypatch.setattr(_cache.announce_compilation, "_cache_is_empty", staticmethod(lambda directory: False))
    served = io.StringIO()
    with _cache.announce_compilation("warm", after=0.05, stream=served) as announce:
        announce.stats.count["trace"] += 1  # as the listeners record a trace and a cache read
        announce.stats.seconds["trace"] += 0.5
        time.sleep(0.4)
    assert served.getvalue().startswith("warm: traced its programs and read them from the cache in 0.5 s")


@pytest.mark.parametrize("how", ["env", "flag"])
def test_cache_can_be_turned_off(tmp_path, how):
    # Off also where JAX_COMPILATION_CACHE_DIR turns JAX's own cache on: JAX wrote its programs there, and pamjax its
    # traced programs beside them, whatever --no-cache or PAMJAX_COMPILATION_CACHE=0 said.
    config, cache, jax_cache = _config(tmp_path), tmp_path / "cache", tmp_path / "jax-cache"
    env = {"PAMJAX_COMPILATION_CACHE": "0"} if how == "env" else {}
    extra = [] if how == "env" else ["--no-cache"]
    proc = subprocess.run([sys.executable, "-m", "pamjax", "fit", str(config), "--out", str(tmp_path / "a"),
                           "--quiet", "--no-plot", *extra],
                          env=dict(os.environ, PAMJAX_CACHE_DIR=str(cache), JAX_COMPILATION_CACHE_DIR=str(jax_cache),
                                   JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0", **env),
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    for folder in (cache, jax_cache):
        assert not folder.exists() or not any(folder.iterdir()), sorted(folder.rglob("*"))


def test_default_cache_directory_follows_the_platform_convention(monkeypatch, tmp_path):
    from pamjax._core.cache import default_cache_dir

    monkeypatch.delenv("PAMJAX_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    if sys.platform.startswith("linux"):
        assert default_cache_dir() == tmp_path / "pamjax" / "jax-compilation"
    monkeypatch.setenv("PAMJAX_CACHE_DIR", str(tmp_path / "elsewhere"))
    assert default_cache_dir() == tmp_path / "elsewhere"


def test_program_key_follows_what_is_traced_not_the_traced_values():
    """The traced-program cache's key changes with a static field, a shape or a dtype (another program), not with
    the values of the arrays the program takes as arguments, and is the same for the same (or an equal) model."""
    import dataclasses

    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from pamjax._core.cache import ProgramCache

    jax.config.update("jax_enable_x64", True)
    key = ProgramCache.key
    model = pamjax.presets.mas10_system("pwm")
    theta = jnp.zeros(3)
    reference = key("fit_residuals", (model, theta))
    assert key("fit_residuals", (model, theta)) == reference  # the same model twice
    assert key("fit_residuals", (pamjax.presets.mas10_system("pwm"), jnp.ones(3))) == reference  # equal; other θ
    moved = eqx.tree_at(lambda s: s.friction.coulomb_force, model, model.friction.coulomb_force * 2)
    assert key("fit_residuals", (moved, theta)) == reference  # a traced parameter's value is an argument
    exact = eqx.tree_at(lambda s: s.valve, model, dataclasses.replace(model.valve, mode="exact"))
    assert exact.valve.mode != model.valve.mode
    assert key("fit_residuals", (exact, theta)) != reference  # a static field: another program
    assert key("fit_residuals", (model, jnp.zeros(4))) != reference  # another shape
    assert key("fit_residuals", (model, jnp.zeros(3, jnp.float32))) != reference  # another dtype
    assert key("fit_jacobian", (model, theta)) != reference  # another function
    assert key("fit_residuals", (model, theta, 2.0)) != key("fit_residuals", (model, theta, 3.0))  # a baked constant


def test_program_key_follows_the_platform(monkeypatch):
    """A program exported on one platform (a GPU) is not the same program on another (`JAX_PLATFORMS=cpu`): the
    key names the platform and devices."""
    import jax
    import jax.numpy as jnp

    from pamjax._core import cache

    jax.config.update("jax_enable_x64", True)
    args = (pamjax.presets.mas10_system("pwm"), jnp.zeros(3))
    here = cache.ProgramCache.key("fit_residuals", args)
    monkeypatch.setitem(cache._PROGRAMS, "platform", ("cuda", "12.8", ["NVIDIA H100 80GB HBM3"], 1))
    assert cache.ProgramCache.key("fit_residuals", args) != here


def _planted(tmp_path, content):
    """A program cache whose entry for `fn` at these arguments holds `content(fn, x)` (bytes): what a run on another
    platform, an older jax or a damaged disk left there."""
    import jax
    import jax.numpy as jnp

    from pamjax._core.cache import ProgramCache

    jax.config.update("jax_enable_x64", True)

    def fn(x):
        return jnp.sin(x) * 2.0

    x = jnp.linspace(0.0, 1.0, 5)
    programs = ProgramCache(tmp_path)
    key = programs.key("planted", (x,))
    path = programs.directory / f"planted-{key}.bin"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(content(fn, x))
    return programs, fn, x, path


@pytest.mark.parametrize("entry", ["exported for cuda", "damaged"])
def test_a_foreign_or_damaged_program_entry_is_traced_anew(tmp_path, entry):
    """The regression: a fit run on a GPU, then with `JAX_PLATFORMS=cpu` on the same cache, failed with "Function
    'flat' was exported for platforms '('cuda',)' but it is used on '('cpu',)'". An entry that cannot be used here is
    traced anew and replaced; the result is the function's own."""
    import jax

    def cuda(fn, x):
        return bytes(jax.export.export(jax.jit(fn), platforms=("cuda",))(x).serialize())

    def damaged(fn, x):
        return b"\x00not a program" * 10

    programs, fn, x, path = _planted(tmp_path, cuda if entry == "exported for cuda" else damaged)
    before = path.read_bytes()
    got = programs.call("planted", fn, (x,))
    np.testing.assert_array_equal(np.asarray(got), np.asarray(fn(x)))
    assert path.read_bytes() != before  # replaced by this platform's export
    again = type(programs)(tmp_path).call("planted", fn, (x,))  # a new process reads the replaced entry
    np.testing.assert_array_equal(np.asarray(again), np.asarray(fn(x)))


def test_structural_results_are_kept_per_structure_and_errors_never(tmp_path):
    """`ProgramCache.structural` (a fit's set-up checks: the experiments' output names by shape inference): computed
    once per argument structure, read back by a new process without calling the function; another structure is
    computed anew; an error is raised as the function raised it and nothing is kept; a damaged entry is recomputed."""
    import jax
    import jax.numpy as jnp

    from pamjax._core.cache import ProgramCache

    jax.config.update("jax_enable_x64", True)
    calls = []

    def names(x):
        calls.append(x.shape)
        return sorted(jax.eval_shape(lambda y: {"a": y, "b": y[:1]}, x))

    x = jnp.zeros(3)
    assert ProgramCache(tmp_path).structural("names", names, (x,)) == ["a", "b"]
    assert ProgramCache(tmp_path).structural("names", names, (x + 1.0,)) == ["a", "b"]  # other values, same shape
    assert calls == [(3,)]  # the second "process" read it
    assert ProgramCache(tmp_path).structural("names", names, (jnp.zeros(4),)) == ["a", "b"]
    assert calls == [(3,), (4,)]  # another shape: computed

    def fails(x):
        raise ValueError("bad initial keys")

    for _ in range(2):  # raised both times: never kept
        with pytest.raises(ValueError, match="bad initial keys"):
            ProgramCache(tmp_path).structural("fails", fails, (x,))
    assert not list(tmp_path.glob("programs/fails-*"))
    for entry in tmp_path.glob("programs/names-*.pkl"):
        entry.write_bytes(b"\x00damaged")
    assert ProgramCache(tmp_path).structural("names", names, (x,)) == ["a", "b"]
    assert calls == [(3,), (4,), (3,)]


def test_preload_loads_a_kept_executable_and_nothing_else(tmp_path):
    """`ProgramCache.preload` (a second fit's programs, loaded while optimistix is imported): False and nothing
    traced where no executable is kept; after a first `call` a new cache loads it, and its `call` then gives the
    same values without tracing or compiling."""
    import jax
    import jax.numpy as jnp

    from pamjax._core.cache import ProgramCache

    jax.config.update("jax_enable_x64", True)

    def fn(x):
        return jnp.sin(x) * 2.0

    x = jnp.linspace(0.0, 1.0, 5)
    with pamjax.runtime.CompileStats() as stats:
        assert ProgramCache(tmp_path).preload("pre", (x,)) is False
    assert stats.count["trace"] == 0 and stats.count["compile"] == 0
    expected = np.asarray(ProgramCache(tmp_path).call("pre", fn, (x,)))
    fresh = ProgramCache(tmp_path)
    with pamjax.runtime.CompileStats() as stats:
        assert fresh.preload("pre", (x,)) is True
        got = np.asarray(fresh.call("pre", fn, (x,)))
    assert stats.count["trace"] == 0 and stats.count["compile"] == 0, stats.summary()
    np.testing.assert_array_equal(got, expected)


def _component_module(folder, name, scale):
    """A user's component in a file of its own: `Gain(k)(x) = scale · k · x`."""
    path = folder / f"{name}.py"
    path.write_text(textwrap.dedent(f"""
        import equinox as eqx
        import jax

        class Gain(eqx.Module):
            k: jax.Array

            def __call__(self, x):
                return {scale} * self.k * x
    """))
    return path


def _import_file(name, path):
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def test_an_edited_component_traces_anew(tmp_path, monkeypatch):
    """The regression: the program cache's key held the versions and the arguments' structure, not the code, so a
    user who edited their own component (or pamjax's physics, in the README's editable install) and ran again got
    the program traced from the code before the edit: the old model's results, silently. The key now holds the
    source files of the classes in the arguments (and pamjax's own): an edit gives another key, and the program is
    traced from the new code."""
    import jax
    import jax.numpy as jnp

    from pamjax._core import code_stamp
    from pamjax._core.cache import ProgramCache

    jax.config.update("jax_enable_x64", True)
    name = "pamjax_test_user_gain"
    monkeypatch.delitem(sys.modules, name, raising=False)
    path = _component_module(tmp_path, name, 2.0)
    gain = _import_file(name, path).Gain(jnp.asarray(3.0))
    x = jnp.linspace(0.0, 1.0, 4)
    first = np.asarray(ProgramCache(tmp_path / "cache").call("gain", lambda g, x: g(x), (gain, x)))
    np.testing.assert_allclose(first, 6.0 * np.asarray(x))

    _component_module(tmp_path, name, 5.0)  # the user edits the component; a new process runs it
    monkeypatch.setattr(code_stamp, "_STAMPS", {})
    edited = _import_file(name, path).Gain(jnp.asarray(3.0))
    again = np.asarray(ProgramCache(tmp_path / "cache").call("gain", lambda g, x: g(x), (edited, x)))
    np.testing.assert_allclose(again, 15.0 * np.asarray(x))  # the old code's program gave 6 x


def test_a_component_without_a_source_file_is_compiled_in_the_process_only(tmp_path, monkeypatch):
    """A class defined at the prompt or in a notebook (its module has no file): its code cannot be told apart from
    an edited one, so its program is never written to nor read from the disk; it runs all the same."""
    import types

    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from pamjax._core.cache import ProgramCache

    jax.config.update("jax_enable_x64", True)
    module = types.ModuleType("pamjax_test_prompt")  # no __file__, as `__main__` at the prompt

    class Gain(eqx.Module):
        k: jax.Array

        def __call__(self, x):
            return 2.0 * self.k * x

    Gain.__module__ = module.__name__
    monkeypatch.setitem(sys.modules, module.__name__, module)
    x = jnp.linspace(0.0, 1.0, 4)
    programs = ProgramCache(tmp_path)
    args = (Gain(jnp.asarray(3.0)), x)
    assert programs.key("gain", args) is None
    np.testing.assert_allclose(np.asarray(programs.call("gain", lambda g, x: g(x), args)), 6.0 * np.asarray(x))
    assert programs.structural("names", lambda g, x: ["k"], args) == ["k"]
    assert not ProgramCache(tmp_path).preload("gain", args)  # another process finds nothing
    assert not list(tmp_path.rglob("*gain*")) and not list(tmp_path.rglob("*.pkl"))


def test_enable_compilation_cache_refuses_a_non_path_and_reads_an_empty_one_as_the_default(tmp_path, monkeypatch):
    # enable_compilation_cache(123) was a raw TypeError; "" cached in the current folder while an empty
    # PAMJAX_CACHE_DIR means the default folder
    import jax

    from pamjax._core.cache import enable_compilation_cache

    with pytest.raises(pamjax.PamjaxInputError, match=r"path must be a folder \(str or os.PathLike\) or None for the "
                                                      r"default, got 123"):
        enable_compilation_cache(123)
    names = ("jax_compilation_cache_dir", "jax_persistent_cache_min_compile_time_secs",
             "jax_persistent_cache_min_entry_size_bytes")
    before = {name: getattr(jax.config, name) for name in names}
    monkeypatch.delenv("PAMJAX_COMPILATION_CACHE", raising=False)
    monkeypatch.setenv("PAMJAX_CACHE_DIR", str(tmp_path / "default"))
    monkeypatch.chdir(tmp_path)
    try:
        assert enable_compilation_cache("") == tmp_path / "default"
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "default")
    finally:
        for name, value in before.items():
            jax.config.update(name, value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["default"]


def test_an_unwritable_cache_folder_turns_the_cache_off_as_said(tmp_path, monkeypatch, capsys):
    # The CLI's cache folder unwritable: it said "compilation cache off", and a fit then told the command-line user
    # "pamjax.runtime.enable_compilation_cache() keeps it". The cache is now off as said, and the fit says so.
    import jax

    from pamjax._core.cache import cache_turned_off, enable_compilation_cache, program_cache

    names = ("jax_compilation_cache_dir", "jax_enable_compilation_cache")
    before = {name: getattr(jax.config, name) for name in names}
    monkeypatch.delenv("PAMJAX_COMPILATION_CACHE", raising=False)
    (tmp_path / "file").write_text("not a folder")
    try:
        jax.config.update("jax_compilation_cache_dir", None)
        assert enable_compilation_cache(tmp_path / "file" / "cache") is None
        assert "compilation cache off: cannot write" in capsys.readouterr().err
        assert cache_turned_off() and program_cache() is None
    finally:
        for name, value in before.items():
            jax.config.update(name, value)


def test_the_cache_minimum_must_be_a_number_of_seconds():
    from pamjax._core.env import env_seconds

    assert env_seconds("S", 0.1, {}) == 0.1 and env_seconds("S", 0.1, {"S": " 2 "}) == 2.0
    for bad in ("0.5s", "-1", "nan", "inf"):
        with pytest.raises(pamjax.PamjaxInputError, match=rf"environment variable S='{bad}': write a number of "
                                                          r"seconds >= 0"):
            env_seconds("S", 0.1, {"S": bad})


SWITCH = textwrap.dedent("""
    import pathlib, sys
    import jax, jax.numpy as jnp
    from pamjax._core.cache import disable_compilation_cache, enable_compilation_cache
    a, b = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
    files = lambda d: sum(p.is_file() for p in d.rglob("*"))
    disable_compilation_cache()
    jax.jit(lambda x: jnp.sin(x) + 1.0)(jnp.ones(3))  # compiled with the cache off: JAX decided "off" here
    print(enable_compilation_cache(a) == a, jax.config.jax_enable_compilation_cache)
    jax.jit(lambda x: jnp.cos(x) + 2.0)(jnp.ones(3))
    in_a = files(a)
    print(enable_compilation_cache(b) == b)
    jax.jit(lambda x: jnp.tan(x) + 3.0)(jnp.ones(3))
    in_b = files(b)
    disable_compilation_cache()
    jax.jit(lambda x: jnp.exp(x) + 4.0)(jnp.ones(3))
    print(in_a, files(a), in_b, files(b))
""")


def test_the_cache_turns_on_again_and_moves_after_programs_were_compiled(tmp_path):
    # JAX decides at its first compilation whether its cache is used and in which folder: enable_compilation_cache(d)
    # after disable_compilation_cache() returned d with the cache still off (no file), and a second
    # enable_compilation_cache(B) after programs went to A kept writing to A. Now each takes effect at the next
    # compilation (JAX's reset_cache), and so does a disable after programs were cached.
    a, b = tmp_path / "a", tmp_path / "b"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("JAX_COMPILATION_CACHE", "JAX_PERSISTENT_CACHE",
                                                                    "PAMJAX_COMPILATION_CACHE"))}
    proc = subprocess.run([sys.executable, "-c", SWITCH, str(a), str(b)], capture_output=True, text=True, timeout=300,
                          env=dict(env, PAMJAX_CACHE_MIN_COMPILE_SECONDS="0"))
    assert proc.returncode == 0, proc.stderr[-2000:]
    on_again, moved, counts = proc.stdout.split("\n")[:3]
    assert on_again == "True True" and moved == "True"
    in_a, a_after, in_b, b_after = map(int, counts.split())
    assert in_a == a_after == 1  # the program compiled after enable(a), and none after enable(b)
    assert in_b == b_after == 1  # the program compiled after enable(b); none after the disable


def test_compile_stats_entered_again_counts_each_program_once_and_leaves_no_listener():
    # Every `with` registered two more jax.monitoring listeners for good: the nth use of one object counted each
    # compilation n times (1, 3, 6 for one program per block), and 5,000 uses slowed every compilation down.
    import jax
    from jax._src import monitoring

    before = len(monitoring.get_event_listeners()), len(monitoring.get_event_duration_listeners())
    stats = pamjax.runtime.CompileStats()
    for k in range(1, 4):
        with stats:
            jax.jit(lambda x, k=k: x * (k + 0.25))(np.ones(3))  # one new program per block
            assert len(monitoring.get_event_listeners()) == before[0] + 1
        assert stats.count["compile"] == stats.count["trace"] == k
    with stats, stats:  # nested: the listeners stay until the outer block ends, and count once
        jax.jit(lambda x: x * 5.25)(np.ones(3))
    assert stats.count["compile"] == 4
    assert (len(monitoring.get_event_listeners()), len(monitoring.get_event_duration_listeners())) == before
