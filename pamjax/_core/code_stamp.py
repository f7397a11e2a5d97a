"""What code a traced program runs, for the key of the command line's program cache (`pamjax._core.cache`): a
program kept on disk must not be found again once its code changed. Versions do not tell: an editable install (the
README's `pip install -e`) keeps its version through every edit, and a user's own component has none. So the key
holds pamjax's source files and the source file of every class and function in the program's arguments, by their
contents; where a class has no source file (defined at the prompt or in a notebook), no key."""

import functools
import os
import pathlib
import sys


def code_stamp(args):
    """What the code of a program traced from `args` is: pamjax's own source files (`_package_stamp`) and the
    source file of every module that defines a class or function in `args` (a user's component, an experiment's
    `build`), each by a digest of its contents (`_module_stamp`); None if one has no file."""
    modules = set()
    _modules_of(args, modules, set())
    stamps = []
    for name in sorted(m for m in modules if m and m != "pamjax" and not m.startswith("pamjax.")):
        stamp = _module_stamp(name)
        if stamp is None:
            return None
        stamps.append(stamp)
    return _package_stamp(), tuple(stamps)


def _modules_of(obj, modules, seen):
    """Add to `modules` the modules of the classes (and their bases) and functions inside `obj`."""
    import dataclasses
    import functools

    import equinox as eqx
    import numpy as np

    if obj is None or isinstance(obj, (str, bytes, bool, int, float, complex, np.ndarray, np.generic)):
        return
    if eqx.is_array(obj) or id(obj) in seen:
        return
    seen.add(id(obj))
    if isinstance(obj, (list, tuple, set, frozenset)):
        for x in obj:
            _modules_of(x, modules, seen)
    elif isinstance(obj, dict):
        for x in obj.values():
            _modules_of(x, modules, seen)
    elif isinstance(obj, type):
        modules.update(c.__module__ for c in obj.__mro__)
    elif isinstance(obj, functools.partial):
        for x in (obj.func, obj.args, obj.keywords):
            _modules_of(x, modules, seen)
    elif isinstance(obj, eqx.Module) or dataclasses.is_dataclass(obj):
        modules.update(c.__module__ for c in type(obj).__mro__)
        for f in dataclasses.fields(obj):
            _modules_of(getattr(obj, f.name, None), modules, seen)
    else:
        modules.add(getattr(obj, "__module__", None) if callable(obj) else None)
        modules.update(c.__module__ for c in type(obj).__mro__)
        bound = getattr(obj, "__self__", None)  # a bound method: its object's classes too
        if bound is not None and not isinstance(bound, type(sys)):
            _modules_of(bound, modules, seen)


_STAMPS = {}  # module name → its stamp (once per process: a file changed mid-run is seen by the next process)


def _module_stamp(name):
    """(name, digest of its source file) of module `name` (size and time of change for a compiled extension);
    (name,) for a module built into Python or not loaded under that name (a compiled type's nominal module); None
    for a loaded one without a source file (`__main__` at the prompt or in a notebook, a module made at run time):
    its code cannot be told apart."""
    if name not in _STAMPS:
        module = sys.modules.get(name)
        path = getattr(module, "__file__", None)
        if module is None or name in sys.builtin_module_names:  # built in, or a name a compiled type only shows
            stamp = (name,)
        elif path is None:  # `__main__` at the prompt or in a notebook, a module made at run time
            stamp = None
        else:
            try:
                if str(path).endswith(".py"):
                    stamp = (name, _digest(pathlib.Path(path).read_bytes()))
                else:  # a compiled extension (jaxlib's is ~100 MB: not read): its size and time of change
                    st = os.stat(path)
                    stamp = (name, st.st_size, st.st_mtime_ns)
            except OSError:
                stamp = None
        _STAMPS[name] = stamp
    return _STAMPS[name]


def _digest(data):
    import hashlib

    return hashlib.sha256(data).hexdigest()[:16]


@functools.cache  # once per process
def _package_stamp():
    """A digest of pamjax's own source files (their paths in the package and their contents: ~170 files, ~10 ms once
    per process), so that an edited checkout (the README's `pip install -e`) traces anew although its version stays
    the same, while the same code installed elsewhere (a wheel, a reinstall) finds the programs it traced."""
    import hashlib

    root = pathlib.Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for f in sorted(files):
            if f.endswith(".py"):
                path = os.path.join(folder, f)
                digest.update(os.path.relpath(path, root).encode() + b"\0")
                with open(path, "rb") as fh:
                    digest.update(fh.read())
    return digest.hexdigest()[:16]
