"""benchmarks/check.py's judgement (no benchmark run): RESULT lines read, noise bands from repeated runs, and a figure
that moved beyond its band flagged as worse or better in the right direction."""

import importlib.util
import pathlib

import pytest

_PATH = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "check.py"
_spec = importlib.util.spec_from_file_location("benchmarks_check", _PATH)
check = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(check)


def test_result_line_parsed_last_one_wins_booleans_as_numbers():
    text = "noise\nRESULT a=1 b=2\nmore\nRESULT sweep_avg_s=0.083 accuracy_matched=True devices=1 name=cpu\n"
    assert check.parse_result(text) == {"sweep_avg_s": 0.083, "accuracy_matched": 1.0, "devices": 1.0}
    assert check.parse_result("no result here") is None


def test_bands_from_repeated_runs_within_their_limits():
    relative = check._figure(check.LOWER)
    assert check.band_of(relative, [1.0, 1.01, 0.99]) == check.MIN_BAND  # quiet runs: the floor
    assert check.band_of(relative, [1.0, 1.2, 0.9]) == pytest.approx(0.4)  # twice the largest deviation (20 %)
    assert check.band_of(relative, [1.0, 3.0, 0.5]) == check.MAX_BAND
    counts = check._figure(check.LOWER, "absolute", 0.0)
    assert check.band_of(counts, [0.0, 0.0]) == 0.0 and check.band_of(counts, [2.0, 3.0, 2.0]) == 2.0


@pytest.mark.parametrize("better, value, moved, worse", [
    (check.LOWER, 0.16, True, True),     # a time 1.9x its reference (the slow RODAS stage loop): worse
    (check.LOWER, 0.095, False, False),  # within the band
    (check.LOWER, 0.05, True, False),    # faster: said, not a regression
    (check.HIGHER, 0.05, True, True),    # a speed-up ratio that fell
    (check.HIGHER, 0.16, True, False),
])
def test_a_figure_beyond_its_band_is_flagged_in_its_direction(better, value, moved, worse):
    ref = dict(value=0.083, band=0.3)
    assert check.compare(check._figure(better), value, ref)[:2] == (moved, worse)


def test_an_absolute_figure_is_judged_by_its_difference():
    spec = check._figure(check.LOWER, "absolute", 0.0)
    assert check.compare(spec, 1.0, dict(value=0.0, band=0.0))[:2] == (True, True)  # one silent wrong result
    assert check.compare(spec, 0.0, dict(value=0.0, band=0.0))[:2] == (False, False)


def test_every_check_names_its_script_and_figures():
    for name, (args, figures, timeout) in check.CHECKS.items():
        assert (check.ROOT / args[0]).is_file(), name
        assert figures and timeout > 0
        assert all(spec["better"] in (check.LOWER, check.HIGHER) for spec in figures.values())
