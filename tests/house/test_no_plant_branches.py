"""The application layer asks a plant's spec what it can do; it never branches on a plant's name (issue 43).

Import-linter keeps ``aerobat.experiments``, ``aerobat.cli``, ``aerobat.browse`` and ``aerobat.export`` from
importing a plant's package. This test finds what imports do not show: a comparison with a plant's name
(``kind == "betaflight"``, ``"betaflight" in choices``) or a hand-written list of plants. A default plant
(``default="arena"``) and names in text are allowed: they decide nothing about what a plant can do.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from aerobat.plants import BUILT_IN, PLANTS

SRC = Path(__file__).resolve().parents[2] / "src" / "aerobat"
APPLICATION = ("experiments", "cli", "browse", "export")
NAMES = {name for name, _spec in PLANTS.items()}


def _plant_name(node: ast.AST) -> str | None:
    return node.value if isinstance(node, ast.Constant) and node.value in NAMES else None


def branches_on_plant_names(source: str) -> list[tuple[int, str]]:
    """(line, what) for each comparison with a plant's name and each literal list of two or more plants."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare):
            for side in (node.left, *node.comparators):
                name = _plant_name(side)
                if name is not None:
                    found.append((node.lineno, f"compares with the plant name {name!r}"))
        elif isinstance(node, ast.Tuple | ast.List | ast.Set):
            names = [n for n in map(_plant_name, node.elts) if n is not None]
            if len(names) >= 2:
                found.append((node.lineno, f"lists plants by name: {names}"))
    return found


def test_the_check_finds_a_branch_on_a_plant_name():
    assert branches_on_plant_names('if kind == "betaflight":\n    pass\n') == [
        (1, "compares with the plant name 'betaflight'")]
    assert branches_on_plant_names('ok = "arena" in choices\n')
    assert branches_on_plant_names('kinds = ("arena", "rotorpy")\n')
    assert not branches_on_plant_names('def f(plant="arena"):\n    return f"the {plant} plant"\n')


@pytest.mark.parametrize("package", APPLICATION)
def test_the_application_layer_never_branches_on_a_plant_name(package):
    assert len(NAMES) >= len(BUILT_IN) >= 5  # the built-ins, and any plant a test registered
    found = [f"{path.relative_to(SRC)}:{line}: {what}" for path in sorted((SRC / package).rglob("*.py"))
             for line, what in branches_on_plant_names(path.read_text())]
    assert not found, "ask the plant's spec instead:\n" + "\n".join(found)
