"""The command line: `pamjax fit CONFIG.toml` and `pamjax sweep CONFIG.toml` check every table and key of their
config before anything is solved (an unknown key names itself and lists the valid ones), never replace results
without `--overwrite`, and `pamjax sweep` writes NPZ, CSV and a figure."""

import pathlib
import textwrap
import tomllib

import numpy as np
import pytest

import pamjax
import pamjax._cli_sweep as cli_sweep
from pamjax._cli import main

EXAMPLES = pathlib.Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(autouse=True)
def no_solves(monkeypatch):
    """Any fit or sweep reached is a test failure: the config errors below must come first."""

    def refuse(*args, **kwargs):
        raise AssertionError("a solve was started before the config was rejected")

    monkeypatch.setattr(pamjax, "fit", refuse)
    for name in ("steady_state_map", "frequency_response", "flow_surface"):
        monkeypatch.setattr(cli_sweep, name, refuse)


def _write(tmp_path, text, name="cfg.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


# ---------------------------------------------------------------------------------------------------------------
# pamjax fit

_FIT_OK = """
    [model]
    preset = "mas10_system"
    options = { valve = "averaged" }
    [fit]
    free = ["friction.coulomb_force"]
    [[experiment]]
    file = "missing.csv"        # never read: every case below must fail before data are loaded
    signal = { kind = "Triangle", low = 0.05, high = 0.95, frequency = 0.25 }
"""


def _fit_config(replace=None, append=""):
    text = _FIT_OK
    for old, new in (replace or {}).items():
        assert old in text, old
        text = text.replace(old, new)
    return text + textwrap.dedent(append)


FIT_CASES = {
    "top-level key": (_fit_config(append="[solver]\nrtol = 1e-6\n"),
                      r"unknown key\(s\) \['solver'\]; valid keys are \['experiment', 'fit', 'model'\]"),
    "[model] key": (_fit_config({'preset = "mas10_system"': 'preset = "mas10_system"\nvalve = "pwm"'}),
                    r"\[model\]: unknown key\(s\) \['valve'\]; valid keys are \['options', 'preset', 'set'\]"),
    "[model] options key": (_fit_config({'valve = "averaged"': 'valves = "averaged"'}),
                            r"options .*unknown key\(s\) \['valves'\]; valid keys are \['friction', "
                            r"'payload_mass', 'silencer', 'valve'\]"),
    "[model] preset": (_fit_config({'"mas10_system"': '"mas20_system"'}),
                       r"preset must be one of \['mas10_system', 'mas10_tank_system'\]"),
    "[model] set path": (_fit_config({'[fit]': 'set = { "muscle.volume.v0" = 3e-5 }\n[fit]'}),
                         r"unknown parameter 'muscle.volume.v0'(.|\n)*muscle.volume_law.v0"),
    "[fit] key": (_fit_config({"[fit]": "[fit]\nmaxsteps = 3"}),
                  r"\[fit\]: unknown key\(s\) \['maxsteps'\]; valid keys are \['atol', 'free', 'max_steps'"),
    "[fit] free path": (_fit_config({'"friction.coulomb_force"': '"friction.coulomb"'}),
                        r"unknown parameter 'friction.coulomb'(.|\n)*friction.coulomb_force"),
    "[fit] free table key": (_fit_config({'"friction.coulomb_force"':
                                          '{ path = "friction.coulomb_force", transfrom = "log" }'}),
                             r"free entry: unknown key\(s\) \['transfrom'\]; valid keys are \['bounds', 'path', "
                             r"'scale', 'transform'\]"),
    "experiment key": (_fit_config(append="noise = 2e3\n"),
                       r"#1: unknown key\(s\) \['noise'\]; valid keys are \['channels', 'file'"),
    "experiment as a single table": (_fit_config({"[[experiment]]": "[experiment]"}), r"\[\[experiment\]\]"),
    "signal key": (_fit_config({"frequency = 0.25": "freq = 0.25"}),
                   r"signal \(kind = 'Triangle'\): unknown key\(s\) \['freq'\]; valid keys are \['frequency', "
                   r"'high', 'kind', 'low'\]"),
    "signal kind": (_fit_config({'kind = "Triangle"': 'kind = "Square"'}),
                    r"kind in \['Constant', 'Triangle', 'Sine', 'Step', 'recorded'\]"),
    "recorded signal key": (_fit_config({'{ kind = "Triangle", low = 0.05, high = 0.95, frequency = 0.25 }':
                                         '{ kind = "recorded", periods = 0.02 }'}),
                            r"unknown key\(s\) \['periods'\]; valid keys are \['kind', 'period'\]"),
    "initial key": (_fit_config(append="initial = { pressur = 101325.0 }\n"),
                    r"initial .*MuscleSystem.*unknown key\(s\) \['pressur'\]; valid keys are \['position', "
                    r"'pressure', 'velocity'\]"),
    "tank initial key": (_fit_config(append="tank_volume = 5e-5\ninitial = { position = 0.0 }\n"),
                         r"initial .*TankSystem.*unknown key\(s\) \['position'\]; valid keys are \['pressure'\]"),
    "TOML syntax": ("[fit\nfree = 1\n", "not valid TOML"),
}


@pytest.mark.parametrize("case", sorted(FIT_CASES))
def test_fit_config_errors_name_the_key_before_any_solve(tmp_path, case):
    text, match = FIT_CASES[case]
    config = _write(tmp_path, text)
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        main(["fit", str(config), "--out", str(tmp_path / "out"), "--quiet"])
    assert not (tmp_path / "out").exists()


def test_fit_refuses_to_replace_results_before_fitting(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "fit.json").write_text("{}")
    with pytest.raises(SystemExit, match="fit.json exists; pass --overwrite"):
        main(["fit", str(EXAMPLES / "fit_example.toml"), "--out", str(out), "--quiet"])
    assert (out / "fit.json").read_text() == "{}"


# ---------------------------------------------------------------------------------------------------------------
# pamjax sweep

SWEEP_CASES = {
    "top-level key": ('kind = "flow_surface"\n[plot]\ndpi = 100\n',
                      r"unknown key\(s\) \['plot'\]; valid keys are \['kind', 'sweep', 'system'\]"),
    "kind": ('kind = "bode"\n', r"kind must be one of \['steady_state', 'flow_surface', 'frequency_response'\]"),
    # flow_surface maps the valve alone: a muscle-system key would be silently ignored
    "flow_surface [system] valve": ('kind = "flow_surface"\n[system]\nvalve = "averaged"\n',
                                    r"\[system\] \(kind = 'flow_surface'\): unknown key\(s\) \['valve'\]; valid keys "
                                    r"are \['supply_pressure'\]"),
    "flow_surface [sweep] method": ('kind = "flow_surface"\n[sweep]\nmethod = "rk4"\n',
                                    r"unknown key\(s\) \['method'\]; valid keys are \['commands', 'pressures'\]"),
    "steady_state [system] supply_pressure": ('kind = "steady_state"\n[system]\nsupply_pressure = 7e5\n',
                                              r"unknown key\(s\) \['supply_pressure'\]; valid keys are "
                                              r"\['payload_mass', 'valve'\]"),
    "steady_state [sweep] frequencies": ('kind = "steady_state"\n[sweep]\nfrequencies = [1.0]\n',
                                         r"\[sweep\] \(kind = 'steady_state'\): unknown key\(s\) \['frequencies'\]; "
                                         r"valid keys are \['chunk_size', 'commands', 'dt', 'horizon'"),
    "frequency_response [sweep] horizon": ('kind = "frequency_response"\n[sweep]\nhorizon = 5.0\n',
                                           r"unknown key\(s\) \['horizon'\]; valid keys are \['amplitude', "),
    "axis key": ('kind = "steady_state"\n[sweep]\ncommands = { start = 0.0, stop = 1.0, num = 5, spacing = 1 }\n',
                 r"\[sweep\] commands: unknown key\(s\) \['spacing'\]; valid keys are \['log', 'num', 'start', "
                 r"'stop'\]"),
    "axis form": ('kind = "steady_state"\n[sweep]\ncommands = "0:1"\n', r"\[sweep\] commands must be"),
    "valve": ('kind = "steady_state"\n[system]\nvalve = "exact"\n',
              r"\[system\] valve must be one of \['pwm', 'averaged'\], got 'exact'"),
    "system not a table": ('kind = "steady_state"\nsystem = "pwm"\n', r"\[system\].* must be a table"),
}


@pytest.mark.parametrize("case", sorted(SWEEP_CASES))
def test_sweep_config_errors_name_the_key_before_any_solve(tmp_path, case):
    text, match = SWEEP_CASES[case]
    config = _write(tmp_path, text)
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        main(["sweep", str(config), "--out", str(tmp_path / "out")])
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("sweep_*.toml")), ids=lambda p: p.stem)
def test_example_sweep_configs_are_valid(path):
    cli_sweep.validate_config(tomllib.loads(path.read_text()))


def test_sweep_end_to_end_writes_outputs_and_refuses_to_overwrite(tmp_path, monkeypatch):
    monkeypatch.undo()  # this one solves
    config = _write(tmp_path, """
        kind = "steady_state"
        [system]
        valve = "averaged"            # eq. 13: a fast sweep
        payload_mass = 9.6            # kg
        [sweep]
        commands = [0.2, 0.5, 0.8]
        horizon = 1.0                 # s
        window = 0.2                  # s
    """)
    out = tmp_path / "out"
    assert main(["sweep", str(config), "--out", str(out)]) == 0
    data = np.load(out / "sweep.npz")
    np.testing.assert_array_equal(data["duty"], [0.2, 0.5, 0.8])
    assert np.all(data["status"] == 0)
    assert np.all(np.diff(data["pressure_pa_abs"]) > 0) and np.all(np.diff(data["position_m"]) > 0)
    assert (out / "sweep.csv").read_text().splitlines()[0] == "duty,pressure_pa_abs,position_m,status"
    assert len((out / "sweep.csv").read_text().splitlines()) == 4
    assert (out / "sweep.png").stat().st_size > 10_000
    before = (out / "sweep.npz").read_bytes()
    with pytest.raises(SystemExit, match="exists; pass --overwrite"):
        main(["sweep", str(config), "--out", str(out)])
    assert (out / "sweep.npz").read_bytes() == before
    assert main(["sweep", str(config), "--out", str(out), "--overwrite", "--no-plot"]) == 0


def test_sweep_splits_the_cpu_into_one_device_per_core_and_matches_one_device(tmp_path, monkeypatch):
    # `pamjax sweep` sets JAX's CPU device count before JAX runs (a fresh process, as from the shell) and shards the
    # sweep over the devices; the map equals the one-device map to 1e-12 relative (tests/test_sharding.py).
    import subprocess
    import sys

    monkeypatch.undo()
    config = _write(tmp_path, """
        kind = "steady_state"
        [system]
        valve = "averaged"
        [sweep]
        commands = [0.2, 0.4, 0.6, 0.8]
        horizon = 0.5                 # s
        window = 0.1                  # s
    """)
    runs = {}
    for n in (2, 1):
        out = tmp_path / f"out{n}"
        code = "import sys; from pamjax._cli import main; sys.exit(main(sys.argv[1:]))"
        proc = subprocess.run([sys.executable, "-c", code, "sweep", str(config), "--out", str(out), "--no-plot",
                               "--cpu-devices", str(n)], capture_output=True, text=True, timeout=600,
                              env={**__import__("os").environ, "JAX_PLATFORMS": "cpu"})
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert f"on {n} cpu device(s)" in proc.stdout, proc.stdout
        runs[n] = np.load(out / "sweep.npz")
    for key in ("pressure_pa_abs", "position_m"):
        np.testing.assert_allclose(runs[2][key], runs[1][key], rtol=1e-12, atol=0)
    with pytest.raises(SystemExit):
        main(["sweep", str(config), "--cpu-devices", "0"])
