"""Generate the configuration reference from the typed schema while the site builds.

An MkDocs hook (``hooks:`` in mkdocs.yml): it reads the dataclasses of
``kraby_study.config.schema`` (their fields, types and defaults from ``dataclasses.fields``, each
field's docstring from the source with ``ast``) and adds reference/configuration.md to the site,
so the page cannot drift from the schema Hydra composes into.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import re
import typing
from typing import Any

from omegaconf import MISSING

PAGE = "reference/configuration.md"

INTRO = """# Configuration

Every key a command accepts, generated from the typed schema
(`kraby_study/config/schema.py`) each time this site is built. A key is set on the command
line as `key=value` (for example `ppo.learning_rate=3e-4`), or in a YAML file of the config tree
([studies](../guide/studies.md#the-config-tree-and-a-study-of-your-own)). A misspelt key or a
value of the wrong type is refused when the config is composed, before anything runs.

"Required" marks a key with no default: the chosen option or the study file sets it.
"""

# (heading, key prefix, dataclass name): the order a reader meets the groups in.
SECTIONS = [
    ("Top level", "", "KrabyConfig"),
    ("env=leg: the simulated leg", "env.", "LegEnvConfig"),
    ("env=gym: any Gymnasium id", "env.", "GymEnvConfig"),
    ("ppo: PPO's settings", "ppo.", "PPOConfig"),
    ("budget: steps, seeds and curve points", "budget.", "BudgetConfig"),
    ("study: a sweep of one parameter", "study.", "StudyConfig"),
    ("search: an Optuna search", "search.", "SearchConfig"),
    ("search.params: one searched parameter", "search.params.NAME.", "ParamSpace"),
    ("report: the report's statistics", "report.", "ReportConfig"),
    ("compare: the answers against the best", "compare.", "CompareConfig"),
    ("racing: dropping values between seeds", "racing.", "RacingConfig"),
    ("confirm: fresh seeds for the top configurations", "confirm.", "ConfirmConfig"),
    ("campaign: studies chained by their winners", "campaign.", "CampaignConfig"),
    ("campaign.stages: one stage", "campaign.stages[i].", "StageConfig"),
    ("ray: the Ray executor", "ray.", "RayConfig"),
]


def field_docstrings(module: Any) -> dict[str, dict[str, str]]:
    """Each dataclass's field docstrings (the string literal under a field), by class and field."""
    tree = ast.parse(inspect.getsource(module))
    found: dict[str, dict[str, str]] = {}
    for node in tree.body:
        if not isinstance(node, ast.ClassDef):
            continue
        docs: dict[str, str] = {}
        body = node.body
        for current, following in zip(body, body[1:], strict=False):
            if (
                isinstance(current, ast.AnnAssign)
                and isinstance(current.target, ast.Name)
                and isinstance(following, ast.Expr)
                and isinstance(following.value, ast.Constant)
                and isinstance(following.value.value, str)
            ):
                docs[current.target.id] = inspect.cleandoc(following.value.value)
        found[node.name] = docs
    return found


def type_text(annotation: Any) -> str:
    """A field's type as a reader writes it (``int or None``, ``list[int]``)."""
    text = annotation if isinstance(annotation, str) else getattr(annotation, "__name__", "")
    # A table cell cannot hold "|", even in code: "int | None" reads "int or None".
    return (text or str(annotation)).replace(" | ", " or ")


def default_text(field: dataclasses.Field) -> str:
    """A field's default as YAML would show it; "required" when it has none."""
    if field.default is not dataclasses.MISSING:
        value = field.default
    elif field.default_factory is not dataclasses.MISSING:
        value = field.default_factory()
    else:
        return "required"
    if value is MISSING:
        return "required"
    if dataclasses.is_dataclass(value):
        return "(the group below)"
    if value is None:
        return "`null`"
    if value == "":
        return '`""`'
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    return f"`{value!r}`" if not isinstance(value, str) else f"`{value}`"


def is_group(hint: Any) -> bool:
    """Whether a field holds a schema dataclass (alone or with None): a group of its own."""
    return dataclasses.is_dataclass(hint) or any(
        dataclasses.is_dataclass(arg) for arg in typing.get_args(hint)
    )


def plain(text: str) -> str:
    """Docstring markup as plain Markdown: ``code`` and cross-references become `code`."""
    text = re.sub(r"\[(`[^`]+`)\]\[[^\]]*\]", r"\1", text)
    return text.replace("``", "`")


def cell(text: str) -> str:
    """Text made safe for one Markdown table cell."""
    return " ".join(plain(text).replace("|", "\\|").split())


def render_class(schema: Any, prefix: str, cls: type, docs: dict[str, str]) -> list[str]:
    """One table: every field of ``cls`` with its full key, type, default and description."""
    hints = typing.get_type_hints(cls, vars(schema))
    lines = ["| key | type | default | meaning |", "|---|---|---|---|"]
    raw = {f.name: f.type for f in dataclasses.fields(cls)}
    for field in dataclasses.fields(cls):
        meaning = docs.get(field.name, "")
        if not meaning and is_group(hints.get(field.name)):
            meaning = f"The `{field.name}` group (below)."
        lines.append(
            f"| `{prefix}{field.name}` | {cell(type_text(raw[field.name]))} "
            f"| {cell(default_text(field))} | {cell(meaning)} |"
        )
    return lines


def render(schema: Any) -> str:
    """The whole page, from the schema module; a schema dataclass left out of SECTIONS fails
    the build, so a new group cannot go unlisted."""
    groups = {name for name, value in vars(schema).items()
              if dataclasses.is_dataclass(value) and value.__module__ == schema.__name__}
    missing = sorted(groups - {name for _, _, name in SECTIONS})
    if missing:
        raise ValueError(f"docs/hooks/config_reference.py: add {', '.join(missing)} to SECTIONS")
    docs = field_docstrings(schema)
    lines = [INTRO]
    for heading, prefix, name in SECTIONS:
        cls = getattr(schema, name)
        lines += [f"## {heading}", ""]
        summary = inspect.cleandoc(cls.__doc__ or "")
        if summary:
            lines += [plain(summary), ""]
        lines += render_class(schema, prefix, cls, docs.get(name, {}))
        lines.append("")
    return "\n".join(lines)


def on_files(files: Any, config: Any) -> Any:
    """MkDocs event: add the generated page to the site's files."""
    from mkdocs.structure.files import File

    from kraby_study.config import schema

    files.append(File.generated(config, PAGE, content=render(schema)))
    return files
