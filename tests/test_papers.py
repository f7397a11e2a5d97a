"""The paper gallery (`fits/papers/`, `pamjax reproduce`): every equation, table, figure and stated result of both
papers is reproduced by a script or listed with the reason it cannot be; every script runs in quick mode and its key
numbers stay where they are (tolerances: a few times the run-to-run spread of the seeded noise, or the physics'
own margin, stated per number); the command writes its index page.

The scripts that need the hybrid bench recordings (shared/data, not in the repository) are skipped without them.
"""

import json

import pytest

from pamjax._cli import reproduce as _reproduce
from pamjax._cli.main import main

SCRIPTS = {p.stem: p for p in _reproduce.scripts()}
# p000_10_control scores the bench's E5 runs only when they are there
NEEDS_BENCH = {"p000_06_valve_tests", "p000_07_system_tests", "p000_08_pwm_frequency"}


def get(numbers, path):
    """`numbers[a][b]…` for the path "a/b/…" (or a tuple of keys, for keys that contain a slash)."""
    for key in (path.split("/") if isinstance(path, str) else path):
        numbers = numbers[int(key)] if isinstance(numbers, list) else numbers[key]
    return numbers


# script → [(path in Result.numbers, expected, absolute tolerance)] for `--quick` (seeded: deterministic up to
# floating-point and solver differences across platforms)
KEY_NUMBERS = {
    "p000_01_force_laws": [("eq4_max_relative_difference", 0.0, 1e-12),  # eq. 4 → eq. 5: an identity
                        ("braid_A/force_at_0_N", 90.0, 0.5),  # eq. 5 on the datasheet braid: far below 630 N
                        ("braid_B/zero_force_contraction", 0.384, 0.002),  # eq. 5 at 630 N: 38 % stroke, not 25 %
                        ("eq3_linearity/B/max_deviation_from_line_percent", 9.4, 0.3)],
    "p000_02_static_force": [("eq7_max_error_percent", 0.65, 0.1),  # real map; the authors' model: < 2.35 %
                          ("loop_coulomb_N", 16.0, 1.5),  # 3 standard errors
                          ("loop_width_mean_N", 34.5, 1.0)],  # 2 F_c + 2 C_f |ẋ|
    "p000_03_friction": [("muscle/coulomb_N", 16.0, 0.75), ("muscle/viscous_Ns_per_m", 250.0, 9.0)],  # 3 std errors
    "p000_04_flow_curves": [("fitted/inflate.discharge_coefficient", 0.36, 0.004),
                         ("fitted/inflate.critical_ratio", 0.28, 0.025),
                         ("fitted/exhaust.discharge_coefficient", 0.39, 0.003),
                         ("fitted/exhaust.critical_ratio", 0.49, 0.018),
                         ("eq10_inflate_rmse_percent_of_choked", 4.6, 0.5)],  # eq. 10 misfits path 1→2
    "p000_06_valve_tests": [("usable_duty/0", 0.10, 1e-6), ("usable_duty/1", 0.90, 1e-6),  # 2 ms at 50 Hz
                         ("max_rmse_kPa/switching", 2.0, 0.3),  # the bench's 2 kPa noise
                         ("max_rmse_kPa/averaged", 16.0, 2.0),
                         ("silencer_final_offset_deflation_kPa/0.25", 72.0, 5.0),
                         ("table_1_from_tanks/C_v(1→2)/fitted", 0.36, 0.004),  # Table 1 by the tank route
                         ("table_1_from_tanks/b_v(2→3)/fitted", 0.49, 0.04)],
    "p000_05_averaged_valve": [("cycle_average_fit/max_error_percent", 10.3, 0.5),  # paper: 4.13 %
                            ("cycle_average_fit/rmse_percent", 2.57, 0.2)],  # paper: 1.16 %
    "p000_07_system_tests": [("E4/switching/rmse_mm", 0.10, 0.02),  # the bench's 0.1 mm noise
                          ("E4/averaged/rmse_percent", 2.8, 0.4),  # paper: 3-5 %
                          ("E4/averaged/max_percent", 8.9, 1.0)],  # paper: ≈ 10 %
    "p000_08_pwm_frequency": [("50Hz/pressure_ripple_kPa/0", 50.0, 5.0),  # paper: ≈ 15 kPa amplitude
                           ("100Hz/usable_duty_steps", 60.0, 1e-9), ("25Hz/position_ripple_mm/0", 0.68, 0.1)],
    "p000_09_discrete": [("0.1ms/max_position_difference_mm", 0.0020, 0.0003),
                      ("0.5ms/max_position_difference_mm", 0.0101, 0.0015)],  # first order in T_s
    "p000_10_control": [(("PI (paper: P = 25, I = 150) @ 1.0 rad/s", "rmse_mm"), 0.356, 0.03),
                     (("PID, P = 100, D = 4 s/m @ 1.0 rad/s", "rmse_mm"), 0.289, 0.03),  # derivative helps…
                     (("PID, P = 100, D = 4 s/m, 0.1 mm noise @ 1.0 rad/s", "rmse_mm"), 12.7, 3.0)],  # …until noise
    "p000_11_hysteresis": [("loop/bouc_wen/rmse_N", 2.0, 0.15),  # the plant's model class: at the 2 N noise
                           ("loop/offset/rmse_N", 4.15, 0.4),  # eq. 8 misses the branch transitions
                           ("loop/bouc_wen/values/friction.coulomb_force", 17.0, 0.4),  # 3 standard errors
                           ("down_stroke/offset/down_over_up", 3.4, 0.5),  # the paper's "largest on the way down"
                           ("down_stroke/bouc_wen/down_rmse_mm", 0.0, 0.02)],  # a fraction of the 0.1 mm noise
    "p000_12_silencer": [("alone/z", 0.0, 3.0),  # K recovered within 3 standard errors (procedure check)
                         ("fig12_offset_kPa/identified/0.25", 92.0, 5.0),  # the offset Fig. 12 shows
                         ("flow_ratio/identified/6.50 bar", 0.945, 0.005)],  # "almost negligible" at 0.65 MPa
    "p001_05_tables": [("max_C_error_percent", 0.47, 0.2), ("max_b_error", 0.026, 0.01),
                    ("eq1_printed_max_jump_fraction", 0.134, 0.002),
                    ("charging_choked_flow_l_per_min_anr/5", 294.0, 1.0)],
    "p001_02_valve_model": [("eq5_7/bandwidth_Hz", 3.1404, 1e-3), ("eq5_7/flow_bandwidth_Hz", 3.1404, 1e-3),
                         ("eq5_7/flow_gain_bar_per_l_min", -0.922, 1e-6),
                         ("needed_for_3_69_Hz/both_time_constants_scaled_by", 0.851, 0.002),
                         ("g_vref_fit/validation_fit_percent", 98.9, 0.5), ("fig9/final_bar", -0.922, 1e-3)],
    "p001_01_muscle_flow": [("3V/peak_inflow_l_per_min_anr", 294.0, 2.0), ("3V/volume_term_share/rms", 0.333, 0.02),
                         ("3V/eq3_vs_delivered_max_relative", 0.0, 1e-9),
                         ("3V/inlet_outlet_difference", 0.211, 0.01),  # V_r from Fig. 6's 20 % (2 s; quick 4/3 s)
                         ("fig5_volume_law/slope_scale", 0.193, 0.01),  # the volume slope a 10 % share needs
                         ("fig11/mse_bar2/voltage_only", 2.33, 0.1)],  # printed eq. 6, no fit (paper: 0.1663)
    "p001_06_vppm_specs": [("hysteresis/loop_width_mbar_mean", 50.0, 1.0),  # PressureHysteresis keeps the 50 mbar
                        ("accuracy/worst_static_error_percent_of_full_scale", 0.69, 0.05),  # inside the 2 % band
                        ("modes/universal/t63_s", 0.068, 0.003)],  # eq. 6's step (τ 41 + 23 ms)
    "p001_03_stiffness": [("eq11_vs_delivered_max_relative", 0.0, 1e-9), ("correlation_eq10_eq11", 0.58, 0.05),
                       ("stiffness_eq9_range_N_per_m/1", 1.72e5, 4e3)],
    "p001_04_ankle": [("1.5Hz/rmse_deg", 6.9, 0.5)],
}
FAST = {"p000_01_force_laws", "p000_03_friction", "p000_09_discrete", "p000_10_control"}  # each ~10 s on 2 cores


def test_every_item_of_both_papers_is_covered():
    cover = _reproduce.coverage([_reproduce.load(p) for p in SCRIPTS.values()])
    missing = [(paper, item) for paper, items in cover.items() for item, (status, _) in items.items()
               if status == "missing"]
    assert not missing
    for paper, reasons in _reproduce.NOT_REPRODUCED.items():
        assert set(reasons) <= set(_reproduce.CATALOGUE[paper])
        assert all(cover[paper][item][0] == "not reproduced" for item in reasons)
    assert set(KEY_NUMBERS) == set(SCRIPTS), "every gallery script has its key numbers tested"


@pytest.mark.parametrize("name", [pytest.param(n, marks=() if n in FAST else pytest.mark.slow)
                                  for n in sorted(KEY_NUMBERS)])  # gallery order: later scripts reuse compilations
def test_script_runs_quick_and_keeps_its_key_numbers(name, tmp_path):
    if name in NEEDS_BENCH and _reproduce.bench_folder() is None:
        pytest.skip("hybrid bench recordings not on this machine")
    module = _reproduce.load(SCRIPTS[name])
    result, _ = _reproduce.run_script(module, tmp_path, quick=True)
    assert result.rows and all(r.paper and r.pamjax and r.reading for r in result.rows)
    record = json.loads((tmp_path / name / f"{name}.json").read_text())
    assert record["rows"] and record["covers"] == list(module.COVERS)
    for row in result.rows:
        assert not row.figure or (tmp_path / name / row.figure).exists()
    for path, expected, tol in KEY_NUMBERS[name]:
        value = get(record["numbers"], path)
        assert abs(value - expected) <= tol, f"{name}: {path} = {value}, expected {expected} ± {tol}"


def test_reproduce_command_writes_the_index(tmp_path, capsys):
    assert main(["reproduce", "paper000", "--quick", "--only", "p000_01_force_laws", "--out", str(tmp_path)]) == 0
    index = (tmp_path / "index.md").read_text()
    assert "| eq. 4 |" in index and "[force_laws.png](p000_01_force_laws/force_laws.png)" in index
    assert "| Fig. 1 | not reproduced | hardware only" in index  # coverage of the whole gallery, whatever ran
    assert (tmp_path / "p000_01_force_laws" / "p000_01_force_laws.json").exists()
    capsys.readouterr()
    assert main(["reproduce", "--only", "p999_nothing", "--out", str(tmp_path)]) == 2  # a user error: one line
    err = capsys.readouterr().err
    assert "unknown script(s) ['p999_nothing']" in err and "Traceback" not in err
