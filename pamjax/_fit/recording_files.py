"""What `Recording.load` reads from a file, beside the `Recording` itself (`_fit/recording.py`): which columns are
read and what channel each becomes (bench short names, any capitals, `rename`), which are left out (`channels=`, an
NPZ/MAT variable that is no channel and has not one value per time), the units a bench's meta.json gives them, the
variables of a MATLAB file, where a sample lies in its file, and the magnitude checks' advice for files without a
header (NPZ, MAT: the unit goes in `units` / meta.json's "units", not in a header)."""

import json
import pathlib
import re
import zlib

import numpy as np

from .._core.errors import PamjaxInputError
from .._core.units import channel_dimension, check_magnitude, to_si
from .._files.fingerprint import UNREADABLE

# Default unit per well-known channel name.
DEFAULT_UNITS = dict(
    pressure="Pa", position="m", velocity="m/s", force="N", mass_flow="kg/s", command="1", volume="m^3"
)
# Short names used by bench files (the hybrid reference bench: t, u, p, x) → pamjax channel names.
BENCH_NAMES = dict(p="pressure", x="position", u="command", v="velocity", F="force", mdot="mass_flow",
                   duty="command")


_SPELLED = {**{c: c for c in DEFAULT_UNITS}, "duty": "command"}  # channels in any capitals: 'Pressure [barg]', 'Duty'


def renaming(names, user, path):
    """File column → channel name for the columns `names` of a file: bench short names, the caller's `rename`
    (`user`), channel names in any capitals, and `time` for the time where there is no `t`."""
    rename = {**BENCH_NAMES, **user}
    for n in names:
        known = _SPELLED.get(n.lower())
        if known is not None and n != known and n not in rename:
            rename[n] = known
    if "t" not in [rename.get(n, n) for n in names]:
        time = next((n for n in names if n.lower() == "time" and n not in rename), None)
        if time is None:
            raise PamjaxInputError(f"{path}: needs a time column 't' (or 'time'), has {names}")
        rename[time] = "t"
    unknown = set(rename) - set(BENCH_NAMES) - set(names)
    if unknown:
        raise PamjaxInputError(f"{path}: rename names {sorted(unknown)}, which are not columns of the file "
                               f"(columns: {names})")
    return rename


def _channel_list(channels):
    """`channels` of the readers checked: None, or a list of channel names."""
    if channels is not None and (isinstance(channels, str) or not all(isinstance(c, str) for c in channels)):
        raise PamjaxInputError(f"channels must be a list of channel names (e.g. [\"pressure\", \"position\"]), got "
                               f"{channels!r}")
    return None if channels is None else tuple(channels)


def wanted(channels, rename):
    """The CSV reader's `keep` for `channels` (None: every column): the time and those channels, by any name
    `renaming` turns into them (bench short names, `rename`, any capitals, `time`)."""
    channels = _channel_list(channels)
    if channels is None:
        return None
    chosen = {"t", *channels}
    names = {**BENCH_NAMES, **(rename if isinstance(rename, dict) else {})}
    return lambda name: (names.get(name) or _SPELLED.get(name.lower())
                         or ("t" if name.lower() == "time" else name)) in chosen


def select_columns(columns, rename, user, channels, file_units, path):
    """(the columns read: [(name, array)], those left out: {name: (unit or None, why)}). Left out: a column the CSV
    reader did not read or not among `channels`, and a variable of an NPZ/MAT file that is no channel pamjax knows
    and is no series of one number per time (a scalar setting, a short table, a matrix, text); a channel's, or a
    time that is no such series, is refused naming the file."""
    channels = _channel_list(channels)
    time, t = next((k, v) for k, v in columns if rename.get(k, k) == "t")
    why = _not_a_series(t)
    if why is not None:
        raise PamjaxInputError(f"{path}: the time {time!r} holds {why}: a time is one number per sample (a 1-D array, "
                               "or a column vector (n, 1))")
    size = np.size(t)
    kept, ignored = [], {}
    for k, v in columns:
        new = rename.get(k, k)
        named = channels is not None or k in user or channel_dimension(new) is not None  # a channel's, not metadata
        if new != "t" and (v is None or (channels is not None and new not in channels)):
            ignored[k] = (file_units.get(k), "not a channel read")
        elif new != "t" and (why := _not_a_series(v)) is not None:
            if named:
                raise PamjaxInputError(f"{path}: {k!r} (channel {new!r}) holds {why}: a channel is one number per "
                                       "time (a 1-D array, or a column vector (n, 1)); save it as one")
            ignored[k] = (file_units.get(k), f"{why}: not a channel")
        elif new != "t" and np.size(v) != size:
            if named:
                raise PamjaxInputError(f"{path}: {k!r} (channel {new!r}) has {np.size(v)} values, the time {size}: "
                                       "a channel needs one value per time (a truncated log?); cut both to one length")
            ignored[k] = (file_units.get(k), f"{np.size(v)} values, the time {size}: not a channel")
        else:
            kept.append((k, v))
    return kept, ignored


def _not_a_series(v):
    """Why the array `v` (of an NPZ file; a CSV's columns and a MAT file's vectors are series) is no 1-D series of
    numbers, or None where it is one."""
    a = np.asarray(v)
    if a.dtype.kind == "O":
        return "objects (text or mixed values)"
    if a.dtype.kind not in "fiub":
        return "text" if a.dtype.kind in "US" else f"{a.dtype} values"
    if a.ndim == 0:
        return f"a single value ({a.item()!r:.30})"
    return None if a.ndim == 1 else f"an array of shape {a.shape}"


def unit_key(key, names, rename):
    """The channel a `units` key names: a column of the file (by its name there: `Pressure`, `p`), `t` / `time`, a
    bench short name or a channel's name in any capitals; other keys are kept (and refused as naming no channel)."""
    if key in names:
        return rename.get(key, key)
    low = str(key).lower()
    if low in ("t", "time"):
        return "t"
    if key in BENCH_NAMES:
        return BENCH_NAMES[key]
    return "command" if low == "duty" else low if low in DEFAULT_UNITS else key


def add_default_units(u, default_units, data, source, names, rename, path, atmosphere, left=()):
    """`default_units` (a bench's meta.json `units`) into `u` (channel → unit) for the columns the file gives no unit;
    a unit the file gives that differs is refused naming both; a known channel the file lacks, or one of a column
    left out (`left`), is skipped."""
    for key, unit in (default_units or {}).items():
        channel = unit_key(key, names, rename)
        if channel not in data:
            if channel in DEFAULT_UNITS or channel in BENCH_NAMES.values() or channel in left:
                continue  # a bench-wide table: a channel this file does not record (or one not read)
            raise PamjaxInputError(f"{path}: meta.json 'units' (default_units) names {key!r}, neither a column of "
                                   f"the file {names} nor a channel; key units by column or channel name (t, p / "
                                   "pressure, x / position, u / duty)")
        if channel in u and not _same_unit(channel, u[channel], unit, path, atmosphere):
            raise PamjaxInputError(f"{path}: column {source[channel]!r} is in {u[channel]!r} by the file, but "
                                   f"meta.json 'units' (default_units) says {key!r} is in {unit!r}: one of them is "
                                   "wrong; keep one")
        u.setdefault(channel, str(unit))


def _same_unit(channel, a, b, where, atmosphere):
    """Whether units `a` and `b` of `channel` convert a value alike (`bar g` and `barg`; `Pa` and `Pa abs`)."""
    if str(a).strip() == str(b).strip():
        return True
    try:
        va, ua = to_si(channel, a, np.array([1.0, 3.0]), where, atmosphere)
        vb, ub = to_si(channel, b, np.array([1.0, 3.0]), where, atmosphere)
    except PamjaxInputError:
        return False
    return ua == ub and bool(np.allclose(va, vb, rtol=1e-12, atol=0.0))


def sample_location(source, name, row):
    """Where sample `row` (0-based) of a recording read from `source` (a file, or None) is (`Recording.locate`)."""
    if source is None:
        return f"Recording {name!r}, row {row}"
    path = pathlib.Path(source)
    line = _csv_line(path, row) if path.suffix.lower() in (".csv", ".txt") else None
    return f"{path}, line {line}" if line is not None else f"{path}, sample {row + 1}"


def _csv_line(path, row):
    """The 1-based line of a CSV file that holds its data row `row` (0-based), counted as `pamjax._core.csvio` reads
    the file (blank and '#' comment lines skipped, the first other line the header); None if it cannot be read."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    for encoding in ("utf-8-sig", "cp1252", "latin-1"):  # as the reader decodes it
        try:
            text = data.decode(encoding)
            break
        except UnicodeDecodeError:
            continue
    lines = [k + 1 for k, line in enumerate(text.splitlines()) if line.strip() and not line.lstrip().startswith("#")]
    return lines[row + 1] if 0 <= row < len(lines) - 1 else None


def npz_columns(path):
    """([(name, array)], the file's own units and name) of an .npz file (`np.savez`): its arrays, a column or row
    vector ((n, 1), (1, n): MATLAB's and pandas' habit) as the 1-D series it holds, like a .mat file's; an object array
    (text or mixed values, which NumPy reads only by unpickling: running code from the file) as an empty placeholder
    that `select_columns` leaves out by name. The units and name are those `Recording.to_npz` writes in `__units__`.
    A damaged file (cut short, empty, another format renamed .npz) is refused naming it."""
    with open(path, "rb") as file:  # opened here: np.load left its own file open when the archive was cut short
        try:
            archive = np.load(file, allow_pickle=False)
        except UNREADABLE as err:  # a CSV renamed: "pickled data" (ValueError); empty: EOFError; cut: BadZipFile
            raise PamjaxInputError(f"{path} cannot be read as an .npz archive (np.savez's format; an empty or "
                                   f"truncated copy, or another format renamed .npz?): {type(err).__name__}: "
                                   f"{err}") from None
        if not isinstance(archive, np.lib.npyio.NpzFile):
            raise PamjaxInputError(f"{path} is one NumPy array (an .npy file), not an .npz archive of named arrays: "
                                   "save the recording with np.savez(path, t=t, p=p, ...)")
        columns, units = [], None
        for k in archive.files:
            try:
                a = np.asarray(archive[k])
            except ValueError as err:
                if "allow_pickle" not in str(err):
                    raise PamjaxInputError(f"{path}: array {k!r} cannot be read (a damaged file?): {err}") from None
                a = np.empty((), dtype=object)  # an object array: not unpickled
            except UNREADABLE as err:
                raise PamjaxInputError(f"{path}: array {k!r} cannot be read (a damaged file?): "
                                       f"{type(err).__name__}: {err}") from None
            if k == "__units__":
                units = a
            else:
                columns.append((k, a.reshape(-1) if a.ndim == 2 and 1 in a.shape else a))
    return columns, _npz_meta(path, units)


def _npz_meta(path, units):
    """The units table and name of an NPZ file's `__units__` (JSON, as `Recording.to_npz` writes it), or {}."""
    if units is None:
        return {}
    try:
        meta = json.loads(str(units)) if units.dtype.kind in "US" and units.ndim == 0 else None
    except json.JSONDecodeError:
        meta = None
    if (not isinstance(meta, dict) or not isinstance(meta.get("units", {}), dict)
            or not all(isinstance(v, str) for v in meta.get("units", {}).values())):
        raise PamjaxInputError(f"{path}: its '__units__' is not what Recording.to_npz writes (JSON text {{\"units\": "
                               f"{{channel: unit}}, \"name\": ...}}), got {str(units)[:60]!r}; write that, or save the "
                               "file without it and give units=... (a bench folder: meta.json's \"units\")")
    return meta


def mat_columns(path):
    """[(name, 1-D float array)] of a .mat file's 1-D numeric variables (row or column vectors)."""
    try:
        import scipy.io
        from scipy.io.matlab import MatReadError
    except ModuleNotFoundError as err:  # pragma: no cover - depends on the environment
        raise ModuleNotFoundError('reading .mat recordings needs SciPy: pip install "pamjax[mat]"') from err
    try:
        raw = _mat_variables(path, scipy.io)
    except (MatReadError, *UNREADABLE, zlib.error) as err:  # not a .mat file, cut short, damaged
        raise PamjaxInputError(f"{path} cannot be read as a MATLAB .mat file (an empty or truncated copy, or another "
                               f"format renamed .mat?): {type(err).__name__}: {err}") from None
    columns = []
    for k, v in raw.items():
        if k.startswith("__"):
            continue
        a = np.asarray(v)
        if a.dtype.kind in "fiu" and a.ndim in (1, 2) and (a.ndim == 1 or 1 in a.shape) and a.size > 1:
            columns.append((k, a.reshape(-1).astype(float)))
    if not columns:
        raise PamjaxInputError(f"{path} holds no 1-D numeric variable (expected t and one vector per channel)")
    return columns


def _mat_variables(path, scipy_io):
    """name → value of a .mat file's variables: v5-v7.2 through `scipy.io.loadmat`, v7.3 (HDF5) through h5py."""
    try:
        return scipy_io.loadmat(str(path), squeeze_me=True)
    except NotImplementedError:  # MATLAB v7.3: an HDF5 file
        try:
            import h5py
        except ModuleNotFoundError as err:
            raise PamjaxInputError(f"{path} is a MATLAB v7.3 (HDF5) file: reading it needs h5py "
                                   '(pip install "pamjax[mat]"), or save it with -v7 in MATLAB') from err
        with h5py.File(path, "r") as f:
            return {k: np.asarray(f[k]) for k in f.keys() if isinstance(f[k], h5py.Dataset)}


# check_magnitude's advice for a CSV file: the unit written in its header
_HEADER_HINT = re.compile(r"write '([^']*) \[([^\]]*)\]' in the header"
                          r"|are these seconds written under a \[ms\] header\? \(write '([^']*) \[s\]'\)")


def checked_magnitude(dimension, values, where, name, source):
    """`check_magnitude`; for a recording without a header (an NPZ or MAT file, arrays) its advice to write the
    unit in the CSV header becomes to give it in `units` (a bench folder: meta.json's "units"; docs/fitting.md)."""
    try:
        check_magnitude(dimension, values, where, name)
    except PamjaxInputError as err:
        suffix = None if source is None else pathlib.Path(source).suffix.lower()
        if suffix in (".csv", ".txt"):
            raise
        place = ("Recording(..., units=...)" if source is None else
                 f"meta.json's \"units\" (a bench folder) or units=... (Recording.load): a {suffix} file has no "
                 "header to carry it")

        def hint(m):
            key, unit = (m[1], m[2]) if m[1] is not None else (m[3], "s")
            said = f'give its unit, {{"{key}": "{unit}"}}, in {place}'
            return said if m[1] is not None else f"are these seconds given as ms? ({said})"

        raise PamjaxInputError(_HEADER_HINT.sub(hint, str(err))) from None
