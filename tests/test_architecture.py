"""The package's structure, checked (docs/architecture.md): one direction of imports between the layers
(import-linter's layers contract in pyproject.toml), workflows that ask contracts instead of concrete classes, abstract
methods that are abstract, modules and functions of a readable size, and fits/ and benchmarks/ on public names only."""

import ast
import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "pamjax"
LAYERS = ("_core", "_papers", "_physics", "_systems", "_solve", "_fit", "_sweep", "_control", "_cli")
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
