"""The data flows one way: every module imports only from its own layer or the layers below.

The layer order is written here and in docs/reference/architecture.md ("Layers"); keep the two
alike.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = {"kraby_study": ROOT / "kraby_study", "kraby_envs": ROOT / "envs"}

LAYERS: list[tuple[str, tuple[str, ...]]] = [
    ("envs", ("kraby_envs",)),
    ("records", ("kraby_study.errors", "kraby_study.records", "kraby_study.store.url")),
    ("env", ("kraby_study.env",)),
    ("config", ("kraby_study.config",)),
    ("plan", ("kraby_study.plan",)),
    ("store", ("kraby_study.store",)),
    ("decision", ("kraby_study.decision",)),
    ("answers", ("kraby_study.answers",)),
    ("run", ("kraby_study.run",)),
    ("report", ("kraby_study.report",)),
    ("api", ("kraby_study.api",)),
    ("cli", ("kraby_study.cli",)),
]
"""Bottom to top. A module belongs to the layer of its longest matching prefix; the package's
own ``__init__`` to the top."""


def layer_of(module: str) -> int:
    """Index in LAYERS of a module's layer."""
    if module == "kraby_study":
        return len(LAYERS) - 1
    best, length = -1, -1
    for index, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > length:
                best, length = index, len(prefix)
    assert best >= 0, (f"{module} is in no layer: add it to LAYERS and "
                       "docs/reference/architecture.md")
    return best


def modules() -> dict[str, Path]:
    """Every module of the two packages, by dotted name."""
    found = {}
    for package, folder in PACKAGES.items():
        for path in folder.rglob("*.py"):
            parts = path.relative_to(folder).with_suffix("").parts
            name = ".".join((package, *parts))
            found[name.removesuffix(".__init__")] = path
    return found


def _is_module(name: str) -> bool:
    """Whether a dotted name of our packages is a module or package (a file or folder)."""
    head, *rest = name.split(".")
    if head not in PACKAGES:
        return False
    where = PACKAGES[head].joinpath(*rest)
    return where.with_suffix(".py").is_file() or (where / "__init__.py").is_file()


def imports(path: Path, module: str) -> list[tuple[str, int, bool]]:
    """(imported module, line, at module level) for each import of our packages in a file,
    wherever it stands (inside functions and TYPE_CHECKING blocks too)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    top = {id(node) for node in tree.body}
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    found = []
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")
                base = ".".join(parent[: len(parent) - node.level + 1] + ([base] if base else []))
            # ``from package import module`` imports the module, not the package's face.
            names = [f"{base}.{alias.name}" if _is_module(f"{base}.{alias.name}") else base
                     for alias in node.names]
        for name in dict.fromkeys(names):
            if name.split(".")[0] in PACKAGES:
                found.append((name, node.lineno, id(node) in top))
    return found


def test_every_module_imports_only_its_own_layer_or_below() -> None:
    upward = []
    for module, path in sorted(modules().items()):
        own = layer_of(module)
        for imported, line, _ in imports(path, module):
            if layer_of(imported) > own:
                upward.append(f"{path.relative_to(ROOT)}:{line} ({LAYERS[own][0]}) imports "
                              f"{imported} ({LAYERS[layer_of(imported)][0]})")
    assert not upward, "imports that run upward:\n" + "\n".join(upward)


def test_only_the_env_seam_imports_the_leg() -> None:
    """Every use of an environment goes through kraby_study.env (docs/guide/environments.md)."""
    direct = [f"{path.relative_to(ROOT)}:{line}"
              for module, path in modules().items()
              if module.startswith("kraby_study.") and not module.startswith("kraby_study.env")
              for name, line, _ in imports(path, module) if name.split(".")[0] == "kraby_envs"]
    assert not direct, "kraby_envs imported outside the env seam:\n" + "\n".join(direct)


def test_the_store_imports_at_module_level_only() -> None:
    """A function-level import inside store/ would hide a cycle between its modules."""
    hidden = [f"{path.relative_to(ROOT)}:{line} imports {name}"
              for module, path in modules().items() if module.startswith("kraby_study.store")
              for name, line, at_top in imports(path, module) if not at_top]
    assert not hidden, "\n".join(hidden)


def test_the_layer_test_catches_an_upward_import(tmp_path: Path) -> None:
    module = tmp_path / "ledger.py"
    module.write_text("def f():\n    from kraby_study.run.runner import CommandRun\n")
    found = imports(module, "kraby_study.store.ledger")
    assert found == [("kraby_study.run.runner", 2, False)]
    assert layer_of("kraby_study.run.runner") > layer_of("kraby_study.store.ledger")
    assert layer_of("kraby_study.store.url") < layer_of("kraby_study.config.validate")


PURE = ["kraby_study.config.compose", "kraby_study.config.validate", "kraby_study.config.winner",
        "kraby_study.plan.sweep", "kraby_study.plan.space", "kraby_study.plan.confirm",
        "kraby_study.plan.campaign", "kraby_study.plan.train", "kraby_study.cli",
        "kraby_study"]
HEAVY = ["optuna", "sqlalchemy", "scipy", "pandas", "torch", "stable_baselines3", "matplotlib"]


@pytest.mark.parametrize("module", PURE)
def test_composing_and_planning_load_no_database_optuna_or_statistics(module: str) -> None:
    code = (f"import sys, {module}; "
            f"print(','.join(m for m in {HEAVY!r} if m in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True).stdout.strip()
    assert loaded == "", f"importing {module} loads {loaded}"


def test_reading_where_studies_stand_loads_no_optuna_hydra_pandas_or_scipy_stats() -> None:
    """``list`` reads every study's standing: the statistics stack loads only where a rule
    tests (fastest_tied) or curves are read (auc, the report); the store is read without
    Optuna, and a plain storage URL without Hydra."""
    code = ("import sys, kraby_study.answers.standing, kraby_study.config.storage, "
            "kraby_study.cli; print(','.join(m for m in ('pandas', 'scipy.stats', 'optuna', "
            "'hydra') if m in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True).stdout.strip()
    assert loaded == "", f"answers.standing loads {loaded}"


def import_cycles() -> list[list[str]]:
    """Every group of modules that import each other in a loop (strongly connected components of
    the import graph, imports inside functions counted), largest first."""
    known = modules()
    graph = {module: sorted({name for name, _, _ in imports(path, module) if name in known
                             and name != module})
             for module, path in known.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(module: str) -> None:  # Tarjan's algorithm
        index[module] = low[module] = len(index)
        stack.append(module)
        for name in graph[module]:
            if name not in index:
                visit(name)
                low[module] = min(low[module], low[name])
            elif name in stack:
                low[module] = min(low[module], index[name])
        if low[module] == index[module]:
            group = []
            while True:
                top = stack.pop()
                group.append(top)
                if top == module:
                    break
            if len(group) > 1:
                cycles.append(sorted(group))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return sorted(cycles, key=len, reverse=True)


def test_no_modules_import_each_other_in_a_loop() -> None:
    """A loop of imports (env's adapters and their registry, say) hides which module is the
    lower one; the registry stands apart from the adapters (docs/reference/architecture.md)."""
    assert import_cycles() == []


def test_the_cycle_finder_finds_a_loop(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    first, second = tmp_path / "first.py", tmp_path / "second.py"
    first.write_text("from kraby_study.second import x\n")
    second.write_text("def f():\n    from kraby_study.first import y\n")
    monkeypatch.setattr(sys.modules[__name__], "modules",
                        lambda: {"kraby_study.first": first, "kraby_study.second": second})
    assert import_cycles() == [["kraby_study.first", "kraby_study.second"]]
