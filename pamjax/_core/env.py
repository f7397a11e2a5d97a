"""The environment variables pamjax reads as on/off words or as seconds, each checked where it is read: a value that
is neither is a `PamjaxInputError` naming the variable and what to write (a typo must not silently mean on or off)."""

import os
from collections.abc import Mapping

import numpy as np

from .errors import PamjaxInputError

# The words an on/off environment variable takes (`env_flag`); the off ones are those `xla_cpu` reads as off.
FLAG_ON, FLAG_OFF = ("1", "true", "yes", "on"), ("0", "false", "no", "off")


def env_flag(name: str, default: bool, environ: Mapping[str, str] | None = None) -> bool:
    """The on/off environment variable `name` (`PAMJAX_DEBUG`, `PAMJAX_COMPILATION_CACHE`, ...): `default` when
    unset or empty, True for 1/true/yes/on, False for 0/false/no/off (any case). Anything else is a
    `PamjaxInputError` naming the variable and the words it takes: `PAMJAX_DEBUG=false` once turned the tracebacks
    on, and a typo such as "disabled" must not silently mean either."""
    environ = os.environ if environ is None else environ
    value = environ.get(name, "").strip().lower()
    if not value:
        return default
    if value not in FLAG_ON + FLAG_OFF:
        raise PamjaxInputError(f"environment variable {name}={environ[name]!r}: write one of {'/'.join(FLAG_ON)} "
                               f"(on) or {'/'.join(FLAG_OFF)} (off), or unset it")
    return value in FLAG_ON


def env_seconds(name: str, default: float, environ: Mapping[str, str] | None = None) -> float:
    """The environment variable `name` as a number of seconds >= 0 (`default` when unset or empty); anything else
    (a unit, "nan", a negative number) is a `PamjaxInputError` naming the variable: "0.5s" in
    `PAMJAX_CACHE_MIN_COMPILE_SECONDS` crashed every command with a traceback, "-1" and "nan" were taken silently."""
    environ = os.environ if environ is None else environ
    text = environ.get(name, "").strip()
    try:
        value = float(text) if text else float(default)
    except ValueError:
        value = float("nan")
    if not (np.isfinite(value) and value >= 0.0):
        raise PamjaxInputError(f"environment variable {name}={environ[name]!r}: write a number of seconds >= 0 "
                               f"(e.g. 0.5, no unit), or unset it for the default {default:g} s")
    return value
