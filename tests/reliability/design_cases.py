"""Awkward inputs of `pamjax design` (issues 29 and 33), each run as a user would meet it and judged by what the user
gets: a design a bench can play, or one clear named error before any work, never a silent wrong result, never a
traceback, never an empty output folder.

Classes: "design limits" (a limit in the wrong unit, a run no limit can hold, the valve's thresholds, the muscle's
force), "design setup" (the PWM period, the run's length, the start signal, the noise, what a tank test can see),
"design outputs" (what is written and what is not). The format and the verdicts are those of `bad_inputs_cli.py`:
`name → (class, expect, run, name_in_message)` with `expect` "error" (`run(folder)` → (exit status, printed text);
"ok" when the status is non-zero, the text names `name_in_message` and holds no traceback) or "result" (`run(folder)`
→ True when the result is right).

Shared by `test_design_cases.py` and `benchmarks/reliability.py` (which counts every `*_cases.py` catalogue with
`bad_inputs_cli.py`'s in its `workflow_cases`).
"""

import pathlib
import tempfile

import numpy as np

import pamjax

from .bad_inputs_cli import cli

E, R = "error", "result"

TANK = """
[model]
preset = "mas10_tank_system"
options = {{ valve = "{valve}" }}
[design]
free = ["{free}"]
duration = {duration}
noise = {{ pressure = 2e3 }}
channels = ["pressure"]
start = {{ pressure = 101325.0 }}
rate = 500.0
knots = 4
initial = {initial}
steps = 1
{extra}
"""

MUSCLE = """
[model]
preset = "mas10_system"
options = {{ valve = "pwm" }}
[design]
free = {free}
duration = 0.4
noise = {{ pressure = 2e3, position = {position_noise} }}
rate = 500.0
knots = 4
steps = 1
{extra}
"""


def tank(folder, valve="pwm", free="valve.inflate.discharge_coefficient", duration=0.2, initial="0.6", extra=""):
    path = pathlib.Path(folder) / "design.toml"
    path.write_text(TANK.format(valve=valve, free=free, duration=duration, initial=initial, extra=extra))
    return path


def muscle(folder, free='["friction.coulomb_force", "muscle.force_law.k0"]', position_noise="1e-4", extra=""):
    path = pathlib.Path(folder) / "design.toml"
    path.write_text(MUSCLE.format(free=free, position_noise=position_noise, extra=extra))
    return path


def design(folder, config):
    return cli("design", config, "--out", pathlib.Path(folder) / "out", "--quiet", "--no-plot")


def refused_without_folder(folder, config, needle):
    """A refusal (status 2) naming `needle`, and no output folder left behind."""
    status, text = design(folder, config)
    return status == 2 and needle in text and not (pathlib.Path(folder) / "out").exists()


def averaged_with_period(folder):
    """The fix the averaged valve's refusal names (`period = 0.02` in [design]) designs, and the CSV runs to the end."""
    status, _ = design(folder, tank(folder, valve="averaged", free="valve.coefficients[1,0]", extra="period = 0.02"))
    if status != 0:
        return False
    rec = pamjax.Recording.load(pathlib.Path(folder) / "out" / "design.csv")
    return bool(np.isclose(rec.t[-1], 0.2) and rec.t.size == 11)


def infeasible_not_written(folder):
    """A design that ends outside its limits: status 1, the limit named, design.json written, no design.csv."""
    status, text = design(folder, tank(folder, extra="max_pressure = 1.2e5"))
    out = pathlib.Path(folder) / "out"
    return (status == 1 and "FAILED" in text and "max_pressure: predicted up to" in text
            and (out / "design.json").exists() and not (out / "design.csv").exists())


def kept_margin(folder, extra=""):
    """The design keeps every period 0.025 from the valve's 10 %/90 % thresholds (paper 000's valve), at the band's
    ends (the default band) or inside it (a band across them)."""
    status, _ = design(folder, tank(folder, extra=extra))
    if status != 0:
        return False
    duty = pamjax.Recording.load(pathlib.Path(folder) / "out" / "design.csv")["command"]
    return bool(np.all(np.minimum(np.abs(duty - 0.1), np.abs(duty - 0.9)) >= 0.025 - 1e-12))


CASES = {
    # limits a run cannot keep, or written in another unit: named before anything is solved
    "design max_pressure in bar": ("design limits", E, lambda d: design(d, tank(d, extra="max_pressure = 5.0")),
                                   "It is an ABSOLUTE pressure in Pa"),
    "design stroke_margin in mm": ("design limits", E, lambda d: design(d, muscle(d, extra="stroke_margin = 5.0")),
                                   "stroke_margin 5.0 m leaves no stroke"),
    "design min_force above the start's force": ("design limits", E, lambda d: design(
        d, muscle(d, extra="min_force = 200.0")), "eq. 7 gives 94.2 N at the run's start"),
    "design duty band across the valve's thresholds": ("design limits", R, lambda d: kept_margin(
        d, extra="duty_band = [0.0, 1.0]"), None),
    "design duty band inside the threshold margin": ("design limits", E, lambda d: design(
        d, tank(d, extra="duty_band = [0.09, 0.11]")), "no duty is left"),
    "design duty_margin out of range": ("design limits", E, lambda d: design(d, tank(d, extra="duty_margin = 0.7")),
                                        "duty_margin must be"),
    "design min_force true": ("design limits", E, lambda d: design(d, muscle(d, extra="min_force = true")),
                              "min_force must be a force"),
    "design infeasible after the search fails clearly": ("design outputs", R, infeasible_not_written, None),
    "design keeps the valve-threshold margin": ("design outputs", R, kept_margin, None),
    # the set-up of the run
    "design shorter than one PWM period": ("design setup", E, lambda d: design(d, tank(d, duration=0.01)),
                                           "shorter than one PWM period"),
    "design averaged valve without a period": ("design setup", E, lambda d: design(
        d, tank(d, valve="averaged", free="valve.coefficients[1,0]")), "`period = 0.02` in the [design] table"),
    "design averaged valve with the period it asks for": ("design setup", R, averaged_with_period, None),
    "design start duty above 1": ("design setup", E, lambda d: design(d, tank(d, initial="1.5")),
                                  "the start duty must lie in [0, 1]"),
    "design position noise in mm": ("design setup", E, lambda d: design(d, muscle(d, position_noise="0.1")),
                                    "the noise is a standard deviation in metres"),
    "design tank test asked about the muscle": ("design setup", E, lambda d: design(d, muscle(
        d, extra='channels = ["pressure"]\nstart = { pressure = 101325.0 }\ntank_volume = 5e-5')),
        "remove them from free"),
    "design refused config leaves no output folder": ("design outputs", R, lambda d: refused_without_folder(
        d, tank(d, duration=0.01), "shorter than one PWM period"), None),
}
SLOW = set()


def verdict(name):
    """Run case `name` in a fresh temporary folder: "ok", "silent_wrong", "traceback" or "unnamed", and the text."""
    _, expect, run, message = CASES[name]
    with tempfile.TemporaryDirectory() as d:
        try:
            got = run(d)
        except Exception as err:  # noqa: BLE001 - anything escaping is a traceback the user would see
            return "traceback", f"{type(err).__name__}: {err}"
    if expect == R:
        return ("ok" if got else "silent_wrong"), ""
    status, text = got
    if status is None or "Traceback" in text:
        return "traceback", text
    if status == 0:
        return "silent_wrong", text
    return ("ok" if message in text else "unnamed"), text


def summary(names=None, report=print):
    """Run the cases (all by default): counts {"ok", "silent_wrong", "lost_work", "traceback", "unnamed", "total"};
    reports every case that is not ok."""
    counts = dict(ok=0, silent_wrong=0, lost_work=0, traceback=0, unnamed=0)
    for name in sorted(CASES if names is None else names):
        result, text = verdict(name)
        counts[result] += 1
        if result != "ok":
            report(f"  {result}: [{CASES[name][0]}] {name}: {text.strip()[:300]}")
    counts["total"] = sum(counts.values())
    return counts
