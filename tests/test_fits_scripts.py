"""The fit scripts and the `pamjax fit` config: bad config keys are named; the static-force fit on the real
DMSP-20-300 map reaches the authors' < 2.35 % maximum error; results are never overwritten silently."""

import subprocess
import sys
import textwrap

import pytest
from helpers import checkout_env

from pamjax import PamjaxInputError
from pamjax._cli.fit import load_config


def _write(tmp_path, text):
    path = tmp_path / "cfg.toml"
    path.write_text(textwrap.dedent(text))
    return path


def test_config_unknown_keys_list_valid_ones(tmp_path):
    with pytest.raises(PamjaxInputError, match=r"\[fit\]: unknown key\(s\) \['maxsteps'\]; valid keys are"):
        load_config(_write(tmp_path, """
            [fit]
            free = ["friction.coulomb_force"]
            maxsteps = 3
        """))
    with pytest.raises(PamjaxInputError, match="preset must be one of"):
        load_config(_write(tmp_path, """
            [model]
            preset = "nope"
            [fit]
            free = ["friction.coulomb_force"]
        """))


def test_example_config_loads():
    model, experiments, free, options, out = load_config("examples/fit_example.toml")
    assert [e.name for e in experiments] == ["triangle_025", "tank_charge_050"]
    assert float(model.muscle.volume_law.v0) == 3.0e-5  # the config's start value was applied


def test_static_force_script_matches_authors_max_error(tmp_path):
    out = subprocess.run([sys.executable, "fits/static_force.py", "--out", str(tmp_path)], capture_output=True,
                         text=True, check=True, env=checkout_env()).stdout
    line = next(ln for ln in out.splitlines() if ln.startswith("eq. 7"))
    max_percent = float(line.split("max error")[1].split("(")[1].split("%")[0])
    assert max_percent < 2.35, line
    again = subprocess.run([sys.executable, "fits/static_force.py", "--out", str(tmp_path)], capture_output=True,
                           text=True, env=checkout_env())
    assert again.returncode != 0 and "exists" in again.stderr


@pytest.mark.parametrize("script, result", [("derive_presets", "derived_presets.json"),
                                            ("friction_convergence", "friction_convergence.json"),
                                            ("ankle", "ankle.png"), ("control", "control.json"),
                                            ("joint_control", "joint_control.json")])
def test_scripts_refuse_to_replace_an_earlier_run_without_overwrite(tmp_path, script, result):
    # Was: a --quick or trial run silently replaced a full run's results (these scripts had no --overwrite).
    (tmp_path / result).write_text("an earlier run")
    run = subprocess.run([sys.executable, f"fits/{script}.py", "--out", str(tmp_path), "--quick"][
                         :5 if script == "friction_convergence" else 4], capture_output=True, text=True,
                         env=checkout_env(), timeout=120)
    assert run.returncode != 0 and f"{result} exist; pass --overwrite" in run.stderr, run.stderr
    assert (tmp_path / result).read_text() == "an earlier run"
