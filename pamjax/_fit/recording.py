"""Recordings: measured (or synthetic) time series, named channels with units, read from and written to CSV/NPZ.

Validated on construction: a 1-D strictly increasing time, channels of the same length, no NaN (unless the user asks
to mask them), and pressure channels in ABSOLUTE pascal (a channel that looks like bar or gauge is refused).
Preprocessing as in paper 001: zero-phase low-pass filtering (2nd-order Butterworth, 20 Hz) and resampling. Those two
need SciPy (`pip install scipy`; in the test and bench extras); it is imported only when they are called.
"""

import json
import os
import pathlib
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .._core.csvio import read_table, write_table
from .._core.custom_types import RealScalarLike, TimesLike
from .._core.errors import PamjaxInputError
from .._core.paths import writable_path
from .._core.units import channel_dimension, to_si
from .recording_files import (
    DEFAULT_UNITS,
    add_default_units,
    checked_magnitude,
    mat_columns,
    npz_columns,
    renaming,
    sample_location,
    select_columns,
    unit_key,
    wanted,
)


def _scipy_signal():
    try:
        import scipy.signal
    except ModuleNotFoundError as err:  # pragma: no cover - depends on the environment
        raise ModuleNotFoundError(
            "filtering and resampling recordings needs SciPy: pip install scipy "
            "(in the pamjax[test] and [bench] extras)"
        ) from err
    return scipy.signal


class Recording:
    """Time series of named channels, SI units, ABSOLUTE pressures.

    **Arguments:**

    - `t`: times [s], 1-D, strictly increasing.
    - `channels`: dict name → 1-D array of `len(t)` (names as in `Trajectory`: pressure [Pa abs], position [m],
      velocity, force, mass_flow, command, ...).
    - `units`: dict name → unit string of the values given (defaults from `DEFAULT_UNITS`; `"t"` for the times).
      Other units are converted to SI (`"mm"`, `"ms"`, `"bar abs"`, `"kPa gauge"`, `"%"`, ...; `pamjax._core.units`);
      a unit that does not fit the channel, and a pressure unit other than Pa that does not say absolute or gauge,
      are refused.
    - `mask_nan`: False (default) raises on NaN naming channel and row; True keeps them and marks them in `mask`.
    - `name`: a label. `source`: where the data came from (a file), named in error messages (a bad row by its file
      line for a CSV, counting the header: `locate`).
    - `unit_checks`: True (default) refuses values whose magnitude betrays another unit (positions beyond 1 m:
      millimetres; samples 1 s or more apart: milliseconds; pressures below half an atmosphere: bar, gauge, ...),
      naming the likely unit. False skips these magnitude checks (never the unit conversions).
    - `atmosphere`: the ambient pressure [Pa abs] that gauge units (`barg`, `kPa gauge`, `psig`) are referred to;
      default the ISO 2533 standard atmosphere, 101325 Pa.

    `mask[name]` is a boolean array, True where the sample is valid. `units` holds the SI unit of each channel;
    `columns` the name of each channel's column in the file it was read from (`Recording.load`; else empty);
    `ignored` the file's columns `Recording.load` left out, column → (its unit as the file gives it, or None; why):
    those not among its `channels=`, and an NPZ/MAT variable that is no channel pamjax knows and is no series of one
    number per time (a scalar setting, a short table; in an NPZ file also a matrix, text or objects).
    """

    def __init__(self, t: TimesLike, channels: Mapping[str, TimesLike], units: Mapping[str, str] | None = None, *,
                 mask_nan: bool = False, name: str = "", source: str | os.PathLike | None = None,
                 unit_checks: bool = True, atmosphere: RealScalarLike | None = None):
        self.name = str(name)
        if atmosphere is not None and not (np.isfinite(atmosphere) and 5e4 <= float(atmosphere) <= 1.2e5):
            raise PamjaxInputError(f"Recording {self.name!r}: atmosphere must be the ambient pressure in Pa abs "
                                   f"(50-120 kPa), got {atmosphere!r}")
        if units is not None and not isinstance(units, Mapping):  # "bar abs": dict() raised a raw ValueError
            raise PamjaxInputError(f"Recording {self.name!r}: units must be a dict channel → unit (e.g. "
                                   f"{{'pressure': 'bar abs', 't': 'ms'}}), got {units!r}")
        if not isinstance(channels, Mapping):
            raise PamjaxInputError(f"Recording {self.name!r}: channels must be a dict name → values (e.g. "
                                   f"{{'pressure': p, 'position': x}}), got a {type(channels).__name__}")
        units = {} if units is None else dict(units)
        self.source = source
        self.columns = {}  # channel → its column's name in the file it was read from (`Recording.load`)
        self.ignored = {}  # the file's columns left out by `Recording.load`: column → (unit or None, why)
        where = str(source) if source is not None else f"Recording {self.name!r}"
        try:
            t = np.asarray(t, dtype=float)
        except (TypeError, ValueError) as err:
            raise PamjaxInputError(f"{where}: t must hold numbers, the times [s] ({err})") from None
        t, _ = to_si("t", units.pop("t", "s"), t, where)
        _check_times(t, source, self.name)
        if not channels:
            raise PamjaxInputError(f"Recording {self.name!r}: needs at least one channel besides t")
        unknown = set(units) - set(channels)
        if unknown:
            raise PamjaxInputError(f"{where}: units name {sorted(unknown)}, not channels of the recording "
                                   f"{sorted(channels)}: key units by channel name ('t' for the times)"
                                   + (" or by the file's column name" if source is not None else ""))
        if unit_checks:
            checked_magnitude("time", t, where, "t", source)
        self.unit_checks = bool(unit_checks)
        self.t = t
        self.channels = {}
        self.units = {}
        self.mask = {}
        for key, values in channels.items():
            try:
                v = np.asarray(values, dtype=float)
            except (TypeError, ValueError) as err:  # text, or rows of unequal lengths
                raise PamjaxInputError(f"{where}: channel {key!r} must hold numbers ({err})") from None
            if v.shape != t.shape:
                raise PamjaxInputError(f"{where}: channel {key!r} has shape {v.shape}, expected {t.shape} (same as t)")
            v, unit = to_si(key, units.get(key, DEFAULT_UNITS.get(key, "")), v, where, atmosphere)
            valid = np.isfinite(v)
            if not mask_nan and not np.all(valid):
                row = int(np.argmin(valid))
                if source is None:
                    raise PamjaxInputError(
                        f"Recording {self.name!r}: channel {key!r} is NaN/inf at row {row} (t = {t[row]} s); clean "
                        "the data or pass Recording(..., mask_nan=True) to leave such samples out of fits")
                raise PamjaxInputError(
                    f"{sample_location(source, self.name, row)}: channel {key!r} is NaN/inf at row {row} (0-based "
                    f"data row; t = {t[row]} s): clean or delete that line of the file (a Python script can instead "
                    "leave such samples out of its fit: Recording.load(path, mask_nan=True))")
            dimension = "pressure" if unit == "Pa" else channel_dimension(key)
            if dimension == "pressure" or unit_checks:
                checked_magnitude(dimension, v[valid], where, key, source)
            self.channels[key] = v
            self.units[key] = unit
            self.mask[key] = valid
        self.lowpass_hz = None  # the lowest low-pass cut-off [Hz] applied by `filtered`, if any

    def locate(self, row: int) -> str:
        """Where sample `row` (0-based) of this recording is: `<file>, line N` for a CSV (1-based, counting the header
        and comment lines), `<file>, sample N` (1-based) for other files, `Recording '<name>', row N` for arrays."""
        return sample_location(self.source, self.name, row)

    def __getitem__(self, key):
        if key == "t":
            return self.t
        if key not in self.channels:
            raise PamjaxInputError(f"Recording {self.name!r} has no channel {key!r}; it has {sorted(self.channels)}")
        return self.channels[key]

    def __len__(self):
        return self.t.size

    def __repr__(self):
        return f"Recording({self.name!r}, {len(self)} samples, {self.t[0]}..{self.t[-1]} s, {sorted(self.channels)})"

    @property
    def sample_rate(self):
        """Sampling rate [Hz] of a uniformly sampled recording (error otherwise)."""
        dt = np.diff(self.t)
        if np.ptp(dt) > 1e-6 * np.mean(dt):
            raise PamjaxInputError(f"Recording {self.name!r} is not uniformly sampled; resample it first")
        return 1.0 / float(np.mean(dt))

    def _replace(self, t, channels, filtered_at=None):
        out = Recording(t, channels, self.units, mask_nan=True, name=self.name, unit_checks=self.unit_checks)
        out.lowpass_hz = self.lowpass_hz if filtered_at is None else min(filtered_at, self.lowpass_hz or np.inf)
        return out

    def shifted(self, dt: RealScalarLike) -> "Recording":
        """The same samples with their times moved by `dt` [s] (a logger's clock put on the run's); its file and
        columns kept for messages."""
        out = self._replace(self.t + float(dt), dict(self.channels))
        out.source, out.columns, out.ignored = self.source, dict(self.columns), dict(self.ignored)
        return out

    # -- preprocessing ------------------------------------------------------------------------------------------
    def filtered(self, cutoff_hz: RealScalarLike = 20.0, order: int = 2, channels: Sequence[str] | None = None,
                 pwm_frequency: RealScalarLike | None = None) -> "Recording":
        """Zero-phase Butterworth low-pass (`scipy.signal.butter` + `filtfilt`) of `channels` (default: all but
        `command`); paper 001: 2nd order at 20 Hz (its valve is a proportional regulator).

        A switching valve's recordings carry a pressure ripple at the PWM frequency that a switching model predicts:
        a cut-off below it removes what the model computes, and a fit then biases the valve (a tank charge at
        50 Hz PWM: 10.8 kPa RMS against the true parameters filtered, 2.0 kPa raw). Pass `pwm_frequency` [Hz] to be
        warned here; an `Experiment` with a switching valve warns in any case (`lowpass_hz` records the cut-off).
        Fit switching-valve recordings raw, or decimated (`resampled`)."""
        sig = _scipy_signal()
        fs = self.sample_rate
        if not 0 < cutoff_hz < fs / 2:
            raise PamjaxInputError(f"cutoff_hz must be in (0, {fs / 2}) (Nyquist of this recording), got {cutoff_hz}")
        if pwm_frequency is not None and cutoff_hz < float(pwm_frequency):
            warn_filtered(self.name, cutoff_hz, float(pwm_frequency), stacklevel=3)
        b, a = sig.butter(int(order), cutoff_hz, fs=fs)
        names = [c for c in self.channels if c != "command"] if channels is None else list(channels)
        out = dict(self.channels)
        for c in names:
            self[c]  # unknown channel → error naming the valid ones
            if not np.all(self.mask[c]):
                raise PamjaxInputError(f"cannot filter channel {c!r}: it has masked (NaN) samples")
            out[c] = sig.filtfilt(b, a, self[c])
        return self._replace(self.t, out, filtered_at=float(cutoff_hz))

    def resampled(self, rate_hz: RealScalarLike) -> "Recording":
        """The recording at about `rate_hz` [Hz], by DECIMATION: the recorded samples nearest to a uniform grid of
        that rate, kept with their own times and values (no filter, no interpolation), so every value is one that
        was measured, at the instant it was measured, and a model sampled at those instants is compared like with
        like. When `rate_hz` divides the recording's rate the result is uniform (every k-th sample).

        (A low-pass before decimating, as for audio, removes the 50 Hz pressure ripple of a PWM valve that the
        switching model predicts, and biases a fit of its valve by ~11 %; see `filtered`.) Upsampling is refused:
        it would invent samples."""
        rate_hz = float(rate_hz)
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise PamjaxInputError(f"rate_hz must be > 0, got {rate_hz}")
        dt = np.diff(self.t)
        if rate_hz > 1.0 / float(np.min(dt)) * (1 + 1e-9):
            raise PamjaxInputError(
                f"Recording {self.name!r}: rate_hz = {rate_hz:g} Hz exceeds the recording's own rate "
                f"({1.0 / float(np.mean(dt)):g} Hz); resampling only decimates (it never invents samples)"
            )
        n = int(np.floor((self.t[-1] - self.t[0]) * rate_hz + 1e-9)) + 1
        grid = self.t[0] + np.arange(n) / rate_hz
        right = np.clip(np.searchsorted(self.t, grid), 1, len(self) - 1)
        nearest = np.where(np.abs(self.t[right - 1] - grid) <= np.abs(self.t[right] - grid), right - 1, right)
        idx = np.unique(nearest)
        return self._replace(self.t[idx], {c: v[idx] for c, v in self.channels.items()})

    def window(self, t_start: RealScalarLike | None = None, t_end: RealScalarLike | None = None) -> "Recording":
        """The samples with t_start ≤ t ≤ t_end."""
        lo = -np.inf if t_start is None else t_start
        hi = np.inf if t_end is None else t_end
        keep = (self.t >= lo) & (self.t <= hi)
        if np.count_nonzero(keep) < 2:
            raise PamjaxInputError(
                f"Recording {self.name!r}: window({t_start}, {t_end}) keeps {np.count_nonzero(keep)} samples; the "
                f"recording spans {self.t[0]}..{self.t[-1]} s"
            )
        return self._replace(self.t[keep], {c: v[keep] for c, v in self.channels.items()})

    # -- files --------------------------------------------------------------------------------------------------
    def to_csv(self, path: str | os.PathLike, overwrite: bool = False) -> pathlib.Path:
        """Write a `t [s],name [unit],...` CSV (pressures as `[Pa abs]`, floats exact); refuses to overwrite an
        existing file unless `overwrite=True`."""
        path = writable_path(path, overwrite)
        units = {"t": "s", **{c: "Pa abs" if u == "Pa" else u for c, u in self.units.items()}}
        comment = f"pamjax recording {self.name}; pressures absolute" if self.name else None
        return write_table(path, {"t": self.t, **self.channels}, units, comment)

    def to_npz(self, path: str | os.PathLike, overwrite: bool = False) -> pathlib.Path:
        """Write NPZ with arrays `t` and one per channel, units in `__units__` (JSON); `.npz` is added to a name
        without it, as `np.savez` does. Refuses to overwrite an existing file unless `overwrite=True`; returns the
        path written."""
        path = pathlib.Path(path)
        if path.suffix.lower() != ".npz":  # the file np.savez would write (checked, and returned, by that name)
            path = path.with_name(path.name + ".npz")
        path = writable_path(path, overwrite)
        meta = json.dumps(dict(units=self.units, name=self.name))
        with path.open("wb") as f:  # a file object: np.savez adds no suffix of its own
            np.savez(f, t=self.t, __units__=np.asarray(meta), **self.channels)
        return path

    @classmethod
    def from_csv(cls, path: str | os.PathLike, *, rename: Mapping[str, str] | None = None,
                 units: Mapping[str, str] | None = None, mask_nan: bool = False, name: str | None = None,
                 unit_checks: bool = True, atmosphere: RealScalarLike | None = None,
                 default_units: Mapping[str, str] | None = None,
                 channels: Sequence[str] | None = None) -> "Recording":
        """Read a CSV with a header row naming the columns, a time column `t` (or `time`) and one column per
        channel (a channel's name in any capitals: `Pressure [barg]`); `name [unit]` or `name (unit)` headers give
        units, converted to SI (`pamjax._core.csvio`, `_units`).
        Commas, semicolons or tabs; quoted headers; a UTF-8 byte-order mark; lines starting with '#' are comments.
        `units` (dict name → unit) overrides the header's; `default_units` (a bench's meta.json `units`) gives the
        units of columns whose header has none, and a header unit that differs from it is refused, naming both.
        Either is keyed by the file's column name, the channel's or a bench short name (`p`, `x`, `u`, `t`).
        `channels` (channel names, e.g. `("pressure", "position", "command")`; None: every column) reads the time
        and those channels only: another column is left unread, whatever it holds (text, empty cells, another
        quantity), and listed in `ignored`."""
        columns = read_table(path, keep=wanted(channels, rename))
        return cls._from_columns(pathlib.Path(path), [(n, v) for n, _, v in columns],
                                 {n: u for n, u, _ in columns if u is not None}, rename, units, mask_nan, name,
                                 unit_checks, atmosphere, default_units, channels)

    @classmethod
    def from_npz(cls, path: str | os.PathLike, *, rename: Mapping[str, str] | None = None,
                 units: Mapping[str, str] | None = None, mask_nan: bool = False, name: str | None = None,
                 unit_checks: bool = True, atmosphere: RealScalarLike | None = None,
                 default_units: Mapping[str, str] | None = None,
                 channels: Sequence[str] | None = None) -> "Recording":
        """Read an NPZ with a `t` array and one array per channel (the hybrid bench's short names t, u, p, x are
        renamed to command, pressure, position); `units`, `default_units` and `channels` as in `from_csv` (the
        file's own units: its `__units__`). A column or row vector ((n, 1), (1, n)) is read as the 1-D array it
        holds; an array that is no channel pamjax knows and is no series of one number per time (a scalar setting, a
        short table, a matrix, text or objects, which are never unpickled) is left out (`ignored`); a channel's is
        refused naming the file, as is a damaged file."""
        path = pathlib.Path(path)
        if not path.is_file():
            raise PamjaxInputError(f"recording file {path} does not exist")
        columns, meta = npz_columns(path)
        return cls._from_columns(
            path, columns, meta.get("units", {}), rename, units, mask_nan, name or meta.get("name"), unit_checks,
            atmosphere, default_units, channels
        )

    @classmethod
    def from_mat(cls, path: str | os.PathLike, *, rename: Mapping[str, str] | None = None,
                 units: Mapping[str, str] | None = None, mask_nan: bool = False, name: str | None = None,
                 unit_checks: bool = True, atmosphere: RealScalarLike | None = None,
                 default_units: Mapping[str, str] | None = None,
                 channels: Sequence[str] | None = None) -> "Recording":
        """Read a MATLAB `.mat` file (Simulink / dSPACE logs): every 1-D numeric variable is a column (a time
        variable `t` or `time`, channels by name or the bench short names t, u, p, x); MATLAB files carry no units,
        so `units` (dict name → unit, keyed by the variable's name or the channel's) says what is not SI (e.g.
        {"p": "barg", "x": "mm"}; `default_units` the same). A variable that is no channel pamjax knows and has not
        one value per time (a 5-sample calibration table) is left out (`ignored`), as are scalars and text;
        `channels` as in `from_csv`. v5-v7.2 files through `scipy.io.loadmat`, v7.3 (HDF5) through h5py
        (`pip install "pamjax[mat]"`)."""
        path = pathlib.Path(path)
        if not path.is_file():
            raise PamjaxInputError(f"recording file {path} does not exist")
        return cls._from_columns(path, mat_columns(path), {}, rename, units, mask_nan, name, unit_checks, atmosphere,
                                 default_units, channels)

    @classmethod
    def _from_columns(cls, path, columns, file_units, rename, units, mask_nan, name, unit_checks, atmosphere=None,
                      default_units=None, channels=None):
        """`columns`: list of (name in the file, 1-D array, or None for a column the CSV reader left unread). Bench
        short names (t, u, p, x, ...) and `rename` map file names to channel names; two columns that end up with one
        name are refused; the columns left out (`select_columns`) are listed in `ignored`."""
        if rename is not None and not isinstance(rename, dict):
            raise PamjaxInputError(f"rename must be a dict {{name in the file: channel name}}, got {rename!r}")
        user, names = dict(rename or {}), [n for n, _ in columns]
        rename = renaming(names, user, path)
        kept, ignored = select_columns(columns, rename, user, channels, file_units, path)
        left = {rename.get(k, k) for k in ignored}  # the channels those columns would have been
        data, u, source = {}, {}, {}
        for k, v in kept:
            new = rename.get(k, k)
            if new in data:
                raise PamjaxInputError(f"{path}: columns {source[new]!r} and {k!r} both become channel {new!r}; "
                                       "rename one (rename={...})")
            data[new], source[new] = v, k
            if k in file_units:
                u[new] = file_units[k]
        add_default_units(u, default_units, data, source, names, rename, path, atmosphere, left)
        given = {unit_key(k, names, rename): v for k, v in (units or {}).items()}
        u.update({c: v for c, v in given.items() if c not in left or c in data})  # the caller's: over the file's
        t = data.pop("t")
        out = cls(t, data, u, mask_nan=mask_nan, name=name or path.stem, source=path, unit_checks=unit_checks,
                  atmosphere=atmosphere)
        out.columns = {c: k for c, k in source.items() if c != "t"}
        out.ignored = ignored
        return out

    @classmethod
    def load(cls, path: str | os.PathLike, **kwargs: Any) -> "Recording":
        """`from_csv` or `from_npz` by file extension."""
        suffix = pathlib.Path(path).suffix.lower()
        if suffix == ".npz":
            return cls.from_npz(path, **kwargs)
        if suffix in (".csv", ".txt"):
            return cls.from_csv(path, **kwargs)
        if suffix == ".mat":
            return cls.from_mat(path, **kwargs)
        raise PamjaxInputError(f"recording file must be .csv, .npz or .mat, got {path}")


def _check_times(t, source, name):
    """A recording's times [s]: 1-D, at least 2, finite, strictly increasing; a mistake named by file and line where
    the recording was read from a file, by row (0-based) for arrays."""
    if t.ndim != 1 or t.size < 2:
        if source is not None and t.ndim == 1:
            raise PamjaxInputError(f"{source}: {t.size} data row{'' if t.size == 1 else 's'}: a recording needs at "
                                   "least 2 samples (rows below the header of a CSV)")
        raise PamjaxInputError(f"Recording {name!r}: t must be 1-D with at least 2 times, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        row = int(np.argmin(np.isfinite(t)))
        if source is None:
            raise PamjaxInputError(f"Recording {name!r}: t must be finite; row {row} is {t[row]}")
        raise PamjaxInputError(f"{sample_location(source, name, row)}: the time is {t[row]} (an empty or non-numeric "
                               "cell): t must be finite; fix or delete that line")
    if not np.all(np.diff(t) > 0):
        row = int(np.argmin(np.diff(t) > 0)) + 1
        if source is None:
            raise PamjaxInputError(f"Recording {name!r}: t must be strictly increasing; t[{row}] = {t[row]} <= "
                                   f"t[{row - 1}] = {t[row - 1]}")
        raise PamjaxInputError(f"{sample_location(source, name, row)}: t = {t[row]} s is not after the sample before "
                               f"it ({sample_location(source, name, row - 1).rsplit(', ', 1)[-1]}: t = {t[row - 1]} "
                               "s): t must be strictly increasing; delete a repeated row, sort rows out of order")


class PamjaxDataWarning(UserWarning):
    """Preprocessing that biases a fit (e.g. a low-pass below the PWM frequency of a switching valve)."""


def warn_filtered(name, cutoff_hz, pwm_frequency, stacklevel=2):
    import warnings

    warnings.warn(
        f"recording {name!r} was low-pass filtered at {cutoff_hz:g} Hz, below the {pwm_frequency:g} Hz PWM frequency "
        "of the switching valve it is compared with: the filter removes the pressure ripple the switching model "
        "predicts, and the fit will be biased (a tank charge at 50 Hz: 10.8 kPa RMS against the true parameters). "
        "Fit the raw or decimated recording (Recording.resampled), or use the averaged valve (eq. 13).",
        PamjaxDataWarning, stacklevel=stacklevel)
