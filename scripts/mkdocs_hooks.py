"""mkdocs hooks for aerobat's site: the API reference page, and a build that fails on undocumented names.

``on_config`` refuses to build when a public name of ``aerobat`` (its ``__all__``), or a public
method or property of a public class, has no docstring. ``on_files`` adds ``reference/api.md``:
every public name, grouped by the module it lives in, rendered by mkdocstrings from its docstring,
so the reference cannot drift from the code.
"""

from __future__ import annotations

import inspect
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

_LAYER_TITLES = {
    "aerobat.core": "The method (aerobat.core)",
    "aerobat.quadrotor": "The vehicle (aerobat.quadrotor)",
    "aerobat.plants": "Plants (aerobat.plants)",
    "aerobat.store": "The experiment store (aerobat.store)",
    "aerobat.experiments": "Sessions, studies, identification (aerobat.experiments)",
}


def undocumented_names() -> list[str]:
    """Public names of ``aerobat`` (and public members of its public classes) without a docstring."""
    import aerobat

    missing = []
    for name in aerobat.__all__:
        obj = getattr(aerobat, name)
        if not (inspect.getdoc(obj) or "").strip():
            missing.append(name)
        if inspect.isclass(obj):
            for member, value in vars(obj).items():
                if member.startswith("_"):
                    continue
                target = value.fget if isinstance(value, property) else getattr(value, "__func__", value)
                if (callable(target) or isinstance(value, property)) and not (target.__doc__ or "").strip():
                    missing.append(f"{name}.{member}")
    return missing


def api_page() -> str:
    import aerobat

    by_layer: dict[str, list[tuple[str, str]]] = defaultdict(list)
    for name in aerobat.__all__:
        module = aerobat._HOME[name]  # noqa: SLF001 - the lazy table is the one list of homes
        layer = ".".join(module.split(".")[:2])
        by_layer[layer].append((module, name))
    lines = ["# API reference", "",
             "Every name `from aerobat import …` offers, rendered from its docstring and grouped by layer",
             "(docs/architecture.md). The layers' own modules hold more; these are the entry points.", ""]
    for layer, title in _LAYER_TITLES.items():
        if layer not in by_layer:
            continue
        lines += [f"## {title}", ""]
        for module, name in sorted(by_layer.pop(layer), key=lambda x: (x[0], x[1])):
            lines += [f"::: {module}.{name}", "    options:", "      heading_level: 3", ""]
    if by_layer:
        raise RuntimeError(f"public names in layers the reference does not know: {dict(by_layer)}")
    return "\n".join(lines)


def on_config(config: Any, **_: Any) -> Any:
    from mkdocs.exceptions import PluginError

    missing = undocumented_names()
    if missing:
        raise PluginError(f"public names without a docstring ({len(missing)}): {', '.join(missing)}")
    return config


def on_files(files: Any, config: Any, **_: Any) -> Any:
    from mkdocs.structure.files import File

    files.append(File.generated(config, "reference/api.md", content=api_page()))
    return files


def main() -> int:
    """``python scripts/mkdocs_hooks.py``: list the public names without a docstring (what the site build refuses)."""
    missing = undocumented_names()
    for name in missing:
        print(f"undocumented: {name}")
    print(f"{len(missing)} public names without a docstring")
    return 1 if missing else 0


if __name__ == "__main__":
    raise SystemExit(main())
