"""Generate one reference page per package of kraby_study while the site builds.

An MkDocs hook (``hooks:`` in mkdocs.yml): it lists every module under kraby_study/ from the
files themselves and adds reference/api/modules/<package>.md, whose ``:::`` blocks mkdocstrings
renders from the docstrings. A module a hand-written page already renders (a ``:::`` line in
docs/) is left to that page. So every module is on the site, and a docstring's cross-reference
to a module, class or function that does not exist fails the strict build. A package whose page
the navigation does not list fails it too (``omitted_files`` in mkdocs.yml).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = "kraby_study"
FOLDER = "reference/api/modules"
RENDERED = re.compile(r"^:::\s+(\S+)", re.MULTILINE)

# A package's own entry renders its docstring only: the names it re-exports are rendered where
# they are defined, once.
PACKAGE_OPTIONS = "    options:\n      members: false\n"
# Every public member, documented or not, so a cross-reference to any of them resolves; no
# private or special member (``__init__`` says nothing a dataclass's fields do not).
MODULE_OPTIONS = ('    options:\n      show_if_no_docstring: true\n      filters: ["!^_"]\n')


def module_name(path: Path) -> str:
    """The dotted name of a module file under the repository root."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def packages(root: Path = ROOT) -> dict[str, list[str]]:
    """Each package of kraby_study with its modules, the package itself first; kraby_study's
    own modules (cli, errors) under kraby_study."""
    found: dict[str, list[str]] = {}
    for path in sorted((root / PACKAGE).rglob("*.py")):
        name = module_name(path)
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        found.setdefault(package, []).append(name)
    return {package: sorted(names, key=lambda n: (n != package, n))
            for package, names in sorted(found.items())}


def rendered_elsewhere(docs: Path) -> set[str]:
    """The modules a hand-written page renders with a ``:::`` line."""
    return {name for page in docs.rglob("*.md") for name in RENDERED.findall(page.read_text())}


def render(package: str, modules: list[str], elsewhere: set[str]) -> str:
    """The page of one package: a ``:::`` block for each module no other page renders."""
    lines = [f"# {package}", ""]
    for name in modules:
        if name in elsewhere:
            lines += [f"`{name}` is on its own page: [`{name}`][].", ""]
            continue
        options = PACKAGE_OPTIONS if name == package else MODULE_OPTIONS
        lines += [f"::: {name}", options]
    return "\n".join(lines)


def pages(docs: Path, root: Path = ROOT) -> dict[str, str]:
    """Each generated page's path under docs/, with its Markdown."""
    elsewhere = rendered_elsewhere(docs)
    return {f"{FOLDER}/{package}.md": render(package, modules, elsewhere)
            for package, modules in packages(root).items()
            if any(name not in elsewhere for name in modules)}


def on_files(files: Any, config: Any) -> Any:
    """Add the package pages to the site (MkDocs calls this once the docs are read)."""
    from mkdocs.structure.files import File

    for path, content in pages(Path(config["docs_dir"])).items():
        files.append(File.generated(config, path, content=content))
    return files
