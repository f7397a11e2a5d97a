"""Free parameters of a fit: paths into a model, and the map from an unconstrained, O(1)-scaled vector θ to them.

How each parameter is transformed and reported is declared by its component, in the field's metadata
(`pamjax._core.fitting`): positive quantities in log space (v = v₀ eᶿ: a trial value is never ≤ 0), bounded ones
(ratios in (0, 1)) through a logistic, a polynomial's coefficients as its values at Chebyshev nodes over the domain
an enclosing component names, labelled as the component says; anything else linearly, scaled by its start
magnitude. This module knows no component.
"""

import dataclasses
import re
from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import device_array
from .._core.errors import PamjaxInputError
from .._core.fitting import TRANSFORMS


class PamjaxIdentifiabilityWarning(UserWarning):
    """Some free parameters (or combinations of them) are not determined by the data."""


class Key(str):
    """A step of a parameter path into a dict (an experiment's run conditions: `runs[E1_u0.25].supply_pressure`)."""

    __slots__ = ()


_SEGMENT = re.compile(r"\s*([A-Za-z_]\w*)\s*((?:\[[^\]]*\]\s*)*)")
_BRACKET = re.compile(r"\[([^\]]*)\]")
_INDEX = re.compile(r"^\s*\d+(?:\s*,\s*\d+)*\s*$")


def _parse(path):
    """(steps, index) of a parameter path: steps are attribute names (str) and dict keys (`Key`, written
    `name[key]`, the key optionally quoted, which it must be when it looks like a number); `index` is a final array
    index such as `[2]` or `[1,0]` (None when the path names the whole leaf)."""
    malformed = PamjaxInputError(f"parameter path {path!r} is malformed (expected e.g. 'valve.inflate.area', "
                                 "'muscle.force_law.max_force_coefficients[2]' or 'runs[E4].supply_pressure')")
    if not isinstance(path, str):
        raise PamjaxInputError(f"a parameter path must be a string, got {path!r}")
    steps, index, pos = [], None, 0
    while True:
        m = _SEGMENT.match(path, pos)
        if m is None or index is not None:
            raise malformed
        steps.append(m.group(1))
        brackets = _BRACKET.findall(m.group(2))
        for j, inner in enumerate(brackets):
            if _INDEX.match(inner):  # an array index: the path's last element
                if j != len(brackets) - 1:
                    raise malformed
                index = tuple(int(k) for k in inner.split(","))
            else:
                key = inner.strip()
                if len(key) >= 2 and key[0] == key[-1] and key[0] in "'\"":
                    key = key[1:-1]
                if not key:
                    raise malformed
                steps.append(Key(key))
        pos = m.end()
        if pos == len(path):
            return steps, index
        if path[pos] != ".":
            raise malformed
        pos += 1
        if index is not None:
            raise malformed


def _key_text(key):
    return f"['{key}']" if _INDEX.match(key) else f"[{key}]"


def join_path(steps):
    """The path string of parse steps (the inverse of `_parse` without an index)."""
    out = ""
    for s in steps:
        out += _key_text(s) if isinstance(s, Key) else (f".{s}" if out else s)
    return out


def split_path(path):
    """(steps, index) of a parameter path such as 'valve.coefficients[1,0]' or 'runs[E4].supply_pressure': the
    attribute names and dict keys (`Key`) it walks, and its final array index (None for the whole leaf); a
    malformed path is a `PamjaxInputError`. `join_path(steps)` writes the leaf's path back."""
    return _parse(path)


def parameter_paths(model: eqx.Module, prefix: str = "") -> dict[str, tuple[int, ...]]:
    """All array-valued parameter paths of `model` with their shapes, e.g. {'valve.inflate.area': ()}; dict fields
    (a `Rig`'s run conditions) give `name[key].…` paths. `prefix` is written before every path (e.g. "plant.").
    Anything but a model (an equinox Module) is refused: a number or None gave {} without a word."""
    if not isinstance(model, eqx.Module | dict):
        raise PamjaxInputError(f"parameter_paths: model must be a pamjax model (a system or component), got "
                               f"{type(model).__name__}")
    return _paths(model, prefix)


def _paths(node, prefix):
    """`parameter_paths` of any node of a model: a Module, a dict, an array (anything else has none)."""
    out = {}
    if isinstance(node, eqx.Module):
        for f in dataclasses.fields(node):
            if f.metadata.get("static", False):
                continue
            out.update(_paths(getattr(node, f.name), f"{prefix}{f.name}."))
    elif isinstance(node, dict):
        for key, value in node.items():
            out.update(_paths(value, f"{prefix[:-1]}{_key_text(str(key))}."))
    elif eqx.is_array(node):
        out[prefix[:-1]] = tuple(node.shape)
    return out


def getter(attrs):
    """The function model → the value at the parse steps `attrs` (attribute names and dict `Key`s, as `split_path`
    gives them)."""

    def get(m):
        for a in attrs:
            m = m[a] if isinstance(a, Key) else getattr(m, a)
        return m

    return get


class _Group(eqx.Module):
    """One free entry: an array leaf (or some of its elements) and how it maps from the unconstrained θ."""

    path: str = eqx.field(static=True)
    attrs: tuple = eqx.field(static=True)
    index: tuple | None = eqx.field(static=True)
    transform: str = eqx.field(static=True)
    labels: tuple = eqx.field(static=True)
    scale: jax.Array  # linear: value = scale θ; log: value = scale exp(θ); nodes: F(nodes) = scale θ
    lower: jax.Array
    upper: jax.Array
    basis: jax.Array | None  # nodes: coefficients = basis @ F(nodes)

    @property
    def size(self):
        return len(self.labels)

    def physical(self, theta):
        if self.transform == "linear":
            return self.scale * theta
        if self.transform == "log":
            return self.scale * jnp.exp(theta)
        if self.transform == "logistic":  # within the open range: the sigmoid is 1.0 exactly from θ ≈ 37 on
            lo, hi = jnp.asarray(self.lower, dtype=float), jnp.asarray(self.upper, dtype=float)
            return jnp.clip(lo + (hi - lo) * jax.nn.sigmoid(theta), jnp.nextafter(lo, hi), jnp.nextafter(hi, lo))
        return self.basis @ (self.scale * theta)  # nodes

    def at_bound(self, theta):
        """Per entry: whether θ sits at a bound of its range (logistic within ~3e-7 of an end; log below 1e-6 of the
        start magnitude, i.e. pushed towards 0)."""
        theta = np.asarray(theta, dtype=float)
        if self.transform == "logistic":
            return np.abs(theta) > 15.0
        if self.transform == "log":
            return theta < np.log(1e-6)
        return np.zeros(theta.shape, dtype=bool)

    def theta(self, value):
        # concrete values (a fit's start point) in NumPy: JAX would compile each operation on its own
        xp = jnp if isinstance(value, jax.core.Tracer) else np
        value = xp.asarray(value, dtype=float)
        scale = xp.asarray(self.scale)
        if self.transform == "linear":
            return value / scale
        if self.transform == "log":
            return xp.log(value / scale)
        if self.transform == "logistic":
            lower, upper = xp.asarray(self.lower), xp.asarray(self.upper)
            z = (value - lower) / (upper - lower)
            if xp is np:  # a value on a bound has θ = ±inf (`fit.check_start` names it), without NumPy's warnings
                with np.errstate(divide="ignore", invalid="ignore"):
                    return np.log(z) - np.log1p(-z)
            return xp.log(z) - xp.log1p(-z)
        return xp.linalg.solve(xp.asarray(self.basis), value) / scale


def _refuse_overlaps(groups, valid):
    """Two free entries must not move one element ('valve.coefficients' and 'valve.coefficients[1,0]' both fit m4:
    twice the same unknown, a singular problem)."""
    owner = {}
    for g in groups:
        leaf = ".".join(g.attrs)
        shape = valid.get(leaf, ())
        for element in ([tuple(g.index)] if g.index is not None else list(np.ndindex(*shape)) or [()]):
            if (leaf, element) in owner and owner[(leaf, element)] != g.path:
                shown = f"{leaf}[{','.join(map(str, element))}]" if element else leaf
                raise PamjaxInputError(f"free names {shown} twice: in {owner[(leaf, element)]!r} and in {g.path!r} "
                                       "(a whole array frees all its elements); keep one of them")
            owner[(leaf, element)] = g.path


def _labels(path, shape, index, label):
    """The reported names of a free entry: its path for an indexed entry or a scalar, the field's `label` format
    per entry ({i}: flat index, {n}: i + 1), else path[i, j]."""
    if index is not None:
        return (path,)
    idx = list(np.ndindex(*shape)) if shape else [()]
    if label is not None:
        return tuple(label.format(i=k, n=k + 1) for k in range(len(idx)))
    return tuple(f"{path}[{','.join(map(str, i))}]" if i else path for i in idx)


# Keys of a free-parameter entry given as a dict (the `pamjax fit` config's free tables take the same).
FREE_ENTRY_KEYS = ("path", "transform", "bounds", "scale")
# The type of `free` (fit, ParameterSpace, multistart, ...): entries that are a parameter path, or a dict with the
# keys FREE_ENTRY_KEYS ({"path": ..., "transform": "log", "bounds": (lo, hi), "scale": s}).
Free = Sequence[str | Mapping[str, Any]]


def _zero_start_scale(full, index):
    """Scale of linear parameters that start at exactly 0 (their own magnitude gives none).

    Entries of one column of a 2-D coefficient array are taken to share units (as paper 000's eq. 13 m_ij, which
    multiplies u^i p_g^j with u dimensionless), so a zero entry takes its column's largest magnitude; in a 1-D array,
    the array's largest; else 1 (give the free entry a 'scale' then). Without this, eq. 13's m1 = 0 would be fitted
    in units of 1 kg/s beside m4 and m7 of ~1e-3 kg/s: badly scaled for Levenberg-Marquardt's isotropic damping."""
    if full.ndim == 2:
        s = np.broadcast_to(np.max(np.abs(full), axis=0), full.shape)
    elif full.ndim == 1:
        s = np.full(full.shape, np.max(np.abs(full), initial=0.0))
    else:
        s = np.zeros(full.shape)
    s = np.ravel(s if index is None else s[index])
    return np.where(s > 0, s, 1.0)


def _field_metadata(model, attrs):
    """The metadata of the dataclass field a path ends in (how its component says it is fitted), or {}."""
    owner = getter(attrs[:-1])(model)
    if isinstance(attrs[-1], Key):
        return {}
    fields = dataclasses.fields(owner) if dataclasses.is_dataclass(owner) else ()
    return next((dict(f.metadata) for f in fields if f.name == attrs[-1]), {})


def _entry(entry):
    """(path, transform, bounds, scale) of a free entry: a path string, or a dict with those keys."""
    if not isinstance(entry, (str, Mapping)):
        raise PamjaxInputError(f"free parameter entry {entry!r} must be a parameter path (a string) or a dict with "
                               f"the keys {', '.join(FREE_ENTRY_KEYS)}")
    spec = {"path": entry} if isinstance(entry, str) else dict(entry)
    path = spec.pop("path", None)
    if path is None:
        raise PamjaxInputError(f"free parameter entry {entry!r} needs a 'path'")
    transform, bounds, user_scale = spec.pop("transform", None), spec.pop("bounds", None), spec.pop("scale", None)
    if spec:
        raise PamjaxInputError(f"free parameter {path!r}: unknown keys {sorted(spec)}; valid: "
                               f"{', '.join(FREE_ENTRY_KEYS)}")
    return path, transform, bounds, user_scale


def _start_value(model, path, attrs, index, valid):
    """(the free entry's start value, the whole leaf) as NumPy arrays; a `PamjaxInputError` for an unknown path or
    an index out of range."""
    leaf_path = join_path(attrs)
    if leaf_path not in valid:
        try:  # a leaf set to a Python number (eqx.tree_at(..., model, 6.0e5)) is no array: no parameter, say why
            leaf = getter(attrs)(model)
        except (AttributeError, KeyError, TypeError, IndexError):
            leaf = None
        hint = (f": it holds a Python number ({leaf!r}), not an array; set it as one, np.asarray({leaf!r}) or "
                "jnp.asarray" if isinstance(leaf, int | float) and not isinstance(leaf, bool) else "")
        raise PamjaxInputError(f"unknown parameter {path!r}{hint}; the model's parameters are:\n  "
                               + "\n  ".join(sorted(valid)))
    full = np.asarray(getter(attrs)(model), dtype=float)
    if index is None:
        return full, full
    if len(index) != full.ndim or any(not 0 <= i < n for i, n in zip(index, full.shape)):
        raise PamjaxInputError(f"index {list(index)} out of range for {leaf_path!r} of shape {full.shape}")
    return full[index], full


def _transform(path, value, index, transform, bounds, meta):
    """The checked (transform, bounds) of a free entry: the user's, else its field's declaration (a "log" one only
    for a positive start value, a "nodes" one only for the whole array), else "linear". Bounds are those of the
    logistic transform (the only one that has any): with another transform they are refused, never ignored."""
    if bounds is not None:
        lo, hi = _bounds(path, bounds)
        if transform is not None and transform != "logistic":
            raise PamjaxInputError(f"free parameter {path!r}: bounds apply through the 'logistic' transform, not "
                                   f"{transform!r} (which would ignore them): drop transform or bounds")
        if not (lo < hi and np.all(value > lo) and np.all(value < hi)):
            raise PamjaxInputError(f"bounds {bounds} of {path!r} must satisfy lo < start value {value} < hi")
        transform = transform or "logistic"
    if transform is None:
        transform, bounds = meta.get("transform", "linear"), meta.get("bounds")
        if (transform == "log" and not np.all(value > 0)) or (transform == "nodes" and index is not None):
            transform, bounds = "linear", None
    if transform not in TRANSFORMS:
        raise PamjaxInputError(f"transform of {path!r} must be linear, log, logistic or nodes, got {transform!r}")
    if transform == "log" and not np.all(value > 0):
        raise PamjaxInputError(f"{path!r} starts at {value}: a log transform needs a positive start value")
    if transform == "logistic" and bounds is None:
        raise PamjaxInputError(f"{path!r}: a logistic transform needs bounds (lo, hi)")
    return transform, bounds


def _bounds(path, bounds):
    """(lo, hi) of a free entry's `bounds`: two finite numbers."""
    try:
        lo, hi = (float(b) for b in (() if isinstance(bounds, str) else bounds))
    except (TypeError, ValueError):  # not a pair, or not numbers
        raise PamjaxInputError(f"free parameter {path!r}: bounds must be (lo, hi), two numbers, "
                               f"got {bounds!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise PamjaxInputError(f"free parameter {path!r}: bounds must be finite, got {bounds!r}")
    return lo, hi


def _domain(model, attrs, name, path):
    """The interval (lo, hi) an enclosing component of the path's leaf names `name` (a muscle's `stroke`)."""
    for k in range(len(attrs) - 1, -1, -1):
        owner = getter(attrs[:k])(model)
        if name is not None and isinstance(owner, eqx.Module) and hasattr(owner, name):
            lo, hi = getattr(owner, name)
            return float(lo), float(hi)
    what = (f"an enclosing component with a {name!r} range" if name is not None else
            "a polynomial whose field names the range it spans (a muscle's max_force_coefficients: its stroke)")
    raise PamjaxInputError(f"{path!r}: a 'nodes' transform needs {what}; give another transform")


def _nodes_basis(model, attrs, path, flat, domain):
    """(basis, scale) of a polynomial fitted by its values at len(flat) Chebyshev nodes over `domain`: coefficients =
    basis @ values (well conditioned where the monomials are not)."""
    lo, hi = _domain(model, attrs, domain, path)
    n = flat.size
    nodes = 0.5 * (lo + hi) + 0.5 * (hi - lo) * np.cos(np.pi * (2 * np.arange(n) + 1) / (2 * n))
    vander = np.vander(nodes, n, increasing=True)  # F(nodes) = V a
    return np.linalg.inv(vander), np.full(n, np.max(np.abs(vander @ flat)))


def _make_group(model, entry, valid):
    path, transform, bounds, user_scale = _entry(entry)
    attrs, index = _parse(path)
    value, full = _start_value(model, path, attrs, index, valid)
    meta = _field_metadata(model, attrs)
    transform, bounds = _transform(path, value, index, transform, bounds, meta)
    flat = value.reshape(-1)
    scale = np.where(flat != 0, np.abs(flat), _zero_start_scale(full, index))
    if transform == "linear" and meta.get("scale") is not None:  # a signed quantity with a natural unit (an offset)
        scale = np.full(flat.shape, float(meta["scale"]))
    if user_scale is not None:
        if transform != "linear":
            raise PamjaxInputError(f"free parameter {path!r}: 'scale' applies to the linear transform, not "
                                   f"{transform!r}")
        user = np.broadcast_to(np.asarray(user_scale, dtype=float), value.shape).reshape(-1)
        if not np.all(np.isfinite(user) & (user > 0)):
            raise PamjaxInputError(f"free parameter {path!r}: scale must be finite and > 0, got {user_scale!r}")
        scale = user
    basis = None
    lower = upper = np.zeros_like(flat)
    if transform == "logistic":
        lower, upper = np.full_like(flat, bounds[0]), np.full_like(flat, bounds[1])
    if transform == "nodes":
        basis, scale = _nodes_basis(model, attrs, path, flat, meta.get("domain"))
    labels = _labels(path, value.shape, index, meta.get("label"))
    return _Group(path, tuple(attrs), index, transform, labels, device_array(scale), device_array(lower),
                  device_array(upper), None if basis is None else device_array(basis))


def strong_types(model):
    """`model` with every array leaf of a definite dtype (JAX marks arrays made from Python scalars "weakly typed";
    a fitted model's leaves are strongly typed, and mixing the two recompiles every function they go through)."""
    def strong(x):
        if not eqx.is_array(x):
            return x
        if isinstance(x, jax.core.Tracer):
            return jnp.asarray(x, dtype=jnp.asarray(x).dtype)
        if isinstance(x, jax.Array) and not x.weak_type:
            return x
        return device_array(np.asarray(x))  # concrete: the same values, made without compiling

    return jax.tree_util.tree_map(strong, model)


class ParameterSpace(eqx.Module):
    """Maps the unconstrained, O(1)-scaled vector θ to a model with the free parameters set (everything else
    fixed). `free` entries: a path string, or a dict {path, transform ('linear'|'log'|'logistic'|'nodes'),
    bounds (lo, hi: the logistic transform's, its default; refused with another), scale (linear transform: the O(1)
    unit of θ; default the start magnitude, see
    `_zero_start_scale` for parameters starting at 0)}."""

    base: eqx.Module
    groups: tuple

    def __init__(self, model: eqx.Module, free: Free):
        if isinstance(free, str) or not free:
            raise PamjaxInputError(f"free must be a non-empty list of parameter paths, got {free!r}")
        valid = parameter_paths(model)
        model = strong_types(model)
        self.base = model
        self.groups = tuple(_make_group(model, e, valid) for e in free)
        labels = self.labels
        if len(set(labels)) != len(labels):
            raise PamjaxInputError(f"a parameter is named twice in free: {labels}")
        _refuse_overlaps(self.groups, valid)

    @property
    def labels(self):
        return [label for g in self.groups for label in g.labels]

    @property
    def size(self):
        return sum(g.size for g in self.groups)

    def _split(self, vec):
        out, k = [], 0
        for g in self.groups:
            out.append(vec[k : k + g.size])
            k += g.size
        return out

    def physical(self, theta):
        """The free parameters' physical values (flat; F_max as a0…a4)."""
        return jnp.concatenate([g.physical(t) for g, t in zip(self.groups, self._split(theta))])

    def at_bound(self, theta):
        """Per label: whether the parameter sits at a bound of its range (see `_Group.at_bound`)."""
        return np.concatenate([g.at_bound(t) for g, t in zip(self.groups, self._split(np.asarray(theta)))])

    # Concrete values (start points, fitted values) are mapped in NumPy and made JAX arrays once: eager JAX would
    # compile each small operation on its own (tenths of a second per run); traced ones as before.

    def theta(self, values):
        if isinstance(values, jax.core.Tracer):
            return jnp.concatenate([g.theta(v) for g, v in zip(self.groups, self._split(values))])
        return device_array(np.concatenate([g.theta(v) for g, v in zip(self.groups, self._split(np.asarray(values)))]))

    def initial_theta(self):
        return self.theta(self.initial_values())

    def initial_values(self):
        vals = []
        for g in self.groups:
            v = np.asarray(getter(g.attrs)(self.base), dtype=float)
            vals.append((v if g.index is None else v[g.index]).reshape(-1))
        return device_array(np.concatenate(vals))

    def with_values(self, values, model=None):
        """`model` (default the base) with the free parameters set to physical `values`: one number per label, in
        their order (concrete ones checked: finite, a log-fitted one not negative, a logistic one within its bounds)."""
        model = self.base if model is None else model
        traced = isinstance(values, jax.core.Tracer)
        for g, v in zip(self.groups, self._split(values if traced else self._checked(values))):
            get = getter(g.attrs)
            if traced:
                old = jnp.asarray(get(model), dtype=float)
                new = v.reshape(old.shape) if g.index is None else old.at[g.index].set(v[0])
            else:
                old = np.asarray(get(model), dtype=float)
                if g.index is None:
                    new = v.reshape(old.shape)
                else:
                    new = old.copy()
                    new[g.index] = v[0]
                new = device_array(new)
            model = eqx.tree_at(get, model, new)
        return model

    def _checked(self, values):
        """Concrete `with_values` values as a float array: as many as labels (4 for 3 dropped the 4th silently),
        finite, and in each parameter's range as the space maps it (a negative value of a log-fitted one, a value
        outside a logistic one's bounds has no θ)."""
        want = f"{self.size} number{'s' * (self.size != 1)}, one per label ({', '.join(self.labels)})"
        try:
            v = None if isinstance(values, (str, Mapping)) else np.asarray(values, dtype=float)
        except (TypeError, ValueError):
            v = None
        if v is None or v.shape != (self.size,):
            got = f"shape {v.shape}" if v is not None else f"a {type(values).__name__}"
            raise PamjaxInputError(f"values must be {want}; got {got}: {values!r}")
        for g, x in zip(self.groups, self._split(v)):
            for label, xi, lo, hi in zip(g.labels, x, np.asarray(g.lower), np.asarray(g.upper)):
                if not np.isfinite(xi):
                    raise PamjaxInputError(f"values: {label} = {xi} is non-finite; each value must be a finite number")
                if g.transform == "log" and xi < 0:
                    raise PamjaxInputError(f"values: {label} = {xi:g} is negative; {g.path} is fitted in log space "
                                           "(a positive quantity)")
                give = 1e-9 * (hi - lo)  # lo + (hi − lo)·σ(θ) rounds past a bound (0.1 + 0.2·1 = 0.30000000000000004)
                if g.transform == "logistic" and not lo - give <= xi <= hi + give:
                    raise PamjaxInputError(f"values: {label} = {xi:g} lies outside its bounds ({lo:g}, {hi:g})")
        return v

    def model(self, theta):
        return self.with_values(self.physical(theta))
