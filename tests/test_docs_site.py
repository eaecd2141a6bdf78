"""The documentation site builds with no warning: every page, link and anchor resolves.

`mkdocs build --strict` turns each warning into a failure; mkdocs.yml's `validation` block makes
a link to a missing page or a missing anchor a warning, and the configuration page is generated
from the schema while building (docs/hooks/config_reference.py).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]

pytest.importorskip("mkdocs")
pytest.importorskip("material")
pytest.importorskip("mkdocstrings_handlers.python")


def build(config: Path, site: Path) -> subprocess.CompletedProcess[str]:
    """Run `mkdocs build --strict` on a config file into `site`."""
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(config),
         "--site-dir", str(site)],
        capture_output=True, text=True, cwd=config.parent,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )


def test_site_builds_strict(tmp_path: Path) -> None:
    result = build(ROOT / "mkdocs.yml", tmp_path / "site")
    warnings = [line for line in result.stderr.splitlines() if "WARNING" in line]
    assert result.returncode == 0 and not warnings, result.stderr
    configuration = (tmp_path / "site/reference/configuration/index.html").read_text()
    assert "ppo.learning_rate" in configuration and "compare.margin" in configuration
    api = (tmp_path / "site/reference/api/records/index.html").read_text()
    assert "StoredTrial" in api


def test_broken_anchor_fails_the_build(tmp_path: Path) -> None:
    """The same validation settings on a two-page site: a link to a missing anchor fails."""
    settings = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "index.md").write_text("# Home\n\nSee [the section](other.md#no-such-section).\n")
    (docs / "other.md").write_text("# Other\n\n## A section\n")
    config = tmp_path / "mkdocs.yml"
    config.write_text(yaml.safe_dump({
        "site_name": "anchors", "strict": True, "validation": settings["validation"],
    }))
    result = build(config, tmp_path / "site")
    assert result.returncode != 0
    assert "does not contain an anchor '#no-such-section'" in result.stderr


def test_readme_links_resolve() -> None:
    """The README is read on its own, outside the site: each relative link names a file."""
    text = (ROOT / "README.md").read_text()
    targets = re.findall(r"\]\(([^)\s]+)\)", text)
    missing = [
        target for target in targets
        if not re.match(r"[a-z]+:", target)
        and not target.startswith("reports/")  # drawn by the main job, not committed
        and not (ROOT / target.split("#")[0]).exists()
    ]
    assert targets and not missing, missing


def test_configuration_page_lists_every_schema_group(monkeypatch: pytest.MonkeyPatch) -> None:
    """The generated page covers each field of each schema dataclass, and refuses to build
    when a new dataclass is not given a section."""
    import dataclasses
    import importlib.util

    from kraby_study.config import schema

    spec = importlib.util.spec_from_file_location(
        "config_reference", ROOT / "docs/hooks/config_reference.py")
    assert spec is not None and spec.loader is not None
    hook = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hook)
    page = hook.render(schema)
    for _, prefix, name in hook.SECTIONS:
        for field in dataclasses.fields(getattr(schema, name)):
            assert f"`{prefix}{field.name}`" in page

    @dataclasses.dataclass
    class Unlisted:
        size: int = 1

    Unlisted.__module__ = schema.__name__
    monkeypatch.setattr(schema, "Unlisted", Unlisted, raising=False)
    with pytest.raises(ValueError, match="add Unlisted to SECTIONS"):
        hook.render(schema)


def load_hook(name: str):
    """A hook of docs/hooks/ as a module."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, ROOT / f"docs/hooks/{name}.py")
    assert spec is not None and spec.loader is not None
    hook = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hook)
    return hook


def nav_pages(nav: object) -> list[str]:
    """Every page path the navigation lists, however deep."""
    if isinstance(nav, str):
        return [nav]
    if isinstance(nav, dict):
        return [page for value in nav.values() for page in nav_pages(value)]
    if isinstance(nav, list):
        return [page for item in nav for page in nav_pages(item)]
    return []


def test_every_module_is_rendered_and_listed() -> None:
    """Each module of kraby_study is rendered by a ``:::`` block, on a hand-written page or on its
    package's generated page, and the navigation lists every generated page."""
    hook = load_hook("module_reference")
    docs = ROOT / "docs"
    pages = hook.pages(docs)
    rendered = set(hook.rendered_elsewhere(docs))
    for content in pages.values():
        rendered |= set(hook.RENDERED.findall(content))
    modules = {hook.module_name(path) for path in (ROOT / "kraby_study").rglob("*.py")}
    assert modules and not modules - rendered, sorted(modules - rendered)
    settings = yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=yaml.BaseLoader)
    assert set(pages) <= set(nav_pages(settings["nav"])), sorted(
        set(pages) - set(nav_pages(settings["nav"])))
    assert "docs/hooks/module_reference.py" in settings["hooks"]


def test_docstrings_hold_no_sphinx_roles() -> None:
    """A Sphinx role (``:func:`x` ``) renders as plain text on the site: cross-references are
    written for mkdocstrings (``[`x`][kraby_study.module.x]``), which the strict build checks."""
    role = re.compile(r":(?:class|func|mod|data|attr|meth|exc|obj):`")
    found = [f"{path.relative_to(ROOT)}:{number}"
             for path in sorted((ROOT / "kraby_study").rglob("*.py"))
             for number, line in enumerate(path.read_text().splitlines(), 1)
             if role.search(line)]
    assert not found, found
