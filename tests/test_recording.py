"""Recordings: validation on load, CSV/NPZ round trips, zero-phase filtering and resampling."""

import numpy as np
import pytest

import pamjax
from pamjax import PamjaxInputError, Recording


def _rec(n=200, **kw):
    t = np.arange(n) / 100.0
    return Recording(t, dict(pressure=2e5 + 1e5 * np.sin(t), position=0.01 * t), name="r", **kw)


def test_round_trip_csv_and_npz_exact(tmp_path):
    rec = _rec()
    for suffix in ("csv", "npz"):
        path = rec.to_csv(tmp_path / "r.csv") if suffix == "csv" else rec.to_npz(tmp_path / "r.npz")
        back = Recording.load(path)
        np.testing.assert_array_equal(back.t, rec.t)
        for c in rec.channels:
            np.testing.assert_array_equal(back[c], rec[c])
            assert back.units[c] == rec.units[c]


def test_never_overwrites(tmp_path):
    rec = _rec()
    rec.to_npz(tmp_path / "r.npz")
    with pytest.raises(FileExistsError):
        rec.to_npz(tmp_path / "r.npz")
    rec.to_npz(tmp_path / "r.npz", overwrite=True)


def test_bad_time_and_lengths():
    with pytest.raises(PamjaxInputError, match="strictly increasing; t\\[2\\]"):
        Recording([0.0, 1.0, 1.0], dict(position=[0, 0, 0]))
    with pytest.raises(PamjaxInputError, match="channel 'position' has shape"):
        Recording([0.0, 1.0, 2.0], dict(position=[0, 0]))


def test_nan_names_channel_and_row_unless_masked():
    x = np.zeros(10)
    x[7] = np.nan
    with pytest.raises(PamjaxInputError, match="'position' is NaN/inf at row 7"):
        Recording(np.arange(10.0), dict(position=x))
    rec = Recording(np.arange(10.0), dict(position=x), mask_nan=True)
    assert not rec.mask["position"][7] and rec.mask["position"].sum() == 9


@pytest.mark.parametrize(
    "values, units, match",
    [(np.full(5, 6.0), None, "looks like bar"), (np.linspace(-1e4, 5e5, 5), None, "GAUGE"),
     (np.linspace(0.0, 5.5e5, 5), None, "GAUGE"),  # gauge in Pa: a vented start reads 0, not 101325
     (np.full(5, 6.0), {"pressure": "bar"}, "ABSOLUTE pressure in Pa")],
)
def test_pressure_must_be_absolute_pa(values, units, match):
    with pytest.raises(PamjaxInputError, match=match):
        Recording(np.arange(5.0), dict(pressure=values), units)


def test_absolute_pressures_from_atmosphere_up_are_accepted():
    rec = Recording(np.arange(5.0), dict(pressure=np.linspace(101325.0, 6.5e5, 5)))
    assert np.isclose(rec["pressure"][0], 101325.0)


def test_force_map_gauge_pressures_are_refused():
    from pamjax import ForceMapExperiment

    with pytest.raises(PamjaxInputError, match="gauge"):
        ForceMapExperiment(np.zeros(3), np.array([0.0, 3e5, 6e5]), np.array([0.0, 100.0, 200.0]))


def test_bench_file_names_are_mapped():
    from pamjax.gallery import bench_folder

    rec = Recording.load(bench_folder() / "E1_u0.25.npz")  # the recordings shipped with pamjax
    assert {"pressure", "position", "command"} <= set(rec.channels)


def test_filter_is_zero_phase_and_removes_noise():
    pytest.importorskip("scipy")
    fs = 1000.0
    t = np.arange(2000) / fs
    clean = 3e5 + 1e5 * np.sin(2 * np.pi * 1.0 * t)  # 1 Hz, far below the 20 Hz cut-off
    noisy = clean + 2e3 * np.random.default_rng(0).standard_normal(t.size)
    out = Recording(t, dict(pressure=noisy)).filtered(20.0)
    inner = slice(200, -200)  # away from the edges
    # zero phase: no lag, so the error is the residual noise only (white noise 2 kPa over 500 Hz → ~0.4 kPa at 20 Hz)
    assert np.sqrt(np.mean((out["pressure"][inner] - clean[inner]) ** 2)) < 600.0


def test_resample_decimates_recorded_samples():
    # Decimation keeps recorded samples at their own instants: no filter, no interpolation (a low-pass removes the
    # 50 Hz PWM ripple a switching model predicts and biased valve fits by ~11 %).
    rec = _rec(1001)  # 100 Hz
    low = rec.resampled(20.0)
    assert low.t[1] - low.t[0] == pytest.approx(0.05)
    idx = np.searchsorted(rec.t, low.t)
    np.testing.assert_array_equal(low.t, rec.t[idx])
    for c in rec.channels:
        np.testing.assert_array_equal(low[c], rec[c][idx])
    # a rate that does not divide the recording's: the nearest recorded samples, still measured values
    odd = rec.resampled(30.0)
    assert np.all(np.isin(odd.t, rec.t)) and np.max(np.abs(np.diff(odd.t) - 1 / 30.0)) <= 0.01 + 1e-12
    with pytest.raises(PamjaxInputError, match="exceeds the recording's own rate"):
        rec.resampled(200.0)


def test_filter_below_the_pwm_frequency_warns():
    pytest.importorskip("scipy")
    rec = _rec(1001)
    with pytest.warns(pamjax.PamjaxDataWarning, match="below the 50 Hz PWM frequency"):
        rec.filtered(20.0, pwm_frequency=50.0)
    out = rec.filtered(20.0)
    assert out.lowpass_hz == 20.0 and out.resampled(100.0).lowpass_hz == 20.0
    # an experiment with a switching valve warns about such a recording when it is checked
    system = pamjax.presets.mas10_tank_system("pwm")
    tank = Recording(rec.t, dict(pressure=np.full(rec.t.size, 101325.0)))
    with pytest.warns(pamjax.PamjaxDataWarning, match="low-pass filtered at 20 Hz"):
        pamjax.Experiment(tank.filtered(20.0), pamjax.Constant(0.5)).check(system)




def test_bad_rows_of_a_file_are_named_by_file_and_line(tmp_path):
    # Was: "Recording 'r': ... row 3" (0-based, no file). A CSV's line counts its header and comment lines; the NaN
    # advice names the Python call that has mask_nan; arrays keep their 0-based row and Recording(..., mask_nan=True).
    body = ["# exported", "t [s],position [m]", "0.0,0.0", "0.1,0.001", "0.2,nan", "0.3,0.003"]
    path = tmp_path / "r.csv"
    for lines, match in (
            (body, r"r\.csv, line 5: channel 'position' is NaN/inf at row 2 \(0-based data row; t = 0\.2 s\): clean "
                   r"or delete that line .*Recording\.load\(path, mask_nan=True\)"),
            (body[:4] + ["0.1,0.002"] + body[5:], r"r\.csv, line 5: t = 0\.1 s is not after the sample before it "
                                                  r"\(line 4: t = 0\.1 s\): t must be strictly increasing"),
            (body[:4] + [",0.002"] + body[5:], r"r\.csv, line 5: the time is nan .*t must be finite"),
            (body[:2], r"r\.csv: 0 data rows: a recording needs at least 2 samples")):
        path.write_text("\n".join(lines) + "\n")
        with pytest.raises(PamjaxInputError, match=match):
            Recording.load(path)
    np.savez(tmp_path / "r.npz", t=np.arange(4.0), x=np.array([0.0, 1e-3, np.inf, 0.0]))
    with pytest.raises(PamjaxInputError, match=r"r\.npz, sample 3: channel 'position' is NaN/inf"):
        Recording.load(tmp_path / "r.npz")
    with pytest.raises(PamjaxInputError, match=r"Recording 'a': channel 'position' is NaN/inf at row 1 .*"
                                               r"Recording\(\.\.\., mask_nan=True\)"):
        Recording(np.arange(3.0), dict(position=[0.0, np.nan, 0.0]), name="a")
    rec = Recording.load(tmp_path / "r.npz", mask_nan=True)
    assert rec.locate(2) == f"{tmp_path / 'r.npz'}, sample 3" and rec.columns == {"position": "x"}


def test_npz_and_mat_variables_that_are_no_channel_and_not_one_per_time_are_left_out(tmp_path):
    # A 5-value calibration table `temp` beside t, u, p, x (was: the file unreadable, "Recording 'r': channel 'temp'
    # has shape (5,), expected (200,)", no file named); a channel's array of another length is refused naming the file.
    scipy_io = pytest.importorskip("scipy.io")
    t = np.arange(200) / 100.0
    p, x = 2e5 + 1e3 * t, 0.01 * t
    np.savez(tmp_path / "r.npz", t=t, p=p, x=x, temp=np.full(5, 20.0))
    scipy_io.savemat(tmp_path / "r.mat", dict(t=t, p=p, x=x, temp=np.full(5, 20.0), fs=1000.0, rig="A"))
    for suffix in ("npz", "mat"):
        rec = Recording.load(tmp_path / f"r.{suffix}")
        assert sorted(rec.channels) == ["position", "pressure"], suffix
        np.testing.assert_array_equal(rec["pressure"], p)
        assert rec.ignored == {"temp": (None, "5 values, the time 200: not a channel")}
    np.savez(tmp_path / "short.npz", t=t, p=p[:-1], x=x)
    with pytest.raises(PamjaxInputError, match=r"short\.npz: 'p' \(channel 'pressure'\) has 199 values, the time 200"):
        Recording.load(tmp_path / "short.npz")
    with pytest.raises(PamjaxInputError, match=r"^Recording 'q': channel 'position' has shape \(2,\)"):
        Recording([0.0, 1.0, 2.0], dict(position=[0, 0]), name="q")


def test_a_unit_hint_for_a_file_without_header_says_where_its_units_go(tmp_path):
    # An NPZ's times in ms: the hint names the units table (meta.json's "units" in a bench folder), not a CSV header
    # the file does not have (was: "write 't [ms]' in the header").
    t = np.arange(200) * 1.0  # ms
    np.savez(tmp_path / "r.npz", t=t, x=0.01 * t / 1e3)
    with pytest.raises(PamjaxInputError, match=r"r\.npz: 't' is sampled every 1 s .*look like ms: give its unit, "
                                               r"\{\"t\": \"ms\"\}, in meta\.json's \"units\" .* units=") as err:
        Recording.load(tmp_path / "r.npz")
    assert "header to carry it" in str(err.value) and "in the header" not in str(err.value)
    assert Recording.load(tmp_path / "r.npz", units={"t": "ms"}).t[1] == pytest.approx(1e-3)
    with pytest.raises(PamjaxInputError, match=r"reaches 2 m; .*look like mm .*give its unit, "
                                               r"\{\"position\": \"mm\"\}, in Recording\(\.\.\., units=\.\.\.\)"):
        Recording(np.arange(60) / 100.0, dict(position=np.linspace(0, 2, 60)), name="r")


def test_units_as_text_channels_as_a_list_and_text_values_are_refused_by_name():
    # raw ValueError "dictionary update sequence element #0", TypeError "unhashable type", ValueError "could not
    # convert string to float"
    t, p = np.linspace(0.0, 1.0, 11), np.linspace(2e5, 6e5, 11)
    with pytest.raises(PamjaxInputError, match=r"units must be a dict channel → unit .* got 'bar abs'"):
        Recording(t, {"pressure": p}, units="bar abs")
    with pytest.raises(PamjaxInputError, match=r"channels must be a dict name → values .* got a list"):
        Recording(t, [p])
    with pytest.raises(PamjaxInputError, match=r"channel 'command' must hold numbers"):
        Recording(t, {"pressure": p, "command": ["on"] * 11})
    with pytest.raises(PamjaxInputError, match=r"t must hold numbers"):
        Recording(["a"] * 11, {"pressure": p})


def test_an_npz_channel_stored_as_a_column_vector_is_read_and_other_shapes_are_named(tmp_path):
    # p[:, None] (MATLAB's and pandas' habit) was dropped silently: not read, not in `ignored`, no error; a time so
    # stored gave "needs a time column 't'". A .mat file with the same shapes was read.
    t = np.arange(200) / 100.0
    p, x = 2e5 + 1e3 * t, 0.01 * t
    np.savez(tmp_path / "r.npz", t=t[:, None], p=p[:, None], x=x[None, :], gains=np.ones((2, 3)), fs=1000.0,
             notes=np.array(["valve A", None], dtype=object))
    rec = Recording.load(tmp_path / "r.npz")
    np.testing.assert_array_equal(rec["pressure"], p)
    np.testing.assert_array_equal(rec["position"], x)
    assert rec.ignored == {"gains": (None, "an array of shape (2, 3): not a channel"),
                           "fs": (None, "a single value (1000.0): not a channel"),
                           "notes": (None, "objects (text or mixed values): not a channel")}
    np.savez(tmp_path / "wide.npz", t=t, p=np.stack([p, p], axis=1), x=x)
    with pytest.raises(PamjaxInputError, match=r"wide\.npz: 'p' \(channel 'pressure'\) holds an array of shape "
                                               r"\(200, 2\): a channel is one number per time"):
        Recording.load(tmp_path / "wide.npz")


def test_to_npz_without_the_suffix_refuses_the_file_it_would_replace_and_returns_it(tmp_path):
    # np.savez adds ".npz": to_npz("run") checked "run", replaced an existing run.npz silently and returned "run"
    _rec().to_npz(tmp_path / "run.npz")
    with pytest.raises(FileExistsError, match=r"run\.npz exists"):
        _rec(50).to_npz(tmp_path / "run")
    assert len(Recording.load(tmp_path / "run.npz")) == 200
    out = _rec(50).to_npz(tmp_path / "run", overwrite=True)
    assert out == tmp_path / "run.npz" and len(Recording.load(out)) == 50
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.npz"]


def test_a_damaged_npz_or_mat_file_is_refused_naming_the_file(tmp_path):
    # each was a raw ValueError, JSONDecodeError, AttributeError, EOFError, BadZipFile or scipy MatReadError
    t, p = np.linspace(0.0, 1.0, 11), np.linspace(2e5, 6e5, 11)
    np.savez(tmp_path / "ok.npz", t=t, p=p)
    np.savez(tmp_path / "text.npz", t=t, p=p, __units__=np.array("pressure: Pa"))
    np.savez(tmp_path / "list.npz", t=t, p=p, __units__=np.array('["Pa"]'))
    (tmp_path / "csv.npz").write_text("t,p\n0,2e5\n1,3e5\n")
    (tmp_path / "empty.npz").write_bytes(b"")
    (tmp_path / "cut.npz").write_bytes((tmp_path / "ok.npz").read_bytes()[:300])
    (tmp_path / "cut.mat").write_text("hello")
    for name, match in (("text", r"text\.npz: its '__units__' is not what Recording\.to_npz writes"),
                        ("list", r"list\.npz: its '__units__' is not what Recording\.to_npz writes"),
                        ("csv", r"csv\.npz cannot be read as an \.npz archive"),
                        ("empty", r"empty\.npz cannot be read as an \.npz archive"),
                        ("cut", r"cut\.npz cannot be read as an \.npz archive")):
        with pytest.raises(PamjaxInputError, match=match):
            Recording.load(tmp_path / f"{name}.npz")
    pytest.importorskip("scipy.io")
    with pytest.raises(PamjaxInputError, match=r"cut\.mat cannot be read as a MATLAB \.mat file"):
        Recording.load(tmp_path / "cut.mat")
