"""Every module path the documentation names still resolves, so a move or rename cannot leave it stale.

Two kinds of reference are checked:

* a dotted ``aerobat.x.y`` path anywhere in docs/*.md, README.md or a docstring under src/aerobat:
  the longest prefix that imports as a module, then attribute lookup for the rest;
* a Sphinx role in a docstring (``:mod:``, ``:class:``, ``:func:``, ``:meth:``, ``:attr:``, ...):
  ``aerobat.…`` as above; ``.name`` relative to the docstring's package (then its module); a bare
  name in the enclosing class, the module, or its package.

A few dotted names are not Python paths and are taken from where they are defined: the
entry-point groups (pyproject.toml), the store's default file name and the MCAP schema titles.
"""

from __future__ import annotations

import ast
import builtins
import dataclasses
import importlib
import inspect
import re
import textwrap
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "src"
DOTTED = re.compile(r"(?<![\w./-])aerobat(?:\.[A-Za-z_]\w*)+")
ROLE = re.compile(r":(?:py:)?(mod|class|func|meth|data|attr|exc|obj|const):`~?([^`<>]+?)`")
# References left stale on purpose, each until a named change lands: remove the entry then.
PENDING: set[tuple[str, str]] = set()


def _not_python_paths() -> frozenset[str]:
    """Dotted names in the docs that are something else: entry-point groups, a file name, schema titles."""
    from aerobat.core.registry import MANEUVERS
    from aerobat.core.rules.registry import RULES
    from aerobat.store.database import DEFAULT_PATH

    groups = {MANEUVERS.group, RULES.group, *tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
              .get("entry-points", {})}
    titles = re.findall(r'"title": "(aerobat\.\w+)"', (SRC / "aerobat/export/mcap.py").read_text())
    assert titles, "the MCAP schemas have no titles any more: update this test"
    return frozenset({*groups, DEFAULT_PATH, *titles} - {None})


def _instance_attributes(cls: type) -> set[str]:
    """The ``self.name = …`` attributes a class's methods assign (documented as :attr: but not on the class)."""
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    except (OSError, TypeError):
        return set()
    return {target.attr for node in ast.walk(tree) if isinstance(node, ast.Assign | ast.AnnAssign)
            for target in (node.targets if isinstance(node, ast.Assign) else [node.target])
            if isinstance(target, ast.Attribute) and isinstance(target.value, ast.Name) and target.value.id == "self"}


def unresolved(path: str) -> str | None:
    """Why ``path`` (``package.module.Name.attribute``) does not resolve, or None if it does."""
    parts = path.split(".")
    for n in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:n]))
        except ImportError:
            continue
        for attr in parts[n:]:
            found = getattr(obj, attr, dataclasses.MISSING)
            if found is dataclasses.MISSING:
                mro = getattr(obj, "__mro__", [obj])
                declared = {k for c in mro for k in getattr(c, "__annotations__", {})}
                if inspect.isclass(obj):
                    declared |= {k for c in mro if c.__module__.startswith("aerobat") for k in _instance_attributes(c)}
                return None if attr in declared else f"{'.'.join(parts[:n])} has no {attr!r}"
            obj = found
        return None
    return f"no module {parts[0]!r}"


def _docstrings(tree: ast.Module) -> Iterator[tuple[int, str, str | None]]:
    """(line, docstring, enclosing class name) for the module and every class and function in it."""

    def walk(node: ast.AST, cls: str | None) -> Iterator[tuple[int, str, str | None]]:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
                inner = child.name if isinstance(child, ast.ClassDef) else cls
                doc = ast.get_docstring(child, clean=False)
                if doc:
                    yield child.body[0].lineno, doc, inner
                yield from walk(child, inner if isinstance(child, ast.ClassDef) else cls)

    doc = ast.get_docstring(tree, clean=False)
    if doc:
        yield 1, doc, None
    yield from walk(tree, None)


def _role_candidates(role: str, target: str, module: str, package: str, cls: str | None) -> list[str]:
    if target.startswith("."):
        return [package + target, module + target]
    if role == "mod":
        return [target, f"{package}.{target}"]
    scopes = [f"{module}.{cls}"] if cls else []
    return [f"{scope}.{target}" for scope in (*scopes, module, package)] + [target]


def docstring_references() -> Iterator[tuple[str, str, str | None]]:
    """(where, reference, why it does not resolve) for every reference in src/aerobat's docstrings."""
    for path in sorted((SRC / "aerobat").rglob("*.py")):
        parts = path.relative_to(SRC).with_suffix("").parts
        module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        package = module if parts[-1] == "__init__" else module.rpartition(".")[0]
        for line, doc, cls in _docstrings(ast.parse(path.read_text())):
            where = f"{path.relative_to(ROOT)}:{line}"
            for m in DOTTED.finditer(doc):
                yield where, m.group(0), unresolved(m.group(0))
            for role, target in ROLE.findall(doc):
                target = target.strip().removesuffix("()")
                if target.startswith("aerobat."):
                    continue  # a dotted path, checked above
                candidates = _role_candidates(role, target, module, package, cls)
                problems = [unresolved(c) for c in candidates]
                if all(problems) and not hasattr(builtins, target):
                    yield where, f":{role}:`{target}`", problems[0]
                else:
                    yield where, f":{role}:`{target}`", None


def page_references() -> Iterator[tuple[str, str, str | None]]:
    """(where, path, why it does not resolve) for every dotted ``aerobat.`` path in docs/*.md and README.md."""
    for page in [*sorted((ROOT / "docs").glob("*.md")), ROOT / "README.md"]:
        for number, line in enumerate(page.read_text().splitlines(), 1):
            for m in DOTTED.finditer(line):
                yield f"{page.relative_to(ROOT)}:{number}", m.group(0), unresolved(m.group(0))


def test_every_module_path_in_the_docs_and_docstrings_resolves():
    skip = _not_python_paths()
    references = [*page_references(), *docstring_references()]
    assert len(references) > 300, "the scan found too few references: is it still reading the docs?"
    stale = {(where, ref): why for where, ref, why in references if why and ref not in skip}
    pending = {key for key in stale if (key[0].partition(":")[0], key[1]) in PENDING}
    assert not stale.keys() - pending, "stale references:\n" + "\n".join(
        f"{where}: {ref} ({why})" for (where, ref), why in stale.items() if (where, ref) not in pending)
    fixed = PENDING - {(where.partition(":")[0], ref) for where, ref in pending}
    assert not fixed, f"these references resolve now: remove them from PENDING: {sorted(fixed)}"


@pytest.mark.parametrize(("path", "resolves"), [
    ("aerobat.core.learning", True),
    ("aerobat.quadrotor.maneuvers.staged.StagedManeuver", True),
    ("aerobat.core.outcomes.TrialStatus.retry", True),
    ("aerobat.learning.PaperSchedule", False),
    ("aerobat.core.nosuchmodule", False),
    ("aerobat.core.learning.NoSuchName", False),
])
def test_the_resolver_tells_a_stale_path_from_a_live_one(path, resolves):
    assert (unresolved(path) is None) == resolves
