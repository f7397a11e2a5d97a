"""The Python examples of the README and docs/*.md as a user copies them: the README's runs as written (a user's first
contact: it computed nothing before this test, `jax.grad` of a loss of the whole system stopped on the PWM valve's
traced frequency), and every block of every page parses and names only what pamjax has (an import of a name that
moved, a misspelt `pj.` attribute: one of the guides imported `simulate_joint_control` from a module that no longer
had it). The guides' blocks are fragments of their page (they use names of the blocks before them, and files a run
of `pamjax fit` writes), so they are checked for what they name, not run."""

import ast
import importlib
import math
import pathlib
import re

import jax
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)
ALIASES = {"pj": "pamjax", "pamjax": "pamjax", "presets": "pamjax.presets"}  # names the guides give pamjax's modules


def _blocks(page):
    return [m.group(1) for m in BLOCK.finditer(page.read_text())]


def _examples():
    return [pytest.param(page, i, code, id=f"{page.relative_to(ROOT)}[{i}]")
            for page in PAGES for i, code in enumerate(_blocks(page))]


def test_the_readmes_python_example_runs_as_written():
    [code] = _blocks(ROOT / "README.md")
    namespace = {}
    exec(compile(code, "README.md", "exec"), namespace)  # noqa: S102 - the README's own example
    traj, grads = namespace["traj"], namespace["grads"]
    assert traj.position.shape == (2501,) and math.isfinite(float(traj.position[-1]))
    leaves = jax.tree_util.tree_leaves(grads)
    assert leaves and all(bool(jax.numpy.all(jax.numpy.isfinite(g))) for g in leaves)
    assert float(grads.muscle.force_law.k0) != 0.0 and float(grads.friction.coulomb_force) != 0.0


def _dotted(node):
    """'a.b.c' of an attribute chain `a.b.c` on a plain name, else None."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    return ".".join([node.id, *reversed(parts)]) if isinstance(node, ast.Name) else None


def _resolves(dotted):
    """Whether `pamjax...` names a module or attribute pamjax has (the longest importable module, then attributes)."""
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for name in parts[cut:]:
            if not hasattr(obj, name):
                return False
            obj = getattr(obj, name)
        return True
    return False


def _named(tree):
    """Every `pamjax...` name a block uses: its imports from pamjax and the attribute chains on pamjax's aliases,
    each as far as it goes (`pj.bench.load_bench(...).model` is checked as `pamjax.bench.load_bench`)."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "pamjax":
            names.update(f"{node.module}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            names.update(a.name for a in node.names if a.name.split(".")[0] == "pamjax")
        elif isinstance(node, ast.Attribute) and not isinstance(getattr(node, "_parent", None), ast.Attribute):
            dotted = _dotted(node)
            if dotted and dotted.split(".")[0] in ALIASES:
                head, _, rest = dotted.partition(".")
                names.add(f"{ALIASES[head]}.{rest}")
    return names


def _mark_parents(tree):
    for node in ast.walk(tree):
        for child in ast.iter_child_nodes(node):
            child._parent = node
    return tree


@pytest.mark.parametrize("page, index, code", _examples())
def test_every_docs_example_parses_and_names_only_what_pamjax_has(page, index, code):
    tree = _mark_parents(ast.parse(code, f"{page.name} block {index}"))
    missing = sorted(n for n in _named(tree) if not _resolves(n))
    assert not missing, f"{page.relative_to(ROOT)}, Python block {index}: {missing} not in pamjax"


def test_the_names_check_finds_a_name_pamjax_does_not_have():
    tree = _mark_parents(ast.parse("import pamjax as pj\nfrom pamjax._systems.joint_control import "
                                   "simulate_joint_control\nx = pj.presets.mas10_system(valve='pwm').valve\n"
                                   "y = pj.no_such_function(1)\nz = pj.bench.load_bench\n"))
    names = _named(tree)
    assert {"pamjax._systems.joint_control.simulate_joint_control", "pamjax.presets.mas10_system",
            "pamjax.no_such_function", "pamjax.bench.load_bench"} <= names
    assert [n for n in sorted(names) if not _resolves(n)] == ["pamjax._systems.joint_control.simulate_joint_control",
                                                                "pamjax.no_such_function"]
