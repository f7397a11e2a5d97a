"""The CSV reader (`pamjax._core.csvio`, behind `Recording.load`) and units (`pamjax._core.units`): whatever spreadsheet
or bench software wrote the file, the recording read is the same, or the reader refuses by file, line and column; header
units are converted to SI or refused, never ignored; values whose magnitude says another unit are refused with the
likely unit named."""

import numpy as np
import pytest

from pamjax import PamjaxInputError, Recording

T = np.round(np.arange(60) * 0.01, 10)  # s: 60 samples at 100 Hz (enough for the sampling-rate check)
P = 101325.0 + 1e3 * np.arange(60)  # Pa abs
X = 1e-4 * np.arange(60)  # m


def _write(tmp_path, text, name="r.csv", encoding="utf-8"):
    path = tmp_path / name
    path.write_bytes(text.encode(encoding))
    return path


def _table(delimiter=",", t=T, p=P, x=X, header=("t [s]", "pressure [Pa]", "position [m]"), fmt=repr, quote=False):
    head = [f'"{h}"' if quote else h for h in header]
    rows = [delimiter.join(head)] + [delimiter.join(fmt(float(v)) for v in row) for row in zip(t, p, x)]
    return "\n".join(rows) + "\n"


def _same_as_reference(rec):
    np.testing.assert_array_equal(rec.t, T)
    np.testing.assert_array_equal(rec["pressure"], P)
    np.testing.assert_array_equal(rec["position"], X)
    assert rec.units == {"pressure": "Pa", "position": "m"}


@pytest.mark.parametrize("variant", ["comma", "semicolon", "tab", "quoted header", "BOM", "Windows-1252 comment",
                                     "decimal comma", "CRLF", "trailing delimiter", "comment lines",
                                     "UTF-16 with BOM", "UTF-16 without BOM", "sep= line"])
def test_every_dialect_reads_the_same_recording(tmp_path, variant):
    text, encoding = _table(), "utf-8"
    if variant == "semicolon":
        text = _table(";")
    elif variant == "tab":
        text = _table("\t")
    elif variant == "quoted header":
        text = _table(quote=True)
    elif variant == "BOM":  # Excel's "CSV UTF-8": the header's first cell would otherwise read '\ufefft [s]'
        text = "\ufeff" + _table(quote=True)
    elif variant == "Windows-1252 comment":
        text, encoding = "# Prüfstand µC export, 23 °C\n" + _table(";"), "cp1252"
    elif variant == "decimal comma":  # European Excel: semicolons between cells, commas in numbers
        text = _table(";", fmt=lambda v: repr(v).replace(".", ","))
    elif variant == "CRLF":
        text = _table().replace("\n", "\r\n")
    elif variant == "trailing delimiter":
        text = "\n".join(line + "," for line in _table().splitlines()) + "\n"
    elif variant == "comment lines":
        lines = _table().splitlines()
        text = "# bench 3\n\n" + lines[0] + "\n# valve opened\n" + "\n".join(lines[1:]) + "\n"
    elif variant == "UTF-16 with BOM":  # Excel's "Unicode Text" (tab-separated): was a column-count refusal
        text, encoding = _table("\t"), "utf-16"
    elif variant == "UTF-16 without BOM":
        text, encoding = _table(";"), "utf-16-le"
    elif variant == "sep= line":  # Excel's delimiter directive: was read as a one-column header
        text = "sep=;\n" + _table(";", fmt=lambda v: repr(v).replace(".", ","))
    _same_as_reference(Recording.load(_write(tmp_path, text, encoding=encoding)))


def test_non_numeric_cell_names_file_line_and_column(tmp_path):
    lines = _table().splitlines()
    lines[5] = lines[5].replace(repr(float(P[4])), "1.0e5 kPa")
    path = _write(tmp_path, "\n".join(lines) + "\n")
    with pytest.raises(PamjaxInputError, match=r"r\.csv, line 6 \(data row 4\), column 2 \('pressure \[Pa\]'\): "
                                               r"'1.0e5 kPa' is not a number"):
        Recording.load(path)


def test_ragged_row_names_the_line(tmp_path):
    lines = _table().splitlines()
    lines[3] += ",7"
    with pytest.raises(PamjaxInputError, match=r"line 4 \(data row 2\): 4 columns, the header has 3"):
        Recording.load(_write(tmp_path, "\n".join(lines) + "\n"))


def test_duplicate_columns_are_refused_by_name(tmp_path):
    text = _table(header=("t [s]", "pressure [Pa]", "pressure [Pa]"), x=P)
    with pytest.raises(PamjaxInputError, match=r"columns 2 and 3 are both named 'pressure'"):
        Recording.load(_write(tmp_path, text))
    # a bench short name and its long form become one channel: refused too
    text = _table(header=("t [s]", "p [Pa]", "pressure [Pa]"), x=P)
    with pytest.raises(PamjaxInputError, match=r"columns 'p' and 'pressure' both become channel 'pressure'"):
        Recording.load(_write(tmp_path, text))


@pytest.mark.parametrize("index", ["", "Unnamed: 0", "index"])
def test_an_index_column_is_refused(tmp_path, index):
    lines = _table().splitlines()
    text = "\n".join([f"{index},{lines[0]}"] + [f"{k},{line}" for k, line in enumerate(lines[1:])]) + "\n"
    with pytest.raises(PamjaxInputError, match=r"column 1 .* looks like a row index.*index=False"):
        Recording.load(_write(tmp_path, text))


@pytest.mark.parametrize("header, values, expected", [
    ("t [ms]", T * 1e3, T),
    ("position [mm]", X * 1e3, X),
    ("position (mm)", X * 1e3, X),
    ("pressure [kPa abs]", P / 1e3, P),
    ("pressure [bar(a)]", P / 1e5, P),
    ("pressure [bar gauge]", (P - 101325.0) / 1e5, P),
    ("pressure [psig]", (P - 101325.0) / 6894.757293168, P),
    ("command [%]", np.linspace(0, 100, 60), np.linspace(0, 1, 60)),
])
def test_header_units_are_converted_to_si(tmp_path, header, values, expected):
    name = header.split()[0]
    cols = {"t": ("t [s]", T), "pressure": ("pressure [Pa]", P), "position": ("position [m]", X)}
    cols[name] = (header, values)
    text = "\n".join([",".join(h for h, _ in cols.values())]
                     + [",".join(repr(float(v)) for v in row) for row in zip(*(v for _, v in cols.values()))]) + "\n"
    rec = Recording.load(_write(tmp_path, text))
    got = rec.t if name == "t" else rec[name]
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("header, match", [
    ("pressure [bar]", r"'pressure' is in 'bar': say whether that is ABSOLUTE or GAUGE .*'pressure \[bar abs\]'"),
    ("pressure [kPa]", r"ABSOLUTE or GAUGE"),
    ("pressure [K]", r"not a pressure unit"),
    ("position [N]", r"'position' has unit 'N' \(a force unit\); a length channel takes one of"),
    ("position [furlong]", r"unit 'furlong' \(a unit pamjax does not know\)"),
])
def test_header_units_that_cannot_be_converted_are_refused(tmp_path, header, match):
    name = header.split()[0]
    header_row = ("t [s]", header, "position [m]" if name == "pressure" else "pressure [Pa]")
    text = _table(header=header_row, p=P if name == "pressure" else X, x=X if name == "pressure" else P)
    with pytest.raises(PamjaxInputError, match=match):
        Recording.load(_write(tmp_path, text))


@pytest.mark.parametrize("column, scale, match", [
    ("position", 1e3, r"channel 'position' reaches 5\.9 m; .*look like mm \(or cm\): write 'position \[mm\]'"),
    ("t", 1e3, r"'t' is sampled every 10 s .*look like ms: write 't \[ms\]'"),
    ("pressure", 1e-5, r"that looks like bar"),
    ("pressure", 1e-3, r"that looks like kPa"),
])
def test_magnitudes_that_betray_another_unit_are_refused(tmp_path, column, scale, match):
    t, p, x = T * (scale if column == "t" else 1), P * (scale if column == "pressure" else 1), X * (
        scale if column == "position" else 1)
    path = _write(tmp_path, _table(t=t, p=p, x=x))
    with pytest.raises(PamjaxInputError, match=match):
        Recording.load(path)
    if column != "pressure":  # the escape hatch for a recording that really is so (pressures are always checked)
        rec = Recording.load(path, unit_checks=False)
        np.testing.assert_array_equal(rec.t if column == "t" else rec[column], t if column == "t" else x)
    else:
        with pytest.raises(PamjaxInputError, match=match):
            Recording.load(path, unit_checks=False)


def test_unit_checks_false_keeps_the_values_and_survives_preprocessing(tmp_path):
    path = _write(tmp_path, _table(x=X * 1e3))
    rec = Recording.load(path, unit_checks=False)
    np.testing.assert_array_equal(rec["position"], X * 1e3)
    assert rec.window(0.0, 0.3)["position"].size == 31  # a derived recording is not re-refused


def test_python_api_units_convert_and_name_the_recording():
    rec = Recording(T, dict(position=X * 1e3), units=dict(position="mm", t="s"), name="bench")
    np.testing.assert_allclose(rec["position"], X, rtol=1e-15)
    with pytest.raises(PamjaxInputError, match=r"units name \['force'\], not channels"):
        Recording(T, dict(position=X), units=dict(force="N"))
    with pytest.raises(PamjaxInputError, match=r"Recording 'bench': channel 'pressure' .* looks like bar"):
        Recording(T, dict(pressure=P / 1e5), name="bench")


def test_a_missing_time_column_and_a_bad_rename_are_named(tmp_path):
    path = _write(tmp_path, _table(header=("seconds", "pressure [Pa]", "position [m]")))
    with pytest.raises(PamjaxInputError, match=r"needs a time column 't' \(or 'time'\), has \['seconds'"):
        Recording.load(path)
    rec = Recording.load(path, rename={"seconds": "t"})
    np.testing.assert_array_equal(rec.t, T)
    with pytest.raises(PamjaxInputError, match=r"rename names \['pressur'\], which are not columns"):
        Recording.load(path, rename={"seconds": "t", "pressur": "pressure"})
    time = _write(tmp_path, _table(header=("time [ms]", "pressure [Pa]", "position [m]"), t=T * 1e3), "time.csv")
    np.testing.assert_allclose(Recording.load(time).t, T, rtol=1e-12, atol=1e-15)


def test_channel_names_in_capitals_are_the_channels(tmp_path):
    # a logger's header 'Time [s],Pressure [Pa],POSITION [m]' (was: a channel 'Pressure' that a bench then missed)
    _same_as_reference(Recording.load(_write(tmp_path, _table(header=("Time [s]", "Pressure [Pa]", "POSITION [m]")))))
    duty = _write(tmp_path, _table(header=("t [s]", "Duty [-]", "position [m]"), p=np.full(60, 0.5)), "duty.csv")
    assert set(Recording.load(duty).channels) == {"command", "position"}
    both = _write(tmp_path, _table(header=("t [s]", "pressure [Pa]", "Pressure [Pa]"), x=P), "both.csv")
    with pytest.raises(PamjaxInputError, match=r"columns 'pressure' and 'Pressure' both become channel 'pressure'"):
        Recording.load(both)
    kept = Recording.load(_write(tmp_path, _table(header=("t [s]", "Pressure [Pa]", "x [m]")), "kept.csv"),
                          rename={"Pressure": "supply"})  # the user's rename decides
    assert set(kept.channels) == {"supply", "position"}


def test_written_csv_reads_back_exactly_with_units_in_the_header(tmp_path):
    rec = Recording(T, dict(pressure=P, position=X, command=np.full(60, 0.5)), name="r")
    path = rec.to_csv(tmp_path / "out.csv")
    header = next(line for line in path.read_text().splitlines() if not line.startswith("#"))
    assert header == "t [s],pressure [Pa abs],position [m],command [1]"
    back = Recording.load(path)
    for c in rec.channels:
        np.testing.assert_array_equal(back[c], rec[c])


def test_default_units_fill_the_columns_a_header_leaves_without(tmp_path):
    # A bench's meta.json "units" for a CSV headed 't,p,x' (was: ignored for CSV files); a header unit they
    # contradict is refused naming both, one they restate is accepted; a channel the file lacks is skipped.
    path = _write(tmp_path, _table(header=("t", "p", "x [mm]"), p=(P - 101325.0) / 1e5, x=X * 1e3))
    rec = Recording.load(path, default_units={"p": "barg", "x": "mm", "u": "%"})
    np.testing.assert_allclose(rec["pressure"], P, rtol=1e-12)
    np.testing.assert_allclose(rec["position"], X, rtol=1e-12, atol=1e-18)
    assert rec.units == {"pressure": "Pa", "position": "m"}
    with pytest.raises(PamjaxInputError, match=r"r\.csv: column 'x' is in 'mm' by the file, but meta\.json 'units' "
                                               r"\(default_units\) says 'position' is in 'm'"):
        Recording.load(path, default_units={"p": "barg", "position": "m"})
    with pytest.raises(PamjaxInputError, match=r"names 'pres', neither a column of the file"):
        Recording.load(path, default_units={"pres": "barg"})


def test_mat_units_keyed_by_the_files_variable_names(tmp_path):
    # A MATLAB file with variables Pressure / Position and units keyed the same (was: refused, "units name
    # ['Position', 'Pressure'], not channels", without saying how to key them).
    scipy_io = pytest.importorskip("scipy.io")
    scipy_io.savemat(tmp_path / "r.mat", dict(time=T, Pressure=(P - 101325.0) / 1e5, Position=X * 1e3))
    for units in ({"Pressure": "barg", "Position": "mm"}, {"p": "barg", "position": "mm"}):
        rec = Recording.load(tmp_path / "r.mat", units=units)
        np.testing.assert_allclose(rec["pressure"], P, rtol=1e-12)
        np.testing.assert_allclose(rec["position"], X, rtol=1e-12, atol=1e-18)
    with pytest.raises(PamjaxInputError, match=r"units name \['Presure'\], not channels .*key units by channel name "
                                               r"\('t' for the times\) or by the file's column name"):
        Recording.load(tmp_path / "r.mat", units={"Presure": "barg"})


def test_a_gauge_suffix_in_round_brackets_is_the_columns_unit(tmp_path):
    # `pressure (bar(g))`, the documented `name (unit)` form with the documented `(g)` suffix (was: the nested
    # brackets did not parse, and the column became a channel 'pressure (bar(g))' without a unit).
    from pamjax._core.csvio import split_header

    assert split_header("pressure (bar(g))") == ("pressure", "bar(g)")
    assert split_header("p (MPa (abs.))") == ("p", "MPa (abs.)")
    assert split_header("force (N)") == ("force", "N") and split_header("x") == ("x", None)
    path = _write(tmp_path, _table(header=("t (s)", "pressure (bar(g))", "position (m)"), p=(P - 101325.0) / 1e5))
    rec = Recording.load(path)
    assert sorted(rec.channels) == ["position", "pressure"]
    np.testing.assert_allclose(rec["pressure"], P, rtol=1e-12)


def test_columns_not_asked_for_are_left_unread_whatever_they_hold(tmp_path):
    # `read_table(keep=...)` and `Recording.load(channels=...)`: a column not asked for is not read (text, empty cells,
    # a differential pressure of 850 Pa that the pressure checks would refuse), and is listed in `ignored` with its
    # unit; the columns read keep every check.
    from pamjax._core.csvio import read_table

    rows = ["t [s],pressure [Pa],position [m],dp_filter [Pa],notes,status"]
    rows += [f"{float(t)!r},{float(p)!r},{float(x)!r},850,,{'FAULT' if k % 2 else 'OK'}"
             for k, (t, p, x) in enumerate(zip(T, P, X))]
    path = _write(tmp_path, "\n".join(rows) + "\n")
    with pytest.raises(PamjaxInputError, match=r"column 6 \('status'\): 'OK' is not a number"):
        read_table(path)
    columns = read_table(path, keep=lambda name: name in ("t", "pressure", "position"))
    assert [(n, u) for n, u, _ in columns] == [("t", "s"), ("pressure", "Pa"), ("position", "m"),
                                               ("dp_filter", "Pa"), ("notes", None), ("status", None)]
    assert [v is None for _, _, v in columns] == [False, False, False, True, True, True]
    rec = Recording.load(path, channels=["pressure", "position"])
    _same_as_reference(rec)
    assert rec.ignored == {"dp_filter": ("Pa", "not a channel read"), "notes": (None, "not a channel read"),
                           "status": (None, "not a channel read")}
    with pytest.raises(PamjaxInputError, match=r"'dp_filter' is 850 Pa at most"):  # asked for: checked
        Recording.load(path, channels=["pressure", "position", "dp_filter"])
    bad = _write(tmp_path, _table().replace(f",{float(P[3])!r},", ",nan,"), name="bad.csv")
    with pytest.raises(PamjaxInputError, match=r"bad\.csv, line 5: channel 'pressure' is NaN/inf"):
        Recording.load(bad, channels=["pressure"])
    with pytest.raises(PamjaxInputError, match="channels must be a list of channel names"):
        Recording.load(path, channels="pressure")
