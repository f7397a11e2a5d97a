"""Awkward inputs and faults of the file and command-line workflow (issue 15), each run as a user would meet it and
judged by what the user gets: a correct result, or one clear named error before any work — never a silent wrong
result, never lost finished work, never a traceback.

Classes: configs (values matched by name and shape), CSV files, units, output paths, concurrency, interrupts, resume
mismatches, solves that used to fail with a misleading hint, and the fitted model carried onward. Each case is
`name → (class, expect, run)`:

- `expect = "error"`: `run(folder)` returns `(exit status, printed text)` of the command (or of a Python call, as
  status 2 with the message); the verdict is "ok" when the status is non-zero, the text names `name_in_message` and
  holds no traceback; "silent_wrong" when it succeeded; "traceback" when a traceback (or a raw, unnamed exception)
  reached the user; "unnamed" when the message does not name the problem.
- `expect = "result"`: `run(folder)` returns True when the result is correct ("silent_wrong" otherwise).
- `expect = "kept"`: `run(folder)` returns True when the finished work or the user's files survived ("lost_work"
  otherwise).

Shared by `test_bad_input_cli.py` (every case not marked slow) and `benchmarks/reliability.py` (all of them), which
ends with `silent_wrong=0 lost_work=0 tracebacks=0`.
"""

import contextlib
import errno
import io
import json
import os
import pathlib
import signal
import subprocess
import sys
import tempfile
import textwrap

import jax.numpy as jnp
import numpy as np

import pamjax
from pamjax import presets

ROOT = pathlib.Path(__file__).resolve().parents[2]
T = np.round(np.arange(51) * 0.01, 10)  # s: 0.5 s at 100 Hz


# ---------------------------------------------------------------------------------------------------------------
# helpers


def cli(*argv):
    """Run `pamjax argv` in this process: (exit status, stdout + stderr). An exception escaping `main` is what a
    user sees as a traceback: status None."""
    from pamjax._cli.main import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = main([str(a) for a in argv])
        except BaseException as exc:  # noqa: BLE001 - the verdict needs every escape
            return None, out.getvalue() + err.getvalue() + f"\nTraceback: {type(exc).__name__}: {exc}"
    return status, out.getvalue() + err.getvalue()


def call(function, *args, **kwargs):
    """A Python call judged like a command: a pamjax error is a named refusal (status 2), anything else escaping is a
    raw exception (status None), success is status 0."""
    try:
        function(*args, **kwargs)
    except (pamjax.PamjaxInputError, pamjax.PamjaxSolveError, FileExistsError) as err:
        return 2, str(err)
    except Exception as err:  # noqa: BLE001
        return None, f"Traceback: {type(err).__name__}: {err}"
    return 0, ""


@contextlib.contextmanager
def patched(obj, name, value):
    old = getattr(obj, name)
    setattr(obj, name, value)
    try:
        yield
    finally:
        setattr(obj, name, old)


def recording(folder, name="tank.csv"):
    """A noisy 0.5 s tank charge at duty 0.5 (averaged valve) as CSV: `t [s], pressure [Pa abs], command [1]`."""
    path = pathlib.Path(folder) / name
    if not path.exists():
        rec = pamjax.synthetic_recording(presets.mas10_tank_system("averaged"), pamjax.Constant(0.5), T,
                                         noise=dict(pressure=2e3), seed=0, name="tank")
        rec.to_csv(path)
    return path


FIT = """
[model]
preset = "mas10_tank_system"
options = {{ valve = "averaged" }}
set = {{ {set} }}
[fit]
free = ["valve.coefficients[1,0]"]
max_steps = 20
[[experiment]]
name = "tank"
file = "{file}"
signal = {{ kind = "Constant", value = 0.5 }}
channels = {channels}
scales = {{ pressure = 2e3 }}
{extra}
"""


def fit_config(folder, set='"valve.coefficients[1,0]" = 1.5e-3', file="tank.csv", channels='["pressure"]', extra="",
               name="fit.toml"):
    recording(folder)
    path = pathlib.Path(folder) / name
    path.write_text(FIT.format(set=set, file=file, channels=channels, extra=extra))
    return path


def fit_run(folder, *flags, config=None):
    config = config or fit_config(folder)
    return cli("fit", config, "--out", pathlib.Path(folder) / "out", "--quiet", "--no-plot", *flags)


def _table(folder, text, name="r.csv", encoding="utf-8"):
    path = pathlib.Path(folder) / name
    path.write_bytes(text.encode(encoding))
    return path


def _csv(delimiter=",", header=("t [s]", "pressure [Pa]", "position [m]"), t=T, p=None, x=None, fmt=repr):
    p = 101325.0 + 1e3 * np.arange(T.size) if p is None else p
    x = 1e-4 * np.arange(T.size) if x is None else x
    rows = [delimiter.join(header)] + [delimiter.join(fmt(float(v)) for v in row) for row in zip(t, p, x)]
    return "\n".join(rows) + "\n"


def _same_recording(path):
    rec = pamjax.Recording.load(path)
    p = 101325.0 + 1e3 * np.arange(T.size)
    return (np.allclose(rec.t, T, rtol=0, atol=1e-12) and np.allclose(rec["pressure"], p, rtol=1e-12)
            and np.allclose(rec["position"], 1e-4 * np.arange(T.size), rtol=1e-12, atol=1e-15))


def _error_in(path):
    """A Python call on a recording file, judged as a command."""
    return call(pamjax.Recording.load, path)


def _fingerprint_refusal(folder, change):
    """Checkpoint a fit, change the problem (`change(folder)` → config path) and --resume: must be refused."""
    status, text = fit_run(folder)
    if status != 0:
        return status, "the reference fit failed: " + text
    return fit_run(folder, "--resume", config=change(folder))


def _interrupted_then_resumed(folder):
    """Ctrl-C as the last iteration reports (in this process); the checkpoint is kept and --resume ends where an
    uninterrupted fit ends."""
    folder = pathlib.Path(folder)
    config = fit_config(folder)
    status, _ = cli("fit", config, "--out", folder / "reference", "--quiet", "--no-plot")
    reference = json.loads((folder / "reference" / "fit.json").read_text())
    real = pamjax.fit

    def interrupted(*args, progress=True, **kwargs):
        def report(step, *rest):
            if step == reference["iterations"]:
                raise KeyboardInterrupt

        return real(*args, progress=report, **kwargs)

    with patched(pamjax, "fit", interrupted):
        status, text = fit_run(folder)
    if status != 130 or "Resume with:" not in text or not (folder / "out" / "checkpoint.npz").exists():
        return False
    status, _ = fit_run(folder, "--resume")
    resumed = json.loads((folder / "out" / "fit.json").read_text())
    return status == 0 and all(resumed[k] == reference[k] for k in ("values", "cost", "iterations", "history"))


def _signal(folder, signum, code):
    """A real SIGINT/SIGTERM from outside while `pamjax fit` compiles: exit `code`, no traceback, unlocked."""
    folder = pathlib.Path(folder)
    config = fit_config(folder)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "JAX_PLATFORMS": "cpu"}
    proc = subprocess.Popen([sys.executable, "-m", "pamjax", "fit", str(config), "--out", str(folder / "out")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    proc.stdout.readline()
    proc.send_signal(signum)
    out, err = proc.communicate(timeout=600)
    ok = proc.returncode == code and "Traceback" not in out + err and not (folder / "out" / ".pamjax.lock").exists()
    return (code if ok else (proc.returncode or 0)), out + err


def _fallback(folder):
    """Writing fit.json fails at the end (disk full): the result goes to a named fallback file."""
    from pamjax._cli import out as _cli_out

    folder = pathlib.Path(folder)
    real = _cli_out.os.replace

    def failing(src, dst):
        if pathlib.Path(dst).name == "fit.json":
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(src, dst)

    cwd = os.getcwd()
    os.chdir(folder)
    try:
        with patched(_cli_out.os, "replace", failing):
            status, text = fit_run(folder)
    finally:
        os.chdir(cwd)
    rescued = list(folder.glob("pamjax-rescued-fit-*-fit.json"))
    return status == 1 and len(rescued) == 1 and "values" in json.loads(rescued[0].read_text()) and str(
        rescued[0].name) in text


def _locked(folder):
    from pamjax._cli.out import OutputFolder

    with OutputFolder(pathlib.Path(folder) / "out", "pamjax fit", ["fit.json"]):
        return fit_run(folder)


def _model_travels(folder):
    """fit → model.json → load_model equal to the fitted values → simulate from it → trajectory CSV with units."""
    folder = pathlib.Path(folder)
    status, _ = fit_run(folder)
    result = json.loads((folder / "out" / "fit.json").read_text())
    model = pamjax.load_model(folder / "out" / "model.json")
    if status != 0 or float(model.valve.coefficients[1, 0]) != result["values"][0]:
        return False
    (folder / "sim.toml").write_text('[model]\nfile = "out/model.json"\n[input]\nfile = "tank.csv"\n')
    status, _ = cli("simulate", folder / "sim.toml", "--out", folder / "sim", "--no-plot")
    rec = pamjax.Recording.load(folder / "sim" / "trajectory.csv")
    expected = pamjax.simulate(model, pamjax.Sampled(rec.t, rec["command"]), rec.t)
    return status == 0 and rec.units["pressure"] == "Pa" and np.array_equal(rec["pressure"], expected.pressure)


def _sweep_any_path(folder):
    folder = pathlib.Path(folder)
    (folder / "s.toml").write_text(textwrap.dedent("""
        kind = "steady_state"
        [model]
        preset = "mas10_system"
        options = { valve = "averaged" }
        [sweep]
        commands = [0.5]
        horizon = 0.5
        window = 0.1
        over = { "friction.coulomb_force" = [10.0, 20.0] }
    """))
    status, _ = cli("sweep", folder / "s.toml", "--out", folder / "sw", "--no-plot", "--cpu-devices", "1")
    data = np.load(folder / "sw" / "sweep.npz")
    return status == 0 and list(data["friction.coulomb_force [N]"]) == [10.0, 20.0] and np.all(data["status"] == 0)


def _sweep(folder, text):
    path = pathlib.Path(folder) / "s.toml"
    path.write_text(textwrap.dedent(text))
    return cli("sweep", path, "--out", pathlib.Path(folder) / "sw", "--cpu-devices", "1")


def _simulate(folder, text):
    path = pathlib.Path(folder) / "sim.toml"
    path.write_text(textwrap.dedent(text))
    return cli("simulate", path, "--out", pathlib.Path(folder) / "sim", "--no-plot")


def _solves(system, signal, horizon, **kwargs):
    traj = pamjax.simulate(system, signal, jnp.linspace(0.0, horizon, 11), **kwargs)
    return bool(traj.succeeded) and bool(np.all(np.isfinite(np.asarray(traj.pressure))))


def _existing_kept(folder):
    folder = pathlib.Path(folder)
    (folder / "out").mkdir(parents=True, exist_ok=True)
    (folder / "out" / "fit.json").write_text("earlier results")
    status, text = fit_run(folder)
    return status == 2 and (folder / "out" / "fit.json").read_text() == "earlier results" and "--overwrite" in text


def _file_as_out_kept(folder):
    folder = pathlib.Path(folder)
    (folder / "out").write_text("mine")
    status, text = fit_run(folder)
    return status == 2 and (folder / "out").read_text() == "mine" and "--out" in text


def _out_under_a_file(folder):
    _table(folder, "mine", "afile")
    return fit_run(folder, "--out", pathlib.Path(folder) / "afile" / "x")


def _variant(folder, old, new):
    """fit.toml with `old` replaced by `new`, as b.toml."""
    path = pathlib.Path(folder) / "b.toml"
    path.write_text((pathlib.Path(folder) / "fit.toml").read_text().replace(old, new))
    return path


def _other_data(folder):
    """A recording of the same shape with other values (1 Pa more), and a config reading it."""
    rec = pamjax.Recording.load(recording(folder))
    other = pamjax.Recording(T, {"pressure": rec["pressure"] + 1.0, "command": rec["command"]})
    other.to_csv(pathlib.Path(folder) / "other.csv")
    return _variant(folder, '"tank.csv"', '"other.csv"')


def _resume_forgotten(folder):
    fit_run(folder)
    (pathlib.Path(folder) / "out" / "fit.json").unlink()  # as if it never got that far
    return fit_run(folder)


def _read_only(folder):
    from pamjax._cli import out as _cli_out

    def refuse(fd):
        raise OSError(errno.EROFS, "Read-only file system")

    with patched(_cli_out.os, "fsync", refuse):
        return fit_run(folder)


# ---------------------------------------------------------------------------------------------------------------
# issue 33: model files, profiles, advice that works, API misuse, the program cache, memory


def _model_file(folder, edit=None, text=None, name="m.json"):
    """The averaged-valve stick-slip preset (what `pamjax fit examples/fit_example.toml` fits) as a model file,
    `edit(parameters)` applied by hand, or its text passed through `text`."""
    path = pamjax.save_model(pathlib.Path(folder) / name, presets.mas10_system("averaged", friction="karnopp"),
                             overwrite=True)
    doc = json.loads(path.read_text(encoding="utf-8"))
    if edit is not None:
        edit(doc["parameters"])
    body = json.dumps(doc, indent=1, ensure_ascii=False)
    path.write_text(text(body) if text else body, encoding="utf-8")
    return path


SIM = """
[model]
file = "{file}"
[input]
signal = {{ kind = "Triangle", low = 0.05, high = 0.95, frequency = 0.25 }}
[simulate]
t_end = 0.5
"""


def _simulate_file(folder, edit=None, text=None):
    """`pamjax simulate` of the hand-edited model file."""
    return _simulate(folder, SIM.format(file=_model_file(folder, edit, text).name))


def _unit_converted(folder):
    """A model file giving payload_mass in g and v0 in cm³ simulates as the SI model does."""
    folder = pathlib.Path(folder)

    def edit(p):
        p["payload_mass"].update(value=9600.0, unit="g")
        p["muscle.volume_law.v0"].update(value=float(p["muscle.volume_law.v0"]["value"]) * 1e6, unit="cm³")

    status, _ = _simulate_file(folder, edit)
    got = pamjax.Recording.load(folder / "sim" / "trajectory.csv")
    model = presets.mas10_system("averaged", friction="karnopp")
    expected = pamjax.simulate(model, pamjax.Triangle(0.05, 0.95, 0.25), got.t)
    return status == 0 and np.allclose(got["position"], expected.position, rtol=1e-12, atol=1e-15)


def _model_json_as_config(folder):
    """`pamjax simulate model.json`: refused, with a config; that config, written as told, simulates."""
    folder = pathlib.Path(folder)
    model = _model_file(folder)
    status, text = cli("simulate", model, "--out", folder / "sim", "--no-plot")
    lines = text.split("holding\n", 1)[-1].split("\nand then", 1)[0]
    (folder / "sim.toml").write_text("\n".join(line.strip() for line in lines.splitlines()) + "\n")
    again, _ = cli("simulate", folder / "sim.toml", "--out", folder / "sim", "--no-plot")
    return status == 2 and again == 0 and (folder / "sim" / "trajectory.csv").is_file()


def _profile_after_max_steps(folder):
    """`fit --profile` of a fit stopped at max_steps: the fit written, no profile, status 1, and the command it
    names (after raising max_steps as it says) writes the profile."""
    folder = pathlib.Path(folder)
    fit_config(folder)
    config = _variant(folder, "max_steps = 20", "max_steps = 1")
    status, text = fit_run(folder, "--profile", config=config)
    out = folder / "out"
    if status != 1 or (out / "profile.json").exists() or not (out / "fit.json").is_file():
        return False
    command = text.split("continue it with: ", 1)[-1].split()
    if command[:2] != ["pamjax", "fit"] or "--resume" not in command or "--profile" not in command:
        return False
    config.write_text(config.read_text().replace("max_steps = 1", "max_steps = 20"))
    status, _ = cli(*command[1:], "--quiet", "--no-plot")
    profile = json.loads((out / "profile.json").read_text()) if (out / "profile.json").exists() else None
    return status == 0 and profile is not None and all(p["verdict"] == "identifiable" for p in profile["profiles"])


def _profile_interrupted(folder):
    """Ctrl-C while profiling (the fit written): status 130, the fit said to be complete, and the command given
    writes the profile."""
    folder = pathlib.Path(folder)
    fit_config(folder)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    with patched(pamjax, "profile_to_minimum", interrupted):  # what pamjax fit --profile calls
        status, text = fit_run(folder, "--profile")
    if status != 130 or "complete and written" not in text or not (folder / "out" / "fit.json").is_file():
        return False
    command = text.split("Take the profiles with: ", 1)[-1].split()
    status, _ = cli(*command[1:], "--quiet", "--no-plot")
    return status == 0 and (folder / "out" / "profile.json").is_file()


def _flipped_coefficient(p):
    p["valve.coefficients"]["value"][1][0] = -abs(p["valve.coefficients"]["value"][1][0])


def _tree_at_mass(mass):
    import equinox as eqx

    system = presets.mas10_system("averaged")
    return eqx.tree_at(lambda s: s.payload_mass, system, jnp.asarray(mass))


def _vmapped(masses=(9.6, 5.0), duties=(0.5, 0.5)):
    import jax

    system = presets.mas10_system("averaged")

    def one(m, d):
        import equinox as eqx

        return pamjax.simulate(eqx.tree_at(lambda s: s.payload_mass, system, m), pamjax.Constant(d), T).position[-1]

    return jax.vmap(one)(jnp.asarray(masses), jnp.asarray(duties))


def _too_few_residuals():
    model = presets.mas10_system("averaged")
    rec = pamjax.synthetic_recording(model, pamjax.Constant(0.5), np.array([0.0, 0.05]),
                                     noise=dict(pressure=2e3, position=1e-4), seed=0)
    exp = pamjax.Experiment(rec, pamjax.Constant(0.5), channels=["pressure", "position"],
                            scales=dict(pressure=2e3, position=1e-4))
    return pamjax.fit(model, [exp], ["friction.coulomb_force", "muscle.volume_law.v0", "muscle.volume_law.v1",
                                     "muscle.force_law.k0", "friction.viscous_coefficient"], progress=False)


def _foreign_program_entry(folder):
    """A program cache entry exported for a GPU ('cuda'), met on the CPU: traced anew, the right result."""
    import jax

    from pamjax._core.cache import ProgramCache

    def fn(x):
        return jnp.cos(x) + 1.0

    x = jnp.linspace(0.0, 1.0, 7)
    programs = ProgramCache(folder)
    path = programs.directory / f"planted-{programs.key('planted', (x,))}.bin"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(bytes(jax.export.export(jax.jit(fn), platforms=("cuda",))(x).serialize()))
    return np.array_equal(np.asarray(programs.call("planted", fn, (x,))), np.asarray(fn(x)))


MEMORY_SCRIPT = """
import resource, sys
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np, pamjax
system = pamjax.presets.mas10_system("averaged", friction="karnopp")
ts = np.arange(300001) * 0.01
traj = pamjax.simulate(system, pamjax.Triangle(0.05, 0.95, 0.25), ts)
try:  # this process's own peak (Linux: VmHWM of its memory map). ru_maxrss would also count the parent's resident
    # memory at the fork (Linux keeps the pre-exec image's high-water mark): a 1.7 GB parent made the case fail
    peak = next(int(line.split()[1]) * 1024 for line in open("/proc/self/status") if line.startswith("VmHWM:"))
except (OSError, StopIteration):
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * (1 if sys.platform == "darwin" else 1024)
print(int(traj.result), float(np.max(np.asarray(traj.position))), peak)
"""


def _long_simulation_memory(folder):
    """A 3,000 s stick-slip run (3 M fixed steps, 300,001 rows) in a fresh process: solved, under 1 GB peak (one
    solve took 1.7 GB; a 19,000 s run 9.3 GB)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "JAX_PLATFORMS": "cpu"}
    proc = subprocess.run([sys.executable, "-c", MEMORY_SCRIPT], capture_output=True, text=True, env=env,
                          timeout=1800)
    result, peak_position, rss = proc.stdout.split()[-3:] if proc.returncode == 0 else ("1", "nan", "inf")
    return int(result) == 0 and 0.05 < float(peak_position) < 0.06 and float(rss) < 2**30


# ---------------------------------------------------------------------------------------------------------------
# the catalogue: name → (class, expect, run, name_in_message)

E, R, K = "error", "result", "kept"
CASES = {
    # configs: values land where written
    "config set list for a scalar": ("config", E, lambda d: fit_run(d, config=fit_config(
        d, set='"valve.coefficients[1,0]" = [1.5e-3, 7.0]')), "expects one number, got shape (2,)"),
    "config set short list": ("config", E, lambda d: fit_run(d, config=fit_config(
        d, set='"valve.coefficients" = [1.0, 2.0]')), "expects shape (3, 3)"),
    "config set string": ("config", E, lambda d: fit_run(d, config=fit_config(d, set='"volume" = "50 ml"')),
                          "must be a number"),
    "config set unknown path": ("config", E, lambda d: fit_run(d, config=fit_config(d, set='"volumes" = 5e-5')),
                                "unknown parameter 'volumes'"),
    "config set refused by the component": ("config", E, lambda d: fit_run(d, config=fit_config(
        d, set='"volume" = -5e-5')), "volume"),
    "config channels as a string": ("config", E, lambda d: fit_run(d, config=fit_config(d, channels='"pressure"')),
                                    "a single string where a list is expected"),
    "config TOML syntax error": ("config", E, lambda d: fit_run(d, config=_table(d, "[fit\nfree = 1\n", "b.toml")),
                                 "line 1, column 5"),
    "config model file missing": ("config", E, lambda d: fit_run(d, config=_table(
        d, '[model]\nfile = "none.json"\n[fit]\nfree = ["volume"]\n[[experiment]]\nfile = "r.csv"\n', "b.toml")),
        "does not exist"),
    "config model file not JSON": ("config", E, lambda d: call(pamjax.load_model, _table(d, "{,}", "m.json")),
                                   "line 1, column 2"),
    "config model file with a foreign class": ("config", E, lambda d: call(pamjax.load_model, _table(d, json.dumps(
        {"format": "pamjax-model", "format_version": 1, "parameters": {},
         "structure": {"class": "subprocess.Popen", "fields": {}}}), "m.json")), "not a pamjax model class"),
    # CSV files
    "csv semicolon-separated": ("csv", R, lambda d: _same_recording(_table(d, _csv(";"))), None),
    "csv tab-separated": ("csv", R, lambda d: _same_recording(_table(d, _csv("\t"))), None),
    "csv Excel UTF-8 byte-order mark, quoted header": ("csv", R, lambda d: _same_recording(_table(
        d, "\ufeff" + _csv(header=('"t [s]"', '"pressure [Pa]"', '"position [m]"')))), None),
    "csv decimal commas": ("csv", R, lambda d: _same_recording(_table(
        d, _csv(";", fmt=lambda v: repr(v).replace(".", ",")))), None),
    "csv Windows-1252 comment": ("csv", R, lambda d: _same_recording(_table(
        d, "# Prüfstand 3, 23 °C\n" + _csv(), encoding="cp1252")), None),
    "csv non-numeric cell": ("csv", E, lambda d: _error_in(_table(d, _csv().replace("0.05,", "0.05s,", 1))),
                             "line 7 (data row 5), column 1"),
    "csv duplicate column": ("csv", E, lambda d: _error_in(_table(d, _csv(
        header=("t [s]", "pressure [Pa]", "pressure [Pa]"), x=101325.0 + np.zeros(T.size)))),
        "both named 'pressure'"),
    "csv pandas index column": ("csv", E, lambda d: _error_in(_table(d, "\n".join(
        [",".join(["Unnamed: 0", *line.split(",")]) if k == 0 else f"{k - 1},{line}"
         for k, line in enumerate(_csv().splitlines())]) + "\n")), "looks like a row index"),
    "csv ragged row": ("csv", E, lambda d: _error_in(_table(d, _csv() + "0.6,1e5,0,7\n")), "4 columns"),
    "csv empty file": ("csv", E, lambda d: _error_in(_table(d, "")), "no header line"),
    "csv without a time column": ("csv", E, lambda d: _error_in(_table(d, _csv(
        header=("seconds", "pressure [Pa]", "position [m]")))), "needs a time column"),
    # units
    "units position [mm] converted": ("units", R, lambda d: np.allclose(pamjax.Recording.load(_table(d, _csv(
        header=("t [s]", "pressure [Pa]", "position [mm]"), x=0.1 * np.arange(T.size))))["position"],
        1e-4 * np.arange(T.size), rtol=1e-12, atol=1e-15), None),
    "units t [ms] converted": ("units", R, lambda d: np.allclose(pamjax.Recording.load(_table(d, _csv(
        header=("t [ms]", "pressure [Pa]", "position [m]"), t=T * 1e3))).t, T, rtol=0, atol=1e-12), None),
    "units pressure [bar gauge] converted": ("units", R, lambda d: np.allclose(pamjax.Recording.load(_table(d, _csv(
        header=("t [s]", "pressure [bar gauge]", "position [m]"), p=0.01 * np.arange(T.size))))["pressure"],
        101325.0 + 1e3 * np.arange(T.size), rtol=1e-12), None),
    "units pressure [bar] without abs or gauge": ("units", E, lambda d: _error_in(_table(d, _csv(
        header=("t [s]", "pressure [bar]", "position [m]"), p=np.full(T.size, 3.0)))), "ABSOLUTE or GAUGE"),
    "units millimetres under [m]": ("units", E, lambda d: _error_in(_table(d, _csv(x=0.1 * np.arange(T.size)))),
                                    "look like mm"),
    "units milliseconds under [s]": ("units", E, lambda d: _error_in(_table(d, _csv(t=T * 1e3))), "look like ms"),
    "units bar under [Pa]": ("units", E, lambda d: _error_in(_table(d, _csv(p=np.linspace(1.0, 6.5, T.size)))),
                             "looks like bar"),
    "units position [N]": ("units", E, lambda d: _error_in(_table(d, _csv(
        header=("t [s]", "pressure [Pa]", "position [N]")))), "a force unit"),
    "units supply pressure below atmospheric": ("units", E, lambda d: call(presets.mas10_valve, supply_pressure=9e4),
                                                "exceed atmospheric"),
    "units supply pressure in MPa (Python)": ("units", E, lambda d: call(presets.mas10_valve, supply_pressure=0.65),
                                              "looks like MPa"),
    "units initial pressure 1.01325 (config)": ("units", E, lambda d: fit_run(d, config=fit_config(
        d, extra="initial = { pressure = 1.01325 }")), "looks like bar"),
    "units initial pressure 1.01325 (simulate)": ("units", E, lambda d: call(
        pamjax.simulate, presets.mas10_tank_system("averaged"), pamjax.Constant(0.5), jnp.linspace(0, 0.1, 3),
        y0=pamjax.TankState(jnp.asarray(1.01325))), "looks like bar"),
    "units tank volume in cm3 (config)": ("units", E, lambda d: fit_run(d, config=fit_config(
        d, set='"volume" = 50.0')), "cm³ or litres"),
    "units sweep pressures in bar": ("units", E, lambda d: _sweep(
        d, 'kind = "flow_surface"\n[sweep]\npressures = [1.0, 3.0, 6.5]\n'), "looks like bar"),
    "units sweep commands in percent": ("units", E, lambda d: _sweep(
        d, 'kind = "steady_state"\n[sweep]\ncommands = [20, 50]\n'), "look like percent"),
    "units simulate t_end in ms": ("units", E, lambda d: _simulate(
        d, '[input]\nsignal = { kind = "Constant", value = 0.5 }\n[simulate]\nt_end = 25000.0\n'),
        "check t_end is in seconds"),
    # output paths
    "path --out is a file": ("paths", K, _file_as_out_kept, None),
    "path --out under a file": ("paths", E, _out_under_a_file, "afile is a file"),
    "path --out not writable": ("paths", E, _read_only, "cannot write to the output folder"),
    "path earlier results kept": ("paths", K, _existing_kept, None),
    "path results unwritable at the end": ("paths", K, _fallback, None),
    # concurrency
    "concurrency a second pamjax on one folder": ("concurrency", E, _locked, "in use by another pamjax"),
    # interrupts
    "interrupt Ctrl-C during the fit, then --resume": ("interrupts", K, _interrupted_then_resumed, None),
    "interrupt SIGINT while compiling": ("interrupts", E, lambda d: _signal(d, signal.SIGINT, 130), "nothing to"),
    "interrupt SIGTERM while compiling": ("interrupts", E, lambda d: _signal(d, signal.SIGTERM, 143), "terminated"),
    # resume mismatches
    "resume another start value": ("resume", E, lambda d: _fingerprint_refusal(d, lambda f: fit_config(
        f, set='"valve.coefficients[1,0]" = 1.6e-3', name="b.toml")), "start model differs in valve.coefficients"),
    "resume other data of the same shape": ("resume", E, lambda d: _fingerprint_refusal(d, _other_data),
                                            "has other data"),
    "resume other scales": ("resume", E, lambda d: _fingerprint_refusal(d, lambda f: _variant(f, "2e3", "3e3")),
                            "has other settings"),
    "resume without a checkpoint": ("resume", E, lambda d: fit_run(d, "--resume"), "holds no checkpoint"),
    "resume forgotten (a checkpoint is there)": ("resume", E, _resume_forgotten, "continue it with --resume"),
    # solves that failed with a hint blaming max_steps
    "solve exact-edge valve at duty 0": ("solve", R, lambda d: _solves(
        presets.mas10_system("exact"), pamjax.Constant(0.0), 2.5), None),
    "solve exact-edge valve at duty 1": ("solve", R, lambda d: _solves(
        presets.mas10_system("exact"), pamjax.Constant(1.0), 2.5), None),
    "solve 1 g payload with the switching valve": ("solve", E, lambda d: call(
        pamjax.simulate, presets.mas10_system("pwm", payload_mass=1e-3), pamjax.Constant(0.5),
        jnp.linspace(0.0, 0.5, 11), max_steps=20_000), "payload_mass = 0.001 kg"),
    # the fitted model carried onward
    "model fit -> model.json -> simulate": ("model", R, _model_travels, None),
    "model sweep over any parameter path": ("model", R, _sweep_any_path, None),
    # model files go through the checks of every other input (issue 33)
    "model file grams under kg": ("model", E, lambda d: _simulate_file(
        d, lambda p: p["payload_mass"].update(value=9600.0)), "looks like g"),
    "model file cm³ under m³": ("model", E, lambda d: _simulate_file(
        d, lambda p: p["muscle.volume_law.v0"].update(value=23.1)), "looks like cm³"),
    "model file bar under Pa abs": ("model", E, lambda d: _simulate_file(
        d, lambda p: p["air.atmospheric_pressure"].update(value=1.01325)), "looks like bar"),
    "model file °C under K": ("model", E, lambda d: _simulate_file(
        d, lambda p: p["air.temperature"].update(value=20.0)), "looks like °C"),
    "model file units g and cm³ converted": ("model", R, _unit_converted, None),
    "model file unit pamjax cannot convert": ("model", E, lambda d: _simulate_file(
        d, lambda p: p["payload_mass"].update(unit="lb")), "unit 'lb' is not one pamjax converts"),
    "model file dtype int8": ("model", E, lambda d: _simulate_file(
        d, lambda p: p["payload_mass"].update(dtype="int8")), "dtype 'int8'"),
    "model file key given twice": ("model", E, lambda d: _simulate_file(d, text=lambda body: body.replace(
        '"payload_mass": {', '"payload_mass": {"value": 96.0, "unit": "kg"},\n  "payload_mass": {', 1)),
        "appears twice in one table"),
    "model file parameter with several values": ("model", E, lambda d: _simulate_file(
        d, lambda p: p["payload_mass"].update(value=[9.6, 9.6])), "has shape (2,) where the model takes one number"),
    "model save of a model load refuses": ("model", E, lambda d: call(
        pamjax.save_model, pathlib.Path(d) / "m.json", _tree_at_mass(np.nan)), "payload_mass must be > 0"),
    "model file given to pamjax simulate": ("model", R, _model_json_as_config, None),
    # profiles need a minimum
    "profile after a fit stopped at max_steps": ("profile", R, _profile_after_max_steps, None),
    "profile interrupted after the fit": ("profile", K, _profile_interrupted, None),
    # advice that works
    "solve sign-flipped valve coefficient in a model file": ("solve", E, lambda d: _simulate_file(
        d, _flipped_coefficient), "negative inflow"),
    # the Python API misused
    "api bad parameter set with eqx.tree_at": ("api", E, lambda d: call(
        pamjax.simulate, _tree_at_mass(-1.0), pamjax.Constant(0.5), T), "payload_mass must be > 0"),
    "api grams set with eqx.tree_at": ("api", E, lambda d: call(
        pamjax.simulate, _tree_at_mass(9600.0), pamjax.Constant(0.5), T), "looks like g"),
    "api parameter with an axis too many": ("api", E, lambda d: call(
        pamjax.simulate, _tree_at_mass([9.6, 5.0]), pamjax.Constant(0.5), T), "'payload_mass' has shape (2,)"),
    "api bad parameter inside jax.vmap": ("api", E, lambda d: call(_vmapped, masses=(9.6, -1.0)),
                                          "payload_mass must be > 0"),
    "api duty out of range inside jax.vmap": ("api", E, lambda d: call(_vmapped, duties=(0.3, 1.5)),
                                              "must stay within [0.0, 1.0]"),
    "api duty in percent": ("api", E, lambda d: call(
        pamjax.simulate, presets.mas10_system("averaged"), pamjax.Constant(50.0), T), "looks like percent"),
    "api free entries that overlap": ("api", E, lambda d: call(
        pamjax.ParameterSpace, presets.mas10_system("averaged"), ["valve.coefficients", "valve.coefficients[1,0]"]),
        "free names valve.coefficients[1,0] twice"),
    "api fewer residuals than free parameters": ("api", E, lambda d: call(_too_few_residuals),
                                                 "4 residuals (samples × channels used for identification) for 5"),
    # the program cache
    "cache program exported for another platform": ("cache", R, _foreign_program_entry, None),
}
# Slow cases (a fresh process or a long solve each): in the benchmark, not in the test suite.
SLOW = {"interrupt SIGINT while compiling", "interrupt SIGTERM while compiling", "solve 1,000 s PWM run",
        "memory 3,000 s stick-slip simulation"}
CASES["memory 3,000 s stick-slip simulation"] = ("memory", R, _long_simulation_memory, None)
CASES["solve 1,000 s PWM run"] = ("solve", R, lambda d: _solves(presets.mas10_system("pwm"), pamjax.Constant(0.5),
                                                                1000.0), None)


def verdict(name):
    """Run case `name` in a fresh temporary folder: "ok", "silent_wrong", "lost_work", "traceback" or "unnamed",
    and the text or detail behind it."""
    _, expect, run, message = CASES[name]
    with tempfile.TemporaryDirectory() as d:
        try:
            got = run(d)
        except Exception as err:  # noqa: BLE001 - anything escaping is a traceback the user would see
            return "traceback", f"{type(err).__name__}: {err}"
    if expect == R:
        return ("ok" if got else "silent_wrong"), ""
    if expect == K:
        return ("ok" if got else "lost_work"), ""
    status, text = got
    if status is None or "Traceback" in text:
        return "traceback", text
    if status == 0:
        return "silent_wrong", text
    return ("ok" if message in text else "unnamed"), text


def summary(names=None, report=print):
    """Run the cases (all by default); returns counts {"ok", "silent_wrong", "lost_work", "traceback", "unnamed",
    "total"} and reports every case that is not ok."""
    counts = dict(ok=0, silent_wrong=0, lost_work=0, traceback=0, unnamed=0)
    for name in sorted(CASES if names is None else names):
        result, text = verdict(name)
        counts[result] += 1
        if result != "ok":
            report(f"  {result}: [{CASES[name][0]}] {name}: {text.strip()[:300]}")
    counts["total"] = sum(counts.values())
    return counts
