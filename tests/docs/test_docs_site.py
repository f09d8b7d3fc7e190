"""The documentation site (issue 28): every public name documented, and `mkdocs build --strict` passes."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import mkdocs_hooks  # noqa: E402

import aerobat  # noqa: E402


def test_every_public_name_has_a_docstring():
    assert mkdocs_hooks.undocumented_names() == []


def test_the_hook_refuses_an_undocumented_public_name(monkeypatch):
    def undocumented() -> None:
        pass

    monkeypatch.setattr(aerobat, "undocumented", undocumented, raising=False)
    monkeypatch.setitem(aerobat._HOME, "undocumented", "aerobat.tests_fake")  # noqa: SLF001
    monkeypatch.setattr(aerobat, "__all__", [*aerobat.__all__, "undocumented"])
    assert mkdocs_hooks.undocumented_names() == ["undocumented"]
    from mkdocs.exceptions import PluginError

    with pytest.raises(PluginError, match="without a docstring.*undocumented"):
        mkdocs_hooks.on_config({})


def test_the_api_reference_lists_every_public_name():
    page = mkdocs_hooks.api_page()
    for name in aerobat.__all__:
        assert f"::: {aerobat._HOME[name]}.{name}\n" in page  # noqa: SLF001


@pytest.mark.skipif(importlib.util.find_spec("mkdocs") is None, reason="the docs extra (mkdocs) builds the site")
def test_mkdocs_build_strict_passes(tmp_path):
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    result = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                            cwd=ROOT, capture_output=True, text=True, timeout=600, env=env)
    assert result.returncode == 0, result.stderr[-3000:]
    api = (tmp_path / "site" / "reference" / "api" / "index.html").read_text()
    assert "start_session" in api and "Store" in api
    tutorial = (tmp_path / "site" / "tutorial" / "index.html").read_text()
    assert "off by" in tutorial and tutorial.count("<img") >= 2  # executed, with its two figures
    assert not (ROOT / "docs" / "my_vehicle.toml").exists()
