"""The package's structure, checked (docs/architecture.md): one direction of imports between the layers
(import-linter's layers contract in pyproject.toml), workflows that ask contracts instead of concrete classes, abstract
methods that are abstract, modules and functions of a readable size, and fits/ and benchmarks/ on public names only;
and the suite itself leaves no temporary compilation cache behind."""

import ast
import os
import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "pamjax"
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80  # code lines, the docstring not counted
LONG_REASON = re.compile(r"#\s*Long:\s*\S")  # the comment that gives a longer function its reason


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py"))


def _layer(path):
    parts = path.relative_to(PACKAGE).parts
    return parts[0] if len(parts) > 1 else None


def test_import_linter_layers_contract_is_kept():
    """`lint-imports` with the contract of pyproject.toml: a module importing a layer above its own, or a sibling
    workflow importing another (fit, sweep, control), fails here with the offending import chain."""
    pytest.importorskip("importlinter")
    code = ("import sys; from importlinter.cli import lint_imports; "
            "sys.exit(lint_imports(config_filename='pyproject.toml', no_cache=True, no_logo=True))")
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr


def test_papers_import_nothing():
    for path in (PACKAGE / "_papers").rglob("*.py"):
        tree = ast.parse(path.read_text())
        imports = [n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))]
        assert not imports, f"{path.name} imports something; pamjax._papers holds numbers only"


def test_no_not_implemented_error():
    """Abstract methods are `abc.abstractmethod`s (an incomplete component cannot be instantiated), not stubs."""
    offenders = [str(p.relative_to(ROOT)) for p in _modules() if "raise NotImplementedError" in p.read_text()]
    assert not offenders, offenders


def _concrete_component_classes():
    """name → layer of every concrete (non-Abstract) class defined in the physics and systems layers."""
    out = {}
    for path in _modules():
        if _layer(path) not in ("_physics", "_systems"):
            continue
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.ClassDef) and not node.name.startswith("Abstract"):
                out[node.name] = _layer(path)
    return out


def test_workflows_ask_contracts_not_concrete_classes():
    """No `isinstance(x, SomeConcreteComponent)` outside the component's own layer: a workflow that needs to know
    whether a valve switches asks `valve.switches`, not `isinstance(valve, OnOffValve)`."""
    concrete = _concrete_component_classes()
    offenders = []
    for path in _modules():
        layer = _layer(path)
        for node in ast.walk(ast.parse(path.read_text())):
            call = isinstance(node, ast.Call) and getattr(node.func, "id", None) == "isinstance"
            if not (call and len(node.args) == 2):
                continue
            kinds = node.args[1].elts if isinstance(node.args[1], ast.Tuple) else [node.args[1]]
            for kind in kinds:
                name = getattr(kind, "id", None) or getattr(kind, "attr", None)
                if name in concrete and concrete[name] != layer:
                    offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} isinstance(..., {name})")
    assert not offenders, offenders


def test_modules_are_readable_in_one_sitting():
    sizes = {str(p.relative_to(ROOT)): len(p.read_text().splitlines()) for p in _modules()}
    assert not {k: v for k, v in sizes.items() if v > MAX_MODULE_LINES}


def _long_functions(path):
    source = path.read_text()
    lines = source.splitlines()
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        length = node.end_lineno - node.lineno + 1
        first = node.body[0]
        if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
            length -= first.end_lineno - first.lineno + 1
        start = min([d.lineno for d in node.decorator_list] + [node.lineno])
        reason = start >= 2 and LONG_REASON.search(lines[start - 2])
        if length > MAX_FUNCTION_LINES and not reason:
            yield f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({length} lines)"


def test_functions_fit_on_a_screen_or_say_why():
    """A function over 80 code lines carries a `# Long: <reason>` comment on the line above its definition."""
    offenders = [f for p in _modules() for f in _long_functions(p)]
    assert not offenders, offenders


@pytest.mark.parametrize("folder", ["fits", "benchmarks", "examples"])
def test_scripts_use_public_names_only(folder):
    """fits/, benchmarks/ and examples/ are written as a user would write them: `pamjax.X`, `pamjax.presets`,
    `pamjax.units`, `pamjax.gallery`, never a private module."""
    private = re.compile(r"\bpamjax\._|\bpj\._|from pamjax import _|from pamjax\._")
    offenders = []
    for path in (ROOT / folder).rglob("*.py"):
        for k, line in enumerate(path.read_text().splitlines(), 1):
            if private.search(line.split("#")[0]):
                offenders.append(f"{path.relative_to(ROOT)}:{k}: {line.strip()}")
    assert not offenders, offenders


MAX_INIT_LINES = 160  # issue 31: the top level holds what a user imports daily; the rest is in sub-namespaces


def test_top_level_is_compact():
    lines = len((PACKAGE / "__init__.py").read_text().splitlines())
    assert lines <= MAX_INIT_LINES, f"pamjax/__init__.py has {lines} lines (at most {MAX_INIT_LINES})"


def test_the_suite_leaves_no_cache_behind(tmp_path):
    """The session's compilation cache (tests/conftest.py: a fresh temporary folder, ~70 MB after a full run) is
    removed when the session ends; every run left one behind before."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PAMJAX_CACHE_DIR", "JAX_COMPILATION_CACHE_DIR", "PYTEST_XDIST_WORKER", "PAMJAX_TEST_CACHE")}
    env["TMPDIR"] = str(tmp_path)
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "0", "-p", "no:cacheprovider",
                          "tests/test_architecture.py::test_top_level_is_compact"],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    assert not list(tmp_path.glob("pamjax-test-cache-*")), "the session's cache folder was left behind"


def _moved():
    from pamjax._core.deprecation import MOVED

    return sorted(MOVED.items())


@pytest.mark.parametrize(("old", "new"), _moved())
def test_deprecated_names_warn_and_resolve_to_their_new_place(old, new):
    """`pamjax.<old>` still works for one release: the same object as at its new place, with a DeprecationWarning that
    names the new place and points at the line that asked for it."""
    import pamjax

    value = pamjax
    for part in new.split("."):
        value = getattr(value, part)
    with pytest.warns(DeprecationWarning, match=rf"pamjax\.{old} is deprecated .*use pamjax\.{re.escape(new)}$") as w:
        alias = getattr(pamjax, old)
    assert alias is value
    assert all(r.filename == __file__ for r in w), [r.filename for r in w]
    assert old not in vars(pamjax) and old not in dir(pamjax)  # resolved by __getattr__ only, so it always warns


def test_from_import_of_a_deprecated_name_warns():
    with pytest.warns(DeprecationWarning, match="use pamjax.bench.load_bench"):
        from pamjax import load_bench
    import pamjax.bench

    assert load_bench is pamjax.bench.load_bench


def test_unknown_names_are_still_attribute_errors():
    import pamjax

    with pytest.raises(AttributeError, match="has no attribute 'no_such_name'"):
        pamjax.no_such_name  # noqa: B018
    assert not hasattr(pamjax, "no_such_name")


def test_the_repository_uses_no_deprecated_name():
    """The package, scripts, docs and tests use the new places (`_core/deprecation.py` lists the old names)."""
    names = "|".join(re.escape(old) for old, _ in _moved())
    old = re.compile(rf"(?<![\w.])(?:pamjax|pj)\.({names})\b|^from pamjax import .*\b({names})\b")
    skip = {PACKAGE / "_core" / "deprecation.py", pathlib.Path(__file__)}
    paths = [p for folder in ("pamjax", "fits", "benchmarks", "examples", "docs", "tests")
             for p in (ROOT / folder).rglob("*") if p.suffix in (".py", ".md", ".toml")] + [ROOT / "README.md"]
    offenders = [f"{p.relative_to(ROOT)}:{k}: {line.strip()}" for p in paths if p not in skip
                 for k, line in enumerate(p.read_text().splitlines(), 1) if old.search(line)]
    assert not offenders, offenders


# --- private names stay in their module (issue 31) -----------------------------------------------------------------
def _module_name(path, root):
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_module(dotted, root):
    """Whether `dotted` (e.g. "pamjax._fit.problem") is a module or package of pamjax."""
    path = root.joinpath(*dotted.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def _imported_from(path, node, root):
    """The absolute module a `from ... import` in `path` reads, or None for a module outside pamjax."""
    if node.level == 0:
        return node.module if node.module and node.module.split(".")[0] == "pamjax" else None
    package = _module_name(path, root).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    base = package[: len(package) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _private(name):
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _defined_names(tree):
    """Every name a module defines itself: functions, classes, their methods and attributes, assignments."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.arg):
            names.add(node.arg)
    return names


def _private_crossings(paths, root=ROOT):
    """`from .x import _y` (a private name of another pamjax module; a module itself may be imported under any
    alias), `module._y` (through a module object) and `obj._y` where `_y` is defined by another pamjax module and not
    by this one (a private method or field of another module's class, e.g. `experiment._grid_size(...)`)."""
    trees = {p: ast.parse(p.read_text()) for p in paths}
    defined = {p: _defined_names(t) for p, t in trees.items()}
    anywhere = set().union(*defined.values())
    offenders = []
    for path, tree in trees.items():
        where = str(path.relative_to(root))
        modules = set()  # local names bound to pamjax modules
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                source = _imported_from(path, node, root)
                if source is None:
                    continue
                for alias in node.names:
                    if _is_module(f"{source}.{alias.name}", root):
                        modules.add(alias.asname or alias.name)
                    elif _private(alias.name):
                        offenders.append(f"{where}:{node.lineno} from {source} import {alias.name}")
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.split(".")[0] == "pamjax":
                        modules.add((alias.asname or alias.name).split(".")[0])
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Attribute) and _private(node.attr)):
                continue
            owner = node.value.id if isinstance(node.value, ast.Name) else None
            if owner in ("self", "cls"):
                continue
            through_module = owner in modules
            if through_module or (node.attr in anywhere and node.attr not in defined[path]):
                offenders.append(f"{where}:{node.lineno} {ast.unparse(node)}")
    return offenders


def test_no_private_name_crosses_a_module_boundary():
    """A module uses another pamjax module through its public names only: no `from .x import _y`, no `x._y` (issue 31:
    design and profile reached the fit through private names that fit.py re-exported). What one module offers another
    it names publicly; a name with a leading underscore is that module's own."""
    offenders = _private_crossings(_modules())
    assert not offenders, "private names used outside their module:\n" + "\n".join(offenders)


def test_the_private_name_rule_can_fail(tmp_path):
    """The rule above on a small package: each kind of crossing is found, the module's own private names are not."""
    package = tmp_path / "pamjax"
    (package / "_a").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "_a" / "__init__.py").write_text("")
    (package / "_a" / "x.py").write_text("def _y():\n    return 1\n\n\nclass C:\n    def _grid(self):\n"
                                         "        return 2\n")
    (package / "_a" / "z.py").write_text("from . import x\nfrom .x import C, _y\n\n\ndef _own():\n"
                                         "    return x._y() + C()._grid() + _own2() + len(C()._cache)\n\n\n"
                                         "def _own2():\n    return 0\n")
    found = _private_crossings([package / "_a" / "x.py", package / "_a" / "z.py"], tmp_path)
    # _own2 is z's own; _cache is defined nowhere in the package (another library's attribute): neither is named
    expected = ["from pamjax._a.x import _y", "x._y", "C()._grid"]
    assert sorted(f.split(" ", 1)[1] for f in found) == sorted(expected), found


# --- contracts, not duck typing (issue 31) -------------------------------------------------------------------------
COMPONENT_LAYERS = ("_physics", "_systems")
EXPERIMENT_MODULES = ("pamjax/_fit/experiment.py", "pamjax/_fit/static_experiments.py")
# (module, attribute) → why a literal hasattr/getattr there is not a component's attribute read outside its layer
GENERIC_READS = {
    ("pamjax/_solve/trajectory.py", "pressure"): "the states' field: a named state (data), marks p ≤ 0 as failed",
    ("pamjax/_solve/hints.py", "pressure"): "the start state's field: a named state (data), for a diagnosis",
    ("pamjax/_solve/hints.py", "friction"): "the start state's friction mode: a named state (data), for a diagnosis",
    ("pamjax/_identifiability/design_setup.py", "pressure"): "the start state's field: a named state (data)",
    ("pamjax/_solve/checks.py", "name"): "a JAX pytree path key's name (GetAttrKey), not a component",
    ("pamjax/_solve/linearise.py", "shape"): "an array leaf's shape, not a component",
}


def _declared_attributes(paths, root=ROOT):
    """attribute → the places that declare it: every public field, method, property and class attribute of the
    components (the classes of `_physics` and `_systems`, except their named states `…State`, which are data whose
    fields are the state's names) by layer, and of the experiments by module."""
    declared = {}
    for path in paths:
        rel = path.relative_to(root)
        layer = rel.parts[1] if len(rel.parts) > 2 else None
        place = layer if layer in COMPONENT_LAYERS else str(rel) if str(rel) in EXPERIMENT_MODULES else None
        if place is None:
            continue
        for node in ast.parse(path.read_text()).body:
            if not isinstance(node, ast.ClassDef) or node.name.endswith("State"):
                continue
            for item in node.body:
                if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
                    names = [item.target.id]
                elif isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    names = [item.name]
                elif isinstance(item, ast.Assign):
                    names = [t.id for t in item.targets if isinstance(t, ast.Name)]
                else:
                    names = []
                for name in names:
                    if not name.startswith("_"):
                        declared.setdefault(name, set()).add(place)
    return declared


def _literal_names(node, loops):
    """The attribute names a hasattr/getattr call reads: its string literal, or the literals a `for name in
    ("muscle", "friction")` loop around it binds to its name argument."""
    arg = node.args[1]
    if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
        return [arg.value]
    if isinstance(arg, ast.Name):
        return loops.get((arg.id, node.lineno), [])
    return []


def _duck_typing(paths, allowed=GENERIC_READS, root=ROOT):
    """hasattr/getattr reads of a component's or an experiment's attribute outside the place that declares it."""
    declared = _declared_attributes(paths, root)
    offenders = []
    for path in paths:
        rel = path.relative_to(root)
        layer = rel.parts[1] if len(rel.parts) > 2 else None
        tree = ast.parse(path.read_text())
        loops = {}
        for loop in ast.walk(tree):
            if (isinstance(loop, ast.For) and isinstance(loop.target, ast.Name)
                    and isinstance(loop.iter, (ast.Tuple, ast.List))
                    and all(isinstance(e, ast.Constant) and isinstance(e.value, str) for e in loop.iter.elts)):
                for inner in ast.walk(loop):
                    if hasattr(inner, "lineno"):
                        loops[(loop.target.id, inner.lineno)] = [e.value for e in loop.iter.elts]
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                    and node.func.id in ("hasattr", "getattr") and len(node.args) >= 2):
                continue
            if isinstance(node.args[0], ast.Name) and node.args[0].id in ("self", "cls"):
                continue  # an object reading its own fields
            for name in _literal_names(node, loops):
                places = declared.get(name, set())
                if not places or layer in places or str(rel) in places or (str(rel), name) in allowed:
                    continue
                offenders.append(f"{rel}:{node.lineno} {node.func.id}({ast.unparse(node.args[0])}, {name!r}): "
                                 f"declared by {', '.join(sorted(places))}")
    return offenders


def test_workflows_ask_contracts_not_attributes():
    """No `hasattr(model, "muscle")`, `getattr(friction, "coulomb_force")` or `hasattr(e, "split_time")` outside the
    component's layer (`_physics`, `_systems`) or the experiment's module: a workflow asks the contract
    (`isinstance(model, AbstractMuscleSystem)`, `AbstractFriction.coulomb_force`, `AbstractExperiment.split_time`,
    `AbstractControlElement.period` and `exact_edges`, `AbstractSignal.cycle_frequency()`, `AbstractSystem.actuators`).
    A read that is not of a component (a named state's field, an array's shape) is listed in `GENERIC_READS` with
    its reason."""
    offenders = _duck_typing(_modules())
    assert not offenders, "attributes read by name instead of through a contract:\n" + "\n".join(offenders)
    stale = [k for k in GENERIC_READS if not (ROOT / k[0]).is_file() or f'"{k[1]}"' not in (ROOT / k[0]).read_text()]
    assert not stale, f"GENERIC_READS entries that no longer match a read: {stale}"


def test_the_duck_typing_rule_can_fail(tmp_path):
    """The rule above on a small package: a component's attribute read by name in a workflow is found (as a literal,
    and through a loop over literals); the same read inside the physics layer, one of `self`, one of an attribute no
    component declares and an allowed one are not."""
    files = {
        "pamjax/_physics/friction.py": "class Friction:\n    coulomb_force: float\n\n    def smoothing_width(self):\n"
                                       "        return getattr(self, 'coulomb_force')\n",
        "pamjax/_systems/muscle.py": "class MuscleState:\n    pressure: float\n\n\nclass MuscleSystem:\n"
                                     "    muscle: object\n    friction: object\n",
        "pamjax/_control/loop.py": "def check(model, friction, y):\n    a = hasattr(model, 'muscle')\n"
                                   "    b = getattr(friction, 'coulomb_force', None)\n"
                                   "    c = getattr(y, 'pressure', None)\n    d = getattr(model, 'weak_type', 0)\n"
                                   "    for name in ('muscle', 'friction'):\n        hasattr(model, name)\n"
                                   "    return getattr(model, 'muscle', 1)\n",
    }
    paths = []
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
        paths.append(tmp_path / rel)
    found = _duck_typing(paths, allowed={("pamjax/_control/loop.py", "friction"): "test"}, root=tmp_path)
    reads = sorted(f.split(" ", 1)[1].split(":")[0] for f in found)
    # 'pressure' is a named state's field, 'weak_type' no component's, 'friction' in the loop allowed here
    assert reads == sorted(["hasattr(model, 'muscle')", "getattr(friction, 'coulomb_force')",
                            "hasattr(model, 'muscle')", "getattr(model, 'muscle')"]), found


# --- the module map and the tests table of docs/architecture.md (issue 31 item 8) ----------------------------------
ARCHITECTURE_DOC = ROOT / "docs" / "architecture.md"
# a path of the package as the doc writes it: relative to pamjax/ (`_solve/grid.py`, `gallery/scripts/p000_01_x.py`,
# `presets.py`), or with the package's name in front (`pamjax/__init__.py`); not a part of a longer path
_DOC_MODULE = re.compile(r"(?<![\w/.-])(?:pamjax/)?((?:_[a-z_]+|gallery|data)/[\w/.-]*?\.py|[a-z_]+\.py)(?![\w/])")
_DOC_TEST = re.compile(r"(?<![\w/.-])tests/(test_\w+\.py)")


def _doc_section(text, title):
    """The text of the `## title` section of a markdown document (to the next `## ` heading)."""
    start = text.index(f"\n## {title}\n")
    end = text.find("\n## ", start + 1)
    return text[start:] if end < 0 else text[start:end]


def _module_map_problems(section, package=PACKAGE):
    """The modules of `package` the map does not name (every .py; a private sub-package's `__init__.py` may be named
    by its folder), and the module paths the map names that are not in the package."""
    named = {m.group(1) for m in _DOC_MODULE.finditer(section)}
    missing = []
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(package).as_posix()
        if rel in named:
            continue
        folder = rel.rsplit("/", 1)[0] if "/" in rel else ""
        if path.name == "__init__.py" and folder.startswith("_") and f"`{folder}/`" in section:
            continue  # a private sub-package's __init__.py holds only its docstring; the package is named
        missing.append(rel)
    # a bare name (`joint.py`) may be a script's (`fits/joint.py`): only a path into a layer can be stale
    stale = sorted(rel for rel in named if "/" in rel and not (package / rel).is_file())
    return missing, stale


def test_every_module_is_in_the_module_map():
    """docs/architecture.md's "Module map" names every module of pamjax/ by its path (`_solve/grid.py`), so a new,
    moved or deleted module cannot leave the map stale silently; a path in the map that names no module fails too."""
    missing, stale = _module_map_problems(_doc_section(ARCHITECTURE_DOC.read_text(), "Module map"))
    assert not missing, "modules missing from docs/architecture.md's module map:\n" + "\n".join(missing)
    assert not stale, "docs/architecture.md's module map names modules that do not exist:\n" + "\n".join(stale)


def test_every_test_file_is_in_the_tests_table():
    """docs/architecture.md's "Tests" table names every tests/test_*.py (which module it tests), and no other."""
    section = _doc_section(ARCHITECTURE_DOC.read_text(), "Tests")
    named = {m.group(1) for m in _DOC_TEST.finditer(section)}
    files = {p.name for p in (ROOT / "tests").glob("test_*.py")}
    assert not files - named, f"test files missing from docs/architecture.md's Tests table: {sorted(files - named)}"
    assert not named - files, f"docs/architecture.md's Tests table names missing files: {sorted(named - files)}"


def test_the_module_map_rule_can_fail(tmp_path):
    """The map rule on a small package: a module the map leaves out is found, a private sub-package's __init__.py is
    covered by its folder, a public one's is not, and a path naming no module is stale."""
    package = tmp_path / "pamjax"
    for rel in ("__init__.py", "presets.py", "_solve/__init__.py", "_solve/grid.py", "_control/fixed_grid.py",
                "gallery/__init__.py", "gallery/scripts/p000_01_x.py"):
        (package / rel).parent.mkdir(parents=True, exist_ok=True)
        (package / rel).write_text("")
    section = ("| `pamjax/__init__.py` | … |\n| `presets.py` | … |\n### `_solve/`\n| `_control/fixed_grid.py` | … |\n"
               "| `gallery/scripts/p000_01_x.py` | … |\n| `_solve/gone.py` | … (see `fits/joint.py`) |\n")
    missing, stale = _module_map_problems(section, package)
    # `_solve/grid.py` is not named (`_control/fixed_grid.py` does not name it); `fits/joint.py` is no module path
    assert missing == ["_solve/grid.py", "gallery/__init__.py"], missing
    assert stale == ["_solve/gone.py"], stale
