"""The config schema (`pamjax/_cli/schema.py`): one module declares every command's tables and keys with their kinds,
examples and units; a config is validated whole before anything is built or read, and every error names its key path.
The messages themselves: `test_cli.py`."""

import ast
import copy
import pathlib
import textwrap
import tomllib

import pytest

import pamjax
from pamjax._cli import schema
from pamjax._cli.main import main

ROOT = pathlib.Path(__file__).resolve().parents[1]

# The smallest valid config of each command (for a table's keys), and where its tables sit.
_FIT = {"fit": {"free": ["friction.coulomb_force"]}, "experiment": [{"file": "run.csv"}]}
_BASES = {
    ("fit", "[model]"): _FIT,
    ("fit", "[fit]"): _FIT,
    ("fit", "[[experiment]]"): {**_FIT, "rig": {}},  # the run conditions need a [rig]
    ("fit", "[rig]"): {**_FIT, "rig": {}},
    ("fit", "[bench]"): {"bench": {"dir": "bench"}},
    ("simulate", "[model]"): {"input": {"signal": {"kind": "Constant", "value": 0.5}}, "simulate": {"t_end": 1.0}},
    ("design", "[model]"): {"design": {"free": ["friction.coulomb_force"], "duration": 1.0,
                                       "noise": {"pressure": 2e3}}},
    ("sweep", "[model]"): {"kind": "steady_state", "model": {}},
}
_BASES[("simulate", "[input]")] = _BASES[("simulate", "[simulate]")] = _BASES[("simulate", "[model]")]
_BASES[("design", "[design]")] = _BASES[("design", "[model]")]


def _base(command, table, key):
    """(a valid config whose `table` will hold `key`, the dict to put it in, the label errors give it)."""
    if command == "sweep":  # a kind whose [system] or [sweep] uses the key
        name = table.strip("[]")
        if not name:  # the top level: kind
            return {"kind": "steady_state"}, None, ""
        uses = {"system": schema.SYSTEM_KEYS, "sweep": schema.SWEEP_KEYS}.get(name)
        kind = next(k for k in schema.SWEEP_KINDS if uses is None or key in uses[k])
        cfg = {"kind": kind, name: {}}
        return cfg, cfg[name], f"{table} "
    cfg = copy.deepcopy(_BASES[(command, table)])
    name = table.strip("[]")
    if name == "experiment":
        return cfg, cfg["experiment"][0], "[[experiment]] #1 "
    return cfg, cfg.setdefault(name, {}), f"{table} "


_KEYS = [(command, table, key) for command, tables in schema.TABLES.items() for table, keys in tables.items()
         for key in keys]


@pytest.mark.parametrize("command, table, key", _KEYS, ids=lambda x: str(x))
def test_every_keys_example_is_valid_and_a_wrong_value_names_the_key(command, table, key):
    spec = schema.TABLES[command][table][key]
    cfg, where, label = _base(command, table, key)
    where = cfg if where is None else where
    schema.validate(command, copy.deepcopy(cfg))  # the base is valid
    where[key] = tomllib.loads(f"v = {spec.example}")["v"]  # the example the errors show is a valid value
    schema.validate(command, copy.deepcopy(cfg))
    where[key] = []  # of no kind: an empty list is no number, string, table, boolean, signal, axis or free list
    with pytest.raises(pamjax.PamjaxInputError) as err:
        schema.validate(command, cfg)
    assert f"{label}{key}" in str(err.value), str(err.value)


def _write(folder, text, name="cfg.toml"):
    path = pathlib.Path(folder) / name
    path.write_text(textwrap.dedent(text))
    return path


# A model file that does not exist, and a mistake further down: the mistake is named (the whole config is checked
# before the model is built), and nothing is made.
WHOLE = {
    "fit": ("""
        [model]
        file = "missing/model.json"
        [fit]
        free = ["friction.coulomb_force"]
        [[experiment]]
        file = "a.csv"
        [[experiment]]
        file = "b.csv"
        scales = { pressure = "2 kPa" }
        """, r"[[experiment]] #2 scales.pressure must be a positive number"),
    "simulate": ("""
        [model]
        file = "missing/model.json"
        [input]
        signal = { kind = "Constant", value = 0.5 }
        [simulate]
        t_end = 1.0
        solver = "RK45"
        """, "[simulate] solver must be one of"),
    "sweep": ("""
        kind = "steady_state"
        [model]
        file = "missing/model.json"
        [sweep]
        horizon = "5 s"
        """, "[sweep] horizon must be a positive number"),
    "design": ("""
        [model]
        file = "missing/model.json"
        [design]
        free = ["friction.coulomb_force"]
        duration = 1.0
        noise = { pressure = 2e3 }
        min_force = true
        """, "[design] min_force must be a force"),
}


@pytest.mark.parametrize("command", sorted(WHOLE))
def test_the_whole_config_is_checked_before_the_model_is_built(tmp_path, capsys, command):
    text, message = WHOLE[command]
    config = _write(tmp_path, text)
    devices = ["--cpu-devices", "1"] if command == "sweep" else []
    argv = [command, str(config), "--out", str(tmp_path / "out"), *devices]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "does not exist" not in err, err
    assert not (tmp_path / "out").exists()
    # the same config without the mistake reaches the model: its file is named
    fixed = "\n".join(line for line in text.splitlines() if not any(
        k in line for k in ("scales", "solver", "horizon", "min_force")))
    _write(tmp_path, fixed)
    assert main(argv) == 2
    assert "missing/model.json does not exist" in capsys.readouterr().err.replace("\\", "/")


@pytest.mark.parametrize("key, value", [("supply_pressure", "6.5e5"), ("start", "{ pressure = 4e5 }"),
                                        ("sensors", '"left"')])
def test_a_run_condition_without_a_rig_is_refused_not_ignored(key, value):
    # [[experiment]] supply_pressure, start and sensors act only through a pamjax.Rig ([rig]); without one they once
    # changed nothing, silently
    cfg = tomllib.loads(f'[fit]\nfree = ["volume"]\n[[experiment]]\nfile = "run.csv"\n{key} = {value}\n')
    with pytest.raises(pamjax.PamjaxInputError, match=rf"\[\[experiment\]\] #1 {key} is a run condition of a rig, "
                                                      r"which only a \[rig\] table applies"):
        schema.validate("fit", cfg)
    schema.validate("fit", {**cfg, "rig": {}})


def test_a_signal_without_a_field_it_needs_is_named():
    cfg = tomllib.loads('[input]\nsignal = { kind = "Constant" }\n[simulate]\nt_end = 1.0\n')
    with pytest.raises(pamjax.PamjaxInputError, match=r"\[input\] signal \(kind = 'Constant'\) needs \['value'\]"):
        schema.validate("simulate", cfg)


def test_every_example_config_is_valid():
    for path in sorted((ROOT / "examples").glob("*.toml")):
        cfg = tomllib.loads(path.read_text())
        command = ("sweep" if "kind" in cfg else "design" if "design" in cfg else
                   "simulate" if "input" in cfg else "fit")
        schema.validate(command, cfg, str(path))


def test_no_private_name_crosses_a_module_boundary_in_the_command_line():
    # the CLI uses the public names of pamjax's modules (and of its own): `split_path`, not `_parse`
    crossing = []
    for path in sorted((ROOT / "pamjax" / "_cli").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").startswith("pamjax")):
                crossing += [f"{path.name}:{node.lineno} {a.name}" for a in node.names if a.name.startswith("_")]
    assert not crossing, crossing


def test_describe_lists_every_key_with_its_kind_and_example():
    text = schema.describe("fit")
    assert "[[experiment]] supply_pressure: positive number, e.g. 6.5e5 (Pa abs)" in text
    assert "[rig] free: list of strings" in text
    assert len(text.splitlines()) == sum(len(keys) for keys in schema.TABLES["fit"].values())
    assert schema.describe("sweep").startswith("kind: string (one of steady_state, flow_surface, frequency_response)")


def test_a_design_names_the_prior_config_its_error_comes_from(tmp_path, capsys):
    _write(tmp_path, '[fit]\nfree = ["volume"]\nmax_step = 3\n[[experiment]]\nfile = "a.csv"\n', "prior.toml")
    config = _write(tmp_path, """
        [design]
        free = ["friction.coulomb_force"]
        duration = 1.0
        noise = { pressure = 2e3 }
        prior = "prior.toml"
        """)
    assert main(["design", str(config), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "[design] prior = 'prior.toml': [fit]: unknown key(s) ['max_step']" in err, err


def test_simulate_takes_every_stepping_pamjax_simulate_takes():
    # Was: ['adaptive', 'pwm'] only, while simulate's own advice says "use stepping='grid'" or "stepping='auto'".
    import typing

    from pamjax._solve.simulate import Stepping

    assert set(schema.SIMULATE["stepping"].choices) == set(typing.get_args(Stepping))
    base = '[input]\nsignal = { kind = "Constant", value = 0.5 }\n[simulate]\nt_end = 1.0\n'
    for stepping in typing.get_args(Stepping):
        schema.validate("simulate", tomllib.loads(base + f'stepping = "{stepping}"\ngrid_step = 5e-4\n'))
