"""One decision: the four answers' comparison (``kraby_study.decision.comparison.compare``) is
made in the answers and decision layers only, in one place per kind of study, and every other
module reads the comparison it is handed."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COMPARISON = "kraby_study.decision.comparison"
ALLOWED_LAYERS = ("kraby_study.answers", "kraby_study.decision")
PLACES = {
    "kraby_study.answers.seed_scores": "sweeps, confirm and single-run studies",
    "kraby_study.decision.front": "a two-objective search's front",
    "kraby_study.decision.race": "each look of a race",
}
"""The modules that call ``compare``, with the kind of study each compares."""


def module_name(path: Path) -> str:
    """A module's dotted name from its path under the repository."""
    return ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")


def compare_calls(source: str) -> int:
    """How many calls of ``compare`` (imported by name, or through the comparison module) the
    source makes."""
    tree = ast.parse(source)
    names, modules = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module == COMPARISON:
            names |= {a.asname or a.name for a in node.names if a.name == "compare"}
        elif isinstance(node, ast.ImportFrom) and node.module == "kraby_study.decision":
            modules |= {a.asname or a.name for a in node.names if a.name == "comparison"}
        elif isinstance(node, ast.Import):
            modules |= {a.asname for a in node.names if a.name == COMPARISON and a.asname}
    calls = 0
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        if isinstance(func, ast.Name) and func.id in names:
            calls += 1
        elif (isinstance(func, ast.Attribute) and func.attr == "compare"
              and ast.unparse(func.value) in modules | {COMPARISON}):
            calls += 1
    return calls


def callers(folder: Path) -> dict[str, int]:
    """Module -> its calls of ``compare``, for every module under ``folder`` that makes one."""
    found = {}
    for path in sorted(folder.rglob("*.py")):
        count = compare_calls(path.read_text(encoding="utf-8"))
        if count:
            found[module_name(path)] = count
    return found


def test_compare_is_called_in_the_answers_and_decision_layers_only() -> None:
    outside = [m for m in callers(ROOT / "kraby_study")
               if m != COMPARISON and not m.startswith(ALLOWED_LAYERS)]
    assert outside == [], f"compare() called outside the answers and decision layers: {outside}"


def test_compare_is_called_from_one_place_per_kind_of_study() -> None:
    found = callers(ROOT / "kraby_study")
    assert set(found) == set(PLACES), found
    assert all(count == 1 for count in found.values()), found


def test_the_scan_finds_every_spelling_of_a_call() -> None:
    spellings = [
        "from kraby_study.decision.comparison import compare\ncompare({}, 0.2)",
        "from kraby_study.decision.comparison import compare as judge\njudge({}, 0.2)",
        "from kraby_study.decision import comparison\ncomparison.compare({}, 0.2)",
        "import kraby_study.decision.comparison as c\nc.compare({}, 0.2)",
        "import kraby_study.decision.comparison\nkraby_study.decision.comparison.compare({}, 0)",
    ]
    assert [compare_calls(source) for source in spellings] == [1] * len(spellings)
    # Another function of the same name is not the comparison.
    assert compare_calls("def compare(a, b):\n    return a\ncompare(1, 2)") == 0
