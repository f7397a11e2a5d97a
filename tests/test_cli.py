"""The command line refuses bad input before any work: every table, key, value type, parameter path, shape and unit of
a config (`pamjax fit`, `pamjax sweep`, `pamjax simulate`) and every output folder that cannot take the results
(a file, under a file, not writable, in use by another pamjax, holding earlier results). Each refusal is one
message naming what is wrong and how to fix it, exit status 2, no traceback, nothing created; `--debug` (or
`PAMJAX_DEBUG=1`) shows the traceback. End-to-end runs: `test_cli_workflow.py`."""

import errno
import pathlib
import re
import textwrap
import tomllib

import numpy as np
import pytest

import pamjax
import pamjax._cli.out as cli_out
import pamjax._cli.sweep as cli_sweep
from pamjax import presets
from pamjax._cli.main import main
from pamjax._cli.out import OutputFolder

EXAMPLES = pathlib.Path(__file__).resolve().parents[1] / "examples"
TRIANGLE = (EXAMPLES / "triangle_025.csv").as_posix()  # 8 s at 50 Hz; its command: the 0.25 Hz triangle 0.05-0.95


@pytest.fixture
def no_solves(monkeypatch):
    """Any fit, simulation or sweep reached is a test failure: the errors below must come first."""

    def refuse(*args, **kwargs):
        raise AssertionError("a solve was started before the input was rejected")

    for name in ("fit", "simulate"):
        monkeypatch.setattr(pamjax, name, refuse)
    for name in ("steady_state_map", "frequency_response", "flow_surface"):
        monkeypatch.setattr(cli_sweep, name, refuse)


def _write(tmp_path, text, name="cfg.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def _refused(capsys, argv, match, code=2):
    """`pamjax argv` exits with `code`, one message matching `match` on stderr, and no traceback."""
    assert main(argv) == code
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    assert re.search(match, err), err
    return err


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


def _set(entries):
    return _fit_config({"[fit]": f"set = {{ {entries} }}\n[fit]"})


FIT_CASES = {
    "top-level key": (_fit_config(append="[solver]\nrtol = 1e-6\n"),
                      r"unknown key\(s\) \['solver'\]; valid keys are "
                      r"\['bench', 'experiment', 'fit', 'measurement', 'model', 'rig'\]"),
    "[model] key": (_fit_config({'preset = "mas10_system"': 'preset = "mas10_system"\nvalve = "pwm"'}),
                    r"\[model\]: unknown key\(s\) \['valve'\]; valid keys are \['file', 'options', 'preset', 'set'\]"),
    "[model] options key": (_fit_config({'valve = "averaged"': 'valves = "averaged"'}),
                            r"options .*unknown key\(s\) \['valves'\]; valid keys are \['friction', "
                            r"'payload_mass', 'silencer', 'valve'\]"),
    "[model] preset": (_fit_config({'"mas10_system"': '"mas20_system"'}),
                       r"preset must be one of \['mas10_system', 'mas10_tank_system'\]"),
    "[model] preset and file": (_fit_config({'[fit]': 'file = "model.json"\n[fit]'}),
                                r"either file .* or preset .*, not both; remove \['options', 'preset'\]"),
    "[model] missing model file": (_fit_config({'preset = "mas10_system"\n    options = { valve = "averaged" }':
                                                'file = "nowhere/model.json"'}),
                                   r"model file .*nowhere.* does not exist"),
    "[model] set path": (_set('"muscle.volume.v0" = 3e-5'),
                         r"unknown parameter 'muscle.volume.v0'(.|\n)*muscle.volume_law.v0"),
    # issue 15: a list here once spread over the following parameters (v1 = 7.0, C_f = 3.5e-4, ...)
    "[model] set list for a scalar": (_set('"muscle.volume_law.v0" = [3e-5, 7.0], "muscle.volume_law.v1" = 3.5e-4'),
                                      r"'muscle.volume_law.v0' expects one number, got shape \(2,\)"),
    "[model] set short list": (_set('"muscle.force_law.max_force_coefficients" = [630.0, 1.0]'),
                               r"'muscle.force_law.max_force_coefficients' expects shape \(5,\), got shape \(2,\)"),
    "[model] set string": (_set('"payload_mass" = "heavy"'), r"'payload_mass' must be a number .*got 'heavy'"),
    "[model] set index out of range": (_set('"valve.coefficients[3,0]" = 1.0'), r"index \[3, 0\] .* out of range"),
    "[model] set refused by the component": (_set('"payload_mass" = -1.0'), r"payload_mass must be > 0"),
    "[model] set supply in bar": (_set('"valve.coefficients[1,0]" = 1e-3, "air.atmospheric_pressure" = 1.01325'),
                                  r"air.atmospheric_pressure is 1.01325 Pa at most: that looks like bar"),
    "[model] options payload in grams": (_fit_config({'valve = "averaged"': 'valve = "averaged", payload_mass = 9600'}),
                                         r"payload_mass = 9600 kg: .*looks like g"),
    "[fit] key": (_fit_config({"[fit]": "[fit]\nmaxsteps = 3"}),
                  r"\[fit\]: unknown key\(s\) \['maxsteps'\]; valid keys are \['free', 'ftol', 'gtol', 'max_steps'"),
    "[fit] free path": (_fit_config({'"friction.coulomb_force"': '"friction.coulomb"'}),
                        r"unknown parameter 'friction.coulomb'(.|\n)*friction.coulomb_force"),
    "[fit] free as a string": (_fit_config({'free = ["friction.coulomb_force"]': 'free = "friction.coulomb_force"'}),
                               r"free must be a non-empty list .*put it in brackets"),
    "[fit] free table key": (_fit_config({'"friction.coulomb_force"':
                                          '{ path = "friction.coulomb_force", transfrom = "log" }'}),
                             r"free entry: unknown key\(s\) \['transfrom'\]; valid keys are \['bounds', 'path', "
                             r"'scale', 'transform'\]"),
    "[fit] free bounds": (_fit_config({'"friction.coulomb_force"': '{ path = "friction.coulomb_force", bounds = 5 }'}),
                          r"bounds must be \[lo, hi\]"),
    "[fit] free scale of the wrong shape": (_fit_config({'"friction.coulomb_force"':
                                                        '{ path = "valve.coefficients", scale = [1.0, 2.0] }'}),
                                           r"scale expects one number or shape \(3, 3\), got shape \(2,\)"),
    "[fit] max_steps float": (_fit_config({"[fit]": "[fit]\nmax_steps = 40.5"}),
                              r"\[fit\] max_steps must be a positive integer"),
    "experiment key": (_fit_config(append="noise = 2e3\n"),
                       r"#1: unknown key\(s\) \['noise'\]; valid keys are \['channels', 'file'"),
    "experiment as a single table": (_fit_config({"[[experiment]]": "[experiment]"}), r"\[\[experiment\]\]"),
    "experiment channels as a string": (_fit_config(append='channels = "pressure"\n'),
                                        r"channels must be a list of strings.*got 'pressure' \(a single string"),
    "experiment scale as a string": (_fit_config(append='scales = { pressure = "2 kPa" }\n'),
                                     r"scales.pressure must be a positive number"),
    "experiment initial pressure in bar": (_fit_config(append="initial = { pressure = 1.01325 }\n"),
                                           r"initial pressure is 1.01325 Pa at most: that looks like bar"),
    "experiment initial gauge pressure": (_fit_config(append="initial = { pressure = 0.0 }\n"), r"GAUGE"),
    "experiment initial position in mm": (_fit_config(append="initial = { position = 12.0 }\n"),
                                          r"initial position = 12 m: .*looks like mm"),
    "experiment payload in grams": (_fit_config(append="payload_kg = 30000.0\n"),
                                    r"payload_kg = 30000 kg: more than 1000 kg; that looks like g"),
    "experiment payload and tank volume": (_fit_config(append="payload_kg = 30.0\ntank_volume = 5e-5\n"),
                                           r"#1: give tank_volume .* or payload_kg .*not both"),
    "experiment tank volume in cm3": (_fit_config(append="tank_volume = 50.0\n"),
                                      r"tank_volume = 50 m³: .*looks like cm³ or litres"),
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
    "TOML syntax": ("[fit\nfree = 1\n", r"cfg.toml, line 1, column 5: not valid TOML: Expected '\]'(.|\n)*\[fit"),
    # an unquoted dotted key is a nested table in TOML: read as the dotted path (was: "unknown parameter 'friction'")
    "[model] set dotted key": (_fit_config({"[fit]": "[model.set]\nfriction.coulomb_forc = 20.0\n[fit]"}),
                               r"\[model\] set: unknown parameter 'friction.coulomb_forc'(.|\n)*"
                               r"friction.coulomb_force"),
    "[model] options number in quotes": (_fit_config({'"averaged"': '"averaged", payload_mass = "9.6"'}),
                                         r"\[model\] options payload_mass must be a number \[SI\], e.g. payload_mass = "
                                         r"9.6; got '9.6' \(a number in quotes"),
    "recorded period in ms": (_fit_config({'{ kind = "Triangle", low = 0.05, high = 0.95, frequency = 0.25 }':
                                           '{ kind = "recorded", period = 20.0 }'}),
                              r"#1 signal period = 20 s is longer than 1 s.*in seconds: 0.02 for 20 ms"),
    # checked against the recording (read, nothing solved): the bundled 8 s triangle run
    "recorded period as long as the recording": (
        _fit_config({'"missing.csv"': f'"{TRIANGLE}"',
                     '{ kind = "Triangle", low = 0.05, high = 0.95, frequency = 0.25 }':
                     '{ kind = "recorded", period = 0.8 }'}, append="t_end = 0.5\n"),
        r"#1 signal period = 0.8 s is not shorter than the recording \(0.5 s\).*in seconds: 0.02 for 20 ms"),
    "experiment t_end in ms": (_fit_config({'"missing.csv"': f'"{TRIANGLE}"'}, append="t_end = 8000.0\n"),
                               r"#1 t_end = 8000 s is past the end of recording 'triangle_025', which spans 0 … 8 s.*"
                               r"8 for 8000 ms"),
    # the typed signal (2.5 Hz) contradicts the run's own command column (the 0.25 Hz triangle): up to 0.9 apart
    "signal contradicting the recorded command": (
        _fit_config({'"missing.csv"': f'"{TRIANGLE}"', "frequency = 0.25": "frequency = 2.5"}),
        r"#1 \(triangle_025\) signal contradicts the recording's own command column: they differ by more than 0.05 "
        r".* at \d+ of 401 samples .*the largest at t = [\d.]+ s \(signal [\d.]+, recorded [\d.]+\).*"
        r'signal = "recorded"'),
    "missing recording": (_fit_config(), r"recording file .*missing.csv does not exist"),
}


@pytest.mark.parametrize("case", sorted(FIT_CASES))
def test_fit_config_errors_name_the_key_before_any_solve(tmp_path, capsys, no_solves, case):
    text, match = FIT_CASES[case]
    config = _write(tmp_path, text)
    _refused(capsys, ["fit", str(config), "--out", str(tmp_path / "out"), "--quiet"], match)
    assert not (tmp_path / "out").exists()


def test_example_fit_config_is_valid(no_solves):
    from pamjax._cli.fit import validate_config

    validate_config(tomllib.loads((EXAMPLES / "fit_example.toml").read_text()))


def test_an_experiment_with_payload_kg_drives_the_model_lifting_that_payload(tmp_path, no_solves):
    # [[experiment]] payload_kg: the run made with weights added (pamjax.PayloadFromModel); the other runs keep the
    # model's payload, and every other parameter is shared
    from pamjax._cli.fit import load_config

    t = np.arange(0.0, 0.1 + 5e-4, 1e-3)
    duty = np.asarray(pamjax.Triangle(0.05, 0.95, 0.25)(t))  # the config's signal: a contradicting column is refused
    rows = np.column_stack([t, duty, np.full(t.size, 2e5), np.zeros(t.size)])
    np.savetxt(tmp_path / "run.csv", rows, delimiter=",", header="t [s],duty [-],pressure [Pa],position [m]",
               comments="")
    body = _FIT_OK.replace('file = "missing.csv"', 'file = "run.csv"')
    config = tmp_path / "fit.toml"
    config.write_text(textwrap.dedent(body + '    payload_kg = 30.0\n    name = "heavy"\n'
                                      + body[body.index("    [[experiment]]"):]))
    model, experiments, *_ = load_config(config)
    heavy, plain = (e.system_for(model) for e in experiments)
    assert float(heavy.payload_mass) == 30.0 and float(plain.payload_mass) == float(model.payload_mass)
    assert float(heavy.muscle.force_law.k0) == float(model.muscle.force_law.k0)


def test_a_typed_signal_is_checked_against_the_recordings_command_allowing_a_pwm_latch():
    # the bundled runs' own signals agree with their command columns (the fit example fits them as typed)
    from pamjax._cli.config import check_against_command

    averaged, pwm = presets.mas10_system("averaged"), presets.mas10_system("pwm")
    triangle = pamjax.Triangle(0.05, 0.95, 0.25)
    check_against_command(triangle, pamjax.Recording.load(TRIANGLE), "E", averaged)
    check_against_command(pamjax.Constant(0.5), pamjax.Recording.load(EXAMPLES / "tank_charge_050.csv"), "E",
                          presets.mas10_tank_system("averaged"))
    # a 1 kHz log of a 2 Hz triangle's duty latched per 20 ms PWM period (as latched, or as the next period will
    # latch it): up to 0.07 off the typed signal, within the switching valve's period (a continuous valve allows
    # only a sample interval)
    t = np.arange(0.0, 2.0, 1e-3)
    fast = pamjax.Triangle(0.05, 0.95, 2.0)
    for start in (np.floor, np.ceil):
        latched = pamjax.Recording(t, {"command": np.asarray(fast(start(t / 0.02) * 0.02))}, name="latched")
        check_against_command(fast, latched, "E", pwm)
        with pytest.raises(pamjax.PamjaxInputError, match=r"E contradicts the recording's own command column"):
            check_against_command(fast, latched, "E", averaged)


def test_a_dotted_set_key_sets_the_dotted_parameter():
    # TOML reads `friction.coulomb_force = 20.0` as a table friction = { coulomb_force = 20.0 }
    from pamjax._cli.config import apply_set

    model = presets.mas10_system("averaged")
    nested = apply_set(model, tomllib.loads("friction.coulomb_force = 20.0\n"), "[model] set")
    assert float(nested.friction.coulomb_force) == 20.0
    twice = tomllib.loads('"friction.coulomb_force" = 20.0\nfriction.coulomb_force = 21.0\n')
    with pytest.raises(pamjax.PamjaxInputError, match=r"\[model\] set: 'friction.coulomb_force' is given twice"):
        apply_set(model, twice, "[model] set")


def test_a_dotted_over_key_sweeps_the_dotted_parameter():
    # `[sweep] over`'s unquoted dotted key was read as a table: "over.friction must be a non-empty list of numbers"
    from pamjax._cli.sweep import prepare

    config = tomllib.loads('kind = "steady_state"\n[system]\nvalve = "averaged"\n[sweep]\n'
                           'over = { friction.coulomb_force = [10.0, 20.0], payload_mass = { start = 5.0, '
                           'stop = 9.6, num = 2 } }\n')
    prepare(config)
    assert list(config["sweep"]["over"]) == ["friction.coulomb_force", "payload_mass"]
    twice = tomllib.loads('kind = "steady_state"\n[sweep.over]\n"friction.coulomb_force" = [1.0]\n'
                          'friction.coulomb_force = [2.0]\n')
    with pytest.raises(pamjax.PamjaxInputError, match=r"\[sweep\] over: 'friction.coulomb_force' is given twice"):
        prepare(twice)


def test_a_typed_signal_may_run_past_the_recording_drawn_beside_it(tmp_path, no_solves):
    # with dt the rows are the run's own; only the recording's channels are drawn (was and is accepted)
    from pamjax._cli.simulate import load

    text = _SIM_RECORDED.replace('"recorded"', '{ kind = "Constant", value = 0.5 }').replace("t_end = 1.0",
                                                                                             "t_end = 10.0\ndt = 0.5")
    # the triangle's recorded command is not 0.5: said, as the recording drawn beside is of another run (was silent)
    with pytest.warns(pamjax.PamjaxDataWarning, match=r"\[input\] signal contradicts the recording's own command "
                                                      r"column.*signal = \"recorded\" to simulate the recorded run"):
        assert float(load(_write(tmp_path, text)).ts[-1]) == 10.0


def test_a_typed_signal_that_matches_the_recording_is_simulated_without_a_word(tmp_path, no_solves):
    from pamjax._cli.simulate import load

    text = _SIM_RECORDED.replace('"recorded"', '{ kind = "Triangle", low = 0.05, high = 0.95, frequency = 0.25 }')
    assert load(_write(tmp_path, text)).recording is not None


# ---------------------------------------------------------------------------------------------------------------
# pamjax sweep

SWEEP_CASES = {
    "top-level key": ('kind = "flow_surface"\n[plot]\ndpi = 100\n',
                      r"unknown key\(s\) \['plot'\]; valid keys are \['kind', 'model', 'sweep', 'system'\]"),
    "kind": ('kind = "bode"\n', r"kind must be one of \['steady_state', 'flow_surface', 'frequency_response'\]"),
    # flow_surface maps the valve alone: a muscle-system key would be silently ignored
    "flow_surface [system] valve": ('kind = "flow_surface"\n[system]\nvalve = "averaged"\n',
                                    r"\[system\] \(kind = 'flow_surface'\): unknown key\(s\) \['valve'\]; valid keys "
                                    r"are \['supply_pressure'\]"),
    "flow_surface [sweep] method": ('kind = "flow_surface"\n[sweep]\nmethod = "rk4"\n',
                                    r"unknown key\(s\) \['method'\]; valid keys are \['commands', 'over', "
                                    r"'pressures'\]"),
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
    "commands in percent": ('kind = "steady_state"\n[sweep]\ncommands = [20, 50, 80]\n',
                            r"duty ratios in \[0, 1\], got 20 … 80 \(these look like percent"),
    "pressures in bar": ('kind = "flow_surface"\n[sweep]\npressures = [1.0, 3.0, 6.5]\n',
                         r"\[sweep\] pressures is 6.5 Pa at most: that looks like bar"),
    "supply pressure in MPa": ('kind = "flow_surface"\n[system]\nsupply_pressure = 0.65\n',
                               r"supply_pressure is 0.65 Pa at most: that looks like MPa"),
    "supply pressure below atmospheric": ('kind = "flow_surface"\n[system]\nsupply_pressure = 9e4\n',
                                          r"supply_pressure must exceed atmospheric pressure"),
    "payload in grams": ('kind = "steady_state"\n[system]\npayload_mass = 9600.0\n', r"looks like g"),
    "over unknown path": ('kind = "steady_state"\n[sweep]\nover = { "payload" = [1.0, 2.0] }\n',
                          r"unknown parameter 'payload'(.|\n)*payload_mass"),
    "over string": ('kind = "steady_state"\n[sweep]\nover = { "payload_mass" = "5, 10" }\n',
                    r"over.payload_mass must be a non-empty list .*a single string"),
    "over in grams": ('kind = "steady_state"\n[sweep]\nover = { "payload_mass" = [5000.0, 9600.0] }\n',
                      r"payload_mass = 9600 kg"),
    "model and system": ('kind = "steady_state"\n[system]\nvalve = "pwm"\n[model]\npreset = "mas10_system"\n',
                         r"either \[system\] .* or \[model\]"),
    "exact valve's flow surface": ('kind = "flow_surface"\n[model]\noptions = { valve = "exact" }\n',
                                   r"flow_surface' maps a smoothed switching valve, not the exact-edge one"),
    # only the grid's first point was checked: the bad last value failed after the earlier maps were solved
    "over bad last value, map by map": ('kind = "frequency_response"\n[system]\nvalve = "averaged"\n[sweep]\n'
                                        'frequencies = [0.2, 2.0]\n'
                                        'over = { "payload_mass" = [9.6, 5.0, 12.0, -1.0] }\n',
                                        r"\[sweep\] over: .*payload_mass must be > 0 and finite, got -1"),
    "over bad value of a second path": ('kind = "frequency_response"\n[system]\nvalve = "averaged"\n[sweep]\n'
                                        'over = { "payload_mass" = [9.6, 5.0], '
                                        '"friction.coulomb_force" = [10.0, -3.0] }\n',
                                        r"\[sweep\] over: .*coulomb_force .*-3"),
    "over dotted key, bad value": ('kind = "steady_state"\n[system]\nvalve = "averaged"\n[sweep]\n'
                                   'over = { friction.coulomb_force = [10.0, -3.0] }\n',
                                   r"\[sweep\] over: .*coulomb_force .*-3"),
    "over bad last value, one sweep": ('kind = "steady_state"\n[system]\nvalve = "averaged"\n[sweep]\n'
                                       'over = { "payload_mass" = [9.6, 5.0, -1.0] }\n',
                                       r"\[sweep\] over: .*payload_mass must be > 0 and finite, got -1"),
    # refused by the maps once they ran, after the output folder was created (was: an empty folder left behind)
    "window beyond horizon": ('kind = "steady_state"\n[system]\nvalve = "averaged"\n[sweep]\ncommands = [0.5]\n'
                              'horizon = 1.0\nwindow = 2.0\n', r"\[sweep\] window must lie in \(0, horizon = 1\] s"),
    "sample_interval beyond window": ('kind = "steady_state"\n[sweep]\ncommands = [0.5]\nwindow = 0.5\n'
                                      'sample_interval = 0.6\n', r"\[sweep\] sample_interval = 0.6 s must be at most"),
    # the window's mean of samples that coarse aliases the 50 Hz PWM's ripple (kPa off): was run, after the folder
    "sample_interval aliasing the PWM": ('kind = "steady_state"\n[sweep]\ncommands = [0.5]\nsample_interval = 0.01\n',
                                         r"sample_interval = 0.01 s is coarser than 1/20 of the switching valve's PWM"),
    "default sample_interval beyond window": ('kind = "steady_state"\n[system]\nvalve = "averaged"\n[sweep]\n'
                                              'window = 0.005\n', r"sample_interval = 0.01 s \(its default"),
    # the 50 Hz PWM latches one duty a period: at 30 Hz the "gain" was the ripple's (was: run, after the folder)
    "frequency response above the PWM's Nyquist": ('kind = "frequency_response"\n[sweep]\nfrequencies = [1.0, 30.0]\n',
                                                  r"\[sweep\] frequencies must lie below half the switching valve's "
                                                  r"PWM frequency \(50 Hz / 2 = 25 Hz\), got \[30\.\] Hz"),
    "frequency response beyond the duty range": ('kind = "frequency_response"\n[system]\nvalve = "averaged"\n'
                                                 '[sweep]\nfrequencies = [0.5]\noffset = 0.9\namplitude = 0.2\n',
                                                 r"\[sweep\] offset ± amplitude \(0.9 ± 0.2: 0.7 … 1.1\) must stay "
                                                 r"within the model's command range \[0, 1\]"),
}


@pytest.mark.parametrize("case", sorted(SWEEP_CASES))
def test_sweep_config_errors_name_the_key_before_any_solve(tmp_path, capsys, no_solves, case):
    text, match = SWEEP_CASES[case]
    config = _write(tmp_path, text)
    _refused(capsys, ["sweep", str(config), "--out", str(tmp_path / "out"), "--cpu-devices", "1"], match)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("sweep_*.toml")), ids=lambda p: p.stem)
def test_example_sweep_configs_are_valid(path):
    cli_sweep.validate_config(tomllib.loads(path.read_text()))


# ---------------------------------------------------------------------------------------------------------------
# pamjax simulate

_SIM_OK = """
    [model]
    preset = "mas10_system"
    [input]
    signal = { kind = "Constant", value = 0.5 }
    [simulate]
    t_end = 1.0
"""

_SIM_RECORDED = _SIM_OK.replace('{ kind = "Constant", value = 0.5 }', f'"recorded"\n    file = "{TRIANGLE}"')

SIMULATE_CASES = {
    "top-level key": (_SIM_OK + "[output]\n", r"unknown key\(s\) \['output'\]; valid keys are \['input', 'model'"),
    "no input": (_SIM_OK.replace('signal = { kind = "Constant", value = 0.5 }', ""), r"\[input\] needs a signal"),
    "no t_end": (_SIM_OK.replace("t_end = 1.0", ""), r"needs t_end"),
    "t_end as text": (_SIM_OK.replace("t_end = 1.0", 't_end = "1 s"'), r"t_end must be a positive number"),
    "duty in percent": (_SIM_OK.replace("value = 0.5", "value = 50.0"), r"signal .* within \[0(.0)?, 1(.0)?\]"),
    "unknown solver": (_SIM_OK + 'solver = "RK45"\n', r"solver must be one of \['Tsit5', 'Rodas5'"),
    "initial pressure in bar": (_SIM_OK + "initial = { pressure = 6.5 }\n", r"looks like bar"),
    "initial key": (_SIM_OK + "initial = { pressur = 2e5 }\n", r"unknown key\(s\) \['pressur'\]"),
    "too many rows": (_SIM_OK.replace("t_end = 1.0", "t_end = 25000.0\ndt = 0.001"),
                      r"would write 25,000,001 rows .* check t_end is in seconds"),
    "recorded without a file": (_SIM_OK.replace('{ kind = "Constant", value = 0.5 }', '"recorded"'),
                                r"'recorded' needs file"),
    # t_end 1.0 at dt 0.3 ended the CSV at 0.9 s without a word
    "dt that does not divide the run": (_SIM_OK + "dt = 0.3\n", r"dt = 0.3 s does not divide t_end - t0 = 1 s: the "
                                        r"rows would end at 0.9 s, short of t_end; set dt = 0.25"),
    # 20 for 20 ms held the first recorded duty all run; a t_end past the recording ended the rows at its end
    "recorded period in ms": (_SIM_RECORDED.replace('"recorded"', '{ kind = "recorded", period = 20.0 }'),
                              r"\[input\] signal period = 20 s is longer than 1 s.*in seconds: 0.02 for 20 ms"),
    "t_end past the recording": (_SIM_RECORDED.replace("t_end = 1.0", "t_end = 20.0"),
                                 r"\[simulate\] t_end = 20 s is past the end of recording 'triangle_025', which spans "
                                 r"0 … 8 s \(8 s\): its command drives the model and ends there(?!;)"),
    # the first recorded duty was held back to a t0 before the log (a made-up command)
    "t0 before the recording": (_SIM_RECORDED + "t0 = -2.0\n", r"\[simulate\] t0 = -2 s is before the start of "
                                r"recording 'triangle_025', which spans 0 … 8 s: its command drives the model"),
    "t_end past the recording's times": (_SIM_RECORDED.replace('"recorded"', '{ kind = "Constant", value = 0.5 }')
                                         .replace("t_end = 1.0", "t_end = 8000.0"),
                                         r"t_end = 8000 s is past .*the output rows are its times and end there \(give "
                                         r"dt to simulate the signal past it\); t_end is in seconds: 8 for 8000 ms"),
    # the uniform grid read a switching valve's duty unlatched: tens of kPa off, silently
    "grid with a switching valve": (_SIM_OK + 'stepping = "grid"\n',
                                    r"stepping='grid' is for continuous valves.* use stepping='pwm'"),
}


@pytest.mark.parametrize("case", sorted(SIMULATE_CASES))
def test_simulate_config_errors_name_the_key_before_any_solve(tmp_path, capsys, no_solves, case):
    text, match = SIMULATE_CASES[case]
    config = _write(tmp_path, text)
    _refused(capsys, ["simulate", str(config), "--out", str(tmp_path / "out")], match)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("simulate_*.toml")), ids=lambda p: p.stem)
def test_example_simulate_configs_are_valid(path):
    from pamjax._cli.simulate import validate_config

    validate_config(tomllib.loads(path.read_text()))


# ---------------------------------------------------------------------------------------------------------------
# output folders: checked before any work


@pytest.fixture
def sweep_config(tmp_path):
    return _write(tmp_path, 'kind = "steady_state"\n[system]\nvalve = "averaged"\n[sweep]\ncommands = [0.5]\n')


def test_out_naming_a_file_or_lying_under_one_is_refused(tmp_path, capsys, no_solves, sweep_config):
    (tmp_path / "afile").write_text("mine")
    _refused(capsys, ["sweep", str(sweep_config), "--out", str(tmp_path / "afile")],
             r"--out .*afile is a file, not a folder; choose another folder with --out")
    _refused(capsys, ["sweep", str(sweep_config), "--out", str(tmp_path / "afile" / "x")],
             r"cannot create the output folder .*afile is a file; choose another folder with --out")
    assert (tmp_path / "afile").read_text() == "mine"


def test_an_unwritable_out_is_refused_before_any_work(tmp_path, capsys, no_solves, sweep_config, monkeypatch):
    def read_only(fd):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(cli_out.os, "fsync", read_only)
    _refused(capsys, ["sweep", str(sweep_config), "--out", str(tmp_path / "out")],
             r"cannot write to the output folder .*out \(Read-only file system\); choose another folder with --out")
    assert not any(p.name.startswith(".pamjax") for p in (tmp_path / "out").iterdir())


def test_a_folder_in_use_by_another_pamjax_is_refused(tmp_path, capsys, no_solves, sweep_config):
    with OutputFolder(tmp_path / "out", "pamjax fit", ["fit.json"]):
        _refused(capsys, ["sweep", str(sweep_config), "--out", str(tmp_path / "out")],
                 r"out is in use by another pamjax \(pamjax fit, pid \d+ on .*\); wait for it to finish, or choose "
                 r"another folder with --out")
    assert not (tmp_path / "out" / cli_out.LOCK_NAME).exists()  # released at the end
    with OutputFolder(tmp_path / "out", "pamjax fit", ["fit.json"]):  # and can be taken again
        pass


def test_existing_results_are_refused_with_the_flag_that_replaces_them(tmp_path, capsys, no_solves, sweep_config):
    out = tmp_path / "out"
    out.mkdir()
    (out / "sweep.csv").write_text("earlier")
    _refused(capsys, ["sweep", str(sweep_config), "--out", str(out)],
             r"sweep.csv exists; pass --overwrite to replace it, or choose another folder with --out")
    assert (out / "sweep.csv").read_text() == "earlier"


def test_overwrite_replaces_the_earlier_results_whole_once_the_new_ones_are_written(tmp_path):
    # `pamjax fit --overwrite` without --profile left the earlier fit's profile.json/png beside the new fit.json
    # (read as its profile); `simulate --overwrite --no-plot` left the earlier trajectory.png.
    out = tmp_path / "out"
    out.mkdir()
    for name in ("fit.json", "profile.json", "profile.png", "notes.txt"):
        (out / name).write_text("earlier")
    stale = ["fit.png", "profile.json", "profile.png"]
    with pytest.raises(RuntimeError):  # a run that fails leaves the earlier results as they were
        with OutputFolder(out, "pamjax fit", ["fit.json"], overwrite=True, stale=stale):
            raise RuntimeError("interrupted")
    assert (out / "profile.json").exists()
    with OutputFolder(out, "pamjax fit", ["fit.json"], overwrite=True, stale=stale) as folder:
        folder.write_text("fit.json", "new")
        assert (out / "profile.json").exists()  # until the command is done
    assert (out / "fit.json").read_text() == "new"
    assert not (out / "profile.json").exists() and not (out / "profile.png").exists()
    assert (out / "notes.txt").read_text() == "earlier"  # not a pamjax output: never touched
    with OutputFolder(out, "pamjax fit", ["fit.json", "profile.json"], overwrite=True, stale=stale) as folder:
        folder.write_text("profile.json", "kept")  # an output of this run is never in its stale list
    assert (out / "profile.json").read_text() == "kept"


def test_results_that_cannot_be_written_at_the_end_go_to_a_named_fallback(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    real = cli_out.os.replace

    def failing(src, dst):
        if pathlib.Path(dst).name == "fit.json":
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(src, dst)

    monkeypatch.setattr(cli_out.os, "replace", failing)
    with OutputFolder(tmp_path / "out", "pamjax fit", ["fit.json"]) as folder:
        folder.write_text("fit.json", '{"values": [1.0]}')
        folder.write_text("model.json", "{}")
    rescued = list(tmp_path.glob("pamjax-rescued-fit-*-fit.json"))
    assert len(rescued) == 1 and rescued[0].read_text() == '{"values": [1.0]}'
    assert folder.failed and folder.failed[0][0] == "fit.json"
    assert (tmp_path / "out" / "model.json").exists() and not (tmp_path / "out" / "fit.json").exists()
    assert f"saved it as {rescued[0]}" in capsys.readouterr().out


# ---------------------------------------------------------------------------------------------------------------
# tracebacks on request


def test_debug_flag_and_environment_variable_show_the_traceback(tmp_path, capsys, no_solves, monkeypatch):
    config = _write(tmp_path, "[fit\n")
    with pytest.raises(pamjax.PamjaxInputError, match="not valid TOML"):
        main(["fit", str(config), "--debug"])
    monkeypatch.setenv("PAMJAX_DEBUG", "1")
    with pytest.raises(pamjax.PamjaxInputError, match="not valid TOML"):
        main(["fit", str(config)])
    monkeypatch.setenv("PAMJAX_DEBUG", "0")
    assert main(["fit", str(config)]) == 2


def test_an_internal_error_is_one_line_pointing_at_debug(tmp_path, capsys, monkeypatch, sweep_config):
    def broken(*args, **kwargs):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(cli_sweep, "steady_state_map", broken)
    err = _refused(capsys, ["sweep", str(sweep_config), "--out", str(tmp_path / "out"), "--cpu-devices", "1"],
                   r"error: ZeroDivisionError: float division by zero\n\(run again with --debug", code=1)
    assert err.count("\n") == 2


def test_the_process_is_set_up_for_the_commands_own_process_only(tmp_path, capsys, no_solves, monkeypatch):
    # `pamjax ...` as a program freezes what its imports made and collects young objects less often (tracing makes
    # millions of short-lived objects); `main(argv)` called from a user's program leaves their collector alone.
    import pamjax._cli.main as cli_main
    import pamjax._core.xla_cpu as xla_cpu

    calls = []

    class Recorder:
        def freeze(self):
            calls.append("freeze")

        def set_threshold(self, *thresholds):
            calls.append(thresholds)

    monkeypatch.setattr(cli_main, "gc", Recorder())
    # and XLA's classic CPU emitters (faster compilation) for every command but sweep (pamjax._core.xla_cpu)
    monkeypatch.setattr(xla_cpu, "prefer_fast_compilation", lambda: calls.append("fast compilation"))
    config = _write(tmp_path, "[fit\n")
    assert main(["fit", str(config)]) == 2
    assert calls == []
    monkeypatch.setattr(cli_main, "_end_process", lambda status: calls.append(("status", status)))
    monkeypatch.setattr(cli_main.sys, "argv", ["pamjax", "fit", str(config)])
    main()
    assert calls == ["freeze", (50_000, 20, 100), "fast compilation", ("status", 2)]
    calls.clear()
    sweep = _write(tmp_path, "[sweep\n", name="sweep.toml")
    monkeypatch.setattr(cli_main.sys, "argv", ["pamjax", "sweep", str(sweep)])
    main()
    assert calls == ["freeze", (50_000, 20, 100), ("status", 2)]  # batched lanes: XLA's default emitters


def test_the_common_flags_count_before_or_after_the_command(tmp_path, capsys, no_solves):
    # `pamjax --no-cache --debug --device gpu simulate x.toml` (where `pamjax --help` lists them) parsed to the
    # defaults: the subcommand's copies of the flags reset what was given before it (`pamjax --device tpu ...` ran on
    # the CPU). Given before or after the command they count; after it, it wins; a bad value is refused in both.
    from pamjax._cli.main import _parser

    parser, _ = _parser()
    for argv in (["--no-cache", "--debug", "--device", "gpu", "simulate", "x.toml"],
                 ["simulate", "--no-cache", "--debug", "--device", "gpu", "x.toml"],
                 ["--device", "tpu", "simulate", "--device", "gpu", "--no-cache", "--debug", "x.toml"]):
        args = parser.parse_args(argv)
        assert (args.no_cache, args.debug, args.device, args.config) == (True, True, "gpu", "x.toml"), argv
    args = parser.parse_args(["fit", "x.toml"])
    assert (args.no_cache, args.debug, args.device) == (False, False, "auto")
    for argv in (["--device", "xpu", "simulate", "x.toml"], ["simulate", "--device", "xpu", "x.toml"]):
        with pytest.raises(SystemExit) as exit_:
            parser.parse_args(argv)
        assert exit_.value.code == 2 and "argument --device: invalid choice: 'xpu'" in capsys.readouterr().err
    config = _write(tmp_path, "[fit\n")  # --debug before the command lets the traceback through
    with pytest.raises(pamjax.PamjaxInputError, match="not valid TOML"):
        main(["--debug", "fit", str(config)])


def test_a_simulate_step_budget_failure_names_the_config_key(tmp_path, capsys):
    # A run that outgrows its step budget was told "pass max_steps=16,384 ... (throw=False returns ...)": Python's
    # words (16,384 is no TOML number; throw is no key). `pamjax simulate` names its [simulate] keys, the number plain.
    config = _write(tmp_path, """
        [model]
        preset = "mas10_tank_system"
        options = { valve = "pwm" }
        [input]
        signal = { kind = "Constant", value = 0.5 }
        [simulate]
        t_end = 1.0
        max_steps = 100
    """)
    err = _refused(capsys, ["simulate", str(config), "--out", str(tmp_path / "out"), "--no-plot"],
                   r"the whole run needs about [\d,]+; set \[simulate\] max_steps = (\d+) or \[simulate\] stepping = "
                   r'"pwm" \(fixed RK4 steps', code=1)
    budget = re.search(r"max_steps = (\d+)", err)[1]
    assert tomllib.loads(f"max_steps = {budget}")["max_steps"] > 100
    assert "throw=False" not in err and "max_steps=" not in err.split("): ", 1)[1], err


def test_a_simulate_stepping_advice_can_be_followed(tmp_path, capsys):
    # The advice "use stepping='grid' (uniform fixed steps) or 'adaptive'" named a value [simulate] refused.
    text = """
        [model]
        preset = "mas10_tank_system"
        options = { valve = "averaged" }
        [input]
        signal = { kind = "Constant", value = 0.5 }
        [simulate]
        t_end = 0.05
        stepping = "pwm"
    """
    config = _write(tmp_path, text)
    _refused(capsys, ["simulate", str(config), "--out", str(tmp_path / "o1"), "--no-plot"],
             r"use stepping='grid'", code=2)
    _write(tmp_path, text.replace('"pwm"', '"grid"\n        grid_step = 0.002'))
    assert main(["simulate", str(config), "--out", str(tmp_path / "o2"), "--no-plot"]) == 0, capsys.readouterr().err
    assert (tmp_path / "o2" / "trajectory.csv").is_file()


@pytest.mark.parametrize("api, cli", [
    ("needs RK4 steps below 1e-05 s; pass substeps=1,024 or more, or use stepping='adaptive' with "
     "solver=pamjax.Rodas5() (implicit: not limited by stiffness). Pass throw=False to get the result with status "
     "instead.",
     'needs RK4 steps below 1e-05 s; set [simulate] substeps = 1024 or more, or use [simulate] stepping = "adaptive" '
     'with [simulate] solver = "Rodas5" (implicit: not limited by stiffness).'),
    ("makes it milder). Pass solver=pamjax.Rodas5() (implicit, L-stable). (throw=False returns the partial result "
     "with its status instead.)",
     'makes it milder). Set [simulate] solver = "Rodas5" (implicit, L-stable).'),
    ("became non-finite (parameters far outside the physical range?); simulate with throw=False and look at the "
     "trajectory up to that time. (throw=False returns the partial result with its status instead.)",
     "became non-finite (parameters far outside the physical range?)."),
    # [simulate] grid_step exists: its advice was left in Python's terms
    ("RK4 on a uniform grid of 0.002 s is unstable here: pass grid_step=0.0005 or less, or stepping='adaptive'",
     'RK4 on a uniform grid of 0.002 s is unstable here: set [simulate] grid_step = 0.0005 or less, or [simulate] '
     'stepping = "adaptive"'),
])
def test_a_simulate_failures_advice_is_in_the_configs_terms(api, cli):
    from pamjax._cli.main import _in_config_terms

    assert _in_config_terms("simulate", api) == cli
    assert _in_config_terms("fit", api) == api  # a fit's config has no such keys: the advice as it was


# ---------------------------------------------------------------------------------------------------------------
# sweep end to end (small)


def test_sweep_end_to_end_writes_outputs_and_refuses_to_overwrite(tmp_path, capsys):
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
    assert main(["sweep", str(config), "--out", str(out), "--cpu-devices", "1"]) == 0
    with np.load(out / "sweep.npz") as npz:  # closed: an open file warns in whichever test runs next
        data = dict(npz)
    np.testing.assert_array_equal(data["duty"], [0.2, 0.5, 0.8])
    assert np.all(data["status"] == 0)
    assert np.all(np.diff(data["pressure_pa_abs"]) > 0) and np.all(np.diff(data["position_m"]) > 0)
    assert (out / "sweep.csv").read_text().splitlines()[0] == "duty,pressure_pa_abs,position_m,status"
    assert len((out / "sweep.csv").read_text().splitlines()) == 4
    assert (out / "sweep.png").stat().st_size > 10_000
    before = (out / "sweep.npz").read_bytes()
    _refused(capsys, ["sweep", str(config), "--out", str(out)], "exists; pass --overwrite")
    assert (out / "sweep.npz").read_bytes() == before
    assert main(["sweep", str(config), "--out", str(out), "--overwrite", "--no-plot"]) == 0


def test_sweep_splits_the_cpu_into_one_device_per_core_and_matches_one_device(tmp_path, capsys):
    # `pamjax sweep` sets JAX's CPU device count before JAX runs (a fresh process, as from the shell) and shards the
    # sweep over the devices; the map equals the one-device map to 1e-12 relative (tests/test_sharding.py).
    import os
    import subprocess
    import sys

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
        proc = subprocess.run([sys.executable, "-m", "pamjax", "sweep", str(config), "--out", str(out), "--no-plot",
                               "--cpu-devices", str(n)], capture_output=True, text=True, timeout=600,
                              env={**os.environ, "JAX_PLATFORMS": "cpu"})
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert f"on {n} cpu device(s)" in proc.stdout, proc.stdout
        with np.load(out / "sweep.npz") as npz:
            runs[n] = dict(npz)
    for key in ("pressure_pa_abs", "position_m"):
        np.testing.assert_allclose(runs[2][key], runs[1][key], rtol=1e-12, atol=0)
    with pytest.raises(SystemExit):
        main(["sweep", str(config), "--cpu-devices", "0"])


def test_an_interrupt_inside_the_import_lock_waits_until_the_lock_is_free():
    # A SIGINT handled while the global import lock is held (e.g. in a weakref callback of the import machinery,
    # whose exception Python swallows) must not raise there: the lock would stay held for good and the next import of
    # another thread would wait forever (`pamjax fit` hung on SIGINT: its beside-import of the solver's module). The
    # handler sends the signal again once the lock is free, and the interrupt arrives then. In a fresh process: the
    # handler is the command's own, installed in the main thread.
    import subprocess
    import sys

    code = textwrap.dedent("""
        import _imp, os, signal, threading, time
        from pamjax._cli.main import _signals_as_interrupts
        raised_inside = later = False
        with _signals_as_interrupts():
            _imp.acquire_lock()
            try:
                try:
                    os.kill(os.getpid(), signal.SIGINT)
                    for _ in range(10000):
                        pass
                except KeyboardInterrupt:
                    raised_inside = True
            finally:
                _imp.release_lock()
            side = threading.Thread(target=__import__, args=("json",))  # another thread's import goes through
            side.start()
            side.join(5.0)
            try:
                time.sleep(5.0)
            except KeyboardInterrupt:
                later = True
        print(raised_inside, later, side.is_alive())
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.split() == ["False", "True", "False"], out.stdout + out.stderr


def test_a_regulator_models_sweep_takes_volts_and_names_its_range(tmp_path, capsys, no_solves):
    # `pamjax sweep` held every model's commands to duty ratios in [0, 1]: a regulator-fed model (0-10 V reference,
    # paper 001) could not be mapped at its own commands, though `pamjax.steady_state_map` takes them. Now they are
    # checked against the model's command range, which is also the default axis; columns and labels say volts.
    from pamjax._cli.kinds import VOLTAGE, command_of, commands

    model = pamjax.RegulatedMuscleSystem(pamjax.ISO6358Regulator(), presets.dmsp40_muscle(), load_force=893.0)
    pamjax.save_model(tmp_path / "reg.json", model)
    config = _write(tmp_path, 'kind = "steady_state"\n[model]\nfile = "reg.json"\n[sweep]\ncommands = [2.0, 8.0]\n')
    assert cli_sweep.prepare(tomllib.loads(config.read_text()), tmp_path) is not None  # no error: volts accepted
    assert command_of(model) is VOLTAGE
    np.testing.assert_allclose(commands({}, model, 11), np.linspace(0.0, 10.0, 11))  # the default: the range
    config.write_text(config.read_text().replace("[2.0, 8.0]", "[2.0, 12.0]"))
    _refused(capsys, ["sweep", str(config), "--out", str(tmp_path / "out"), "--cpu-devices", "1"],
             r"commands are reference voltages of the model's RegulatedMuscleSystem \[V\] in \[0, 10\], got 2 … 12")
    assert not (tmp_path / "out").exists()


def test_the_trajectory_csv_names_a_regulators_volts_and_every_channels_unit():
    # `pamjax simulate` wrote `command [1]` for a regulator's 0-10 V reference and `inlet_flow []` (no unit).
    import types

    from pamjax._cli.simulate import columns_of, command_unit

    model = pamjax.RegulatedMuscleSystem(pamjax.ISO6358Regulator(), presets.dmsp40_muscle(), load_force=893.0)
    assert command_unit(model) == "V" and command_unit(presets.mas10_system("averaged")) == "1"
    names = [*model.output_names, "command"]
    traj = types.SimpleNamespace(t=np.zeros(2), channels=lambda: names, channel=lambda c: np.zeros(2))
    cols, units = columns_of(traj, command_unit(model))
    assert units["command"] == "V" and units["inlet_flow"] == "kg/s"
    assert all(units[c] for c in cols), units


def test_an_earlier_runs_figure_alone_in_the_folder_is_refused_without_overwrite(tmp_path, capsys, no_solves):
    # `pamjax simulate --no-plot` into a folder holding only an earlier run's trajectory.png wrote its CSV beside it,
    # the figure reading as this run's; refused as an existing output is, and --overwrite removes it once written.
    out = tmp_path / "out"
    out.mkdir()
    (out / "trajectory.png").write_text("earlier")
    config = _write(tmp_path, _SIM_OK)
    _refused(capsys, ["simulate", str(config), "--out", str(out), "--no-plot"],
             r"trajectory.png exists, an earlier run's that this one would not replace; pass --overwrite")
    assert not (out / "trajectory.csv").exists() and (out / "trajectory.png").read_text() == "earlier"
    with OutputFolder(out, "pamjax simulate", ["trajectory.csv"], overwrite=True, stale=["trajectory.png"]) as folder:
        folder.write_text("trajectory.csv", "new")
    assert not (out / "trajectory.png").exists()
    (out / "fit.png").write_text("the resumed fit's")  # a resumed run (every output replaceable): its own files
    with OutputFolder(out, "pamjax fit", ["fit.json"], replaceable=["fit.json"], stale=["fit.png"]):
        pass


# ---------------------------------------------------------------------------------------------------------------
# the environment's settings, --out "", a checkpoint that cannot be written


@pytest.mark.parametrize("command", ["simulate", "sweep", "fit", "design"])
def test_an_empty_out_is_refused_by_every_command(tmp_path, capsys, no_solves, monkeypatch, command):
    # `--out "$DIR"` with DIR unset: simulate, sweep, fit and design wrote to results/... instead (demo refused it)
    monkeypatch.chdir(tmp_path)
    _refused(capsys, [command, str(tmp_path / "never-read.toml"), "--out", ""],
             rf"^pamjax {command}: error: the output folder is empty; name one with --out$")
    assert not any(tmp_path.iterdir())


def test_on_off_environment_variables_take_the_same_words_and_refuse_others(tmp_path, capsys, no_solves, monkeypatch):
    config = _write(tmp_path, "[fit\n")
    for word in ("false", "off", "no", "0", ""):  # PAMJAX_DEBUG=false showed the traceback
        monkeypatch.setenv("PAMJAX_DEBUG", word)
        _refused(capsys, ["fit", str(config)], "not valid TOML")
    monkeypatch.setenv("PAMJAX_DEBUG", "Yes")
    with pytest.raises(pamjax.PamjaxInputError, match="not valid TOML"):
        main(["fit", str(config)])
    monkeypatch.delenv("PAMJAX_DEBUG")
    for name in ("PAMJAX_DEBUG", "PAMJAX_COMPILATION_CACHE", "PAMJAX_FAST_COMPILE"):  # "disabled" was read as on
        monkeypatch.setenv(name, "disabled")
        _refused(capsys, ["fit", str(config)], rf"^pamjax fit: error: environment variable {name}='disabled': write "
                                               r"one of 1/true/yes/on \(on\) or 0/false/no/off \(off\), or unset it")
        monkeypatch.delenv(name)
    from pamjax._core.env import env_flag

    assert [env_flag("X", d, {"X": v}) for d, v in ((True, "OFF"), (False, " on "), (True, ""), (False, "1"))] == \
        [False, True, True, True]


@pytest.mark.parametrize("value", ["0.5s", "abc", "-1", "nan", "inf"])
def test_a_cache_minimum_that_is_not_a_number_of_seconds_is_named(tmp_path, capsys, no_solves, monkeypatch, value):
    # "0.5s" crashed every command with a ValueError traceback; "-1" and "nan" were taken silently
    monkeypatch.delenv("PAMJAX_COMPILATION_CACHE", raising=False)
    monkeypatch.setenv("PAMJAX_CACHE_MIN_COMPILE_SECONDS", value)
    _refused(capsys, ["fit", str(tmp_path / "never-read.toml")],
             rf"environment variable PAMJAX_CACHE_MIN_COMPILE_SECONDS='{re.escape(value)}': write a number of "
             r"seconds >= 0 \(e.g. 0.5, no unit\)")


def test_a_checkpoint_that_cannot_be_written_names_it_keeps_the_last_and_leaves_no_temporary(tmp_path, capsys,
                                                                                            monkeypatch):
    # a full disk during a fit: a bare "[Errno 28] No space left on device", and checkpoint.npz.tmp.npz left behind
    import pamjax._files.checkpoint as checkpoint

    path = tmp_path / "out" / "checkpoint.npz"
    checkpoint.write_checkpoint(path, ["a"], {"theta": np.ones(1)})
    before = path.read_bytes()
    real = np.savez

    def disk_full(file, *args, **kwargs):
        real(file, *args, **kwargs)  # written in part, then the disk is full
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(checkpoint.np, "savez", disk_full)
    with pytest.raises(OSError, match=r"could not write the fit's checkpoint .*checkpoint.npz \(No space left on "
                                      r"device\); the checkpoint already there .* is kept whole: make room .* resume "
                                      r"the fit from it \(pamjax fit --resume") as failed:
        checkpoint.write_checkpoint(path, ["a"], {"theta": np.zeros(1)})
    assert failed.value.errno == errno.ENOSPC and failed.value.filename == str(path)
    assert path.read_bytes() == before and [p.name for p in path.parent.iterdir()] == ["checkpoint.npz"]
    with pytest.raises(OSError, match="no earlier checkpoint is there to resume from"):
        checkpoint.write_checkpoint(tmp_path / "other" / "checkpoint.npz", ["a"], {"theta": np.zeros(1)})
    assert not any((tmp_path / "other").iterdir())
    # the command line says it in one line, naming the file once, status 1
    monkeypatch.setattr(cli_sweep, "run", lambda args: checkpoint.write_checkpoint(path, ["a"], {"theta": np.ones(1)}))
    err = _refused(capsys, ["sweep", "never-read.toml"], r"^pamjax sweep: error: could not write the fit's "
                                                          r"checkpoint .* resume=\.\.\.\)\)$", code=1)
    assert err.count(str(path)) == 1
