"""Every Python example a reader can copy runs: the ```python blocks of README.md and of each
page under docs/, and the examples in the API's docstrings.

A page's blocks run in order in one fresh process and an empty working folder, as a notebook
would run them. A block preceded by the line ``<!-- test: slow -->`` (invisible on the page)
runs in the slow tier only, with every block of its page; the fast tier runs the others.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SLOW_MARK = "<!-- test: slow -->"
BLOCK = re.compile(r"^(?P<mark><!-- test: slow -->\n)?```python\n(?P<code>.*?)^```\s*$",
                   re.MULTILINE | re.DOTALL)


def pages() -> list[Path]:
    """README.md and every Markdown page under docs/ that holds a Python block."""
    found = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    return [p for p in found if "```python" in p.read_text(encoding="utf-8")]


def blocks(page: Path) -> list[tuple[str, bool]]:
    """(code, slow) of each Python block of a page, in order."""
    return [(m["code"], m["mark"] is not None)
            for m in BLOCK.finditer(page.read_text(encoding="utf-8"))]


def run_python(code: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """Run code in a fresh interpreter in ``cwd``, without a display."""
    env = dict(os.environ, MPLBACKEND="Agg")
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True,
                          text=True, env=env)


def check(page: Path, code: str, cwd: Path) -> None:
    done = run_python(code, cwd)
    assert done.returncode == 0, (f"{page.relative_to(ROOT)}'s Python examples failed:\n"
                                  f"{done.stdout[-3000:]}\n{done.stderr[-5000:]}")


@pytest.mark.parametrize("page", [p for p in pages() if not all(s for _, s in blocks(p))],
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_the_fast_examples_of_a_page_run(page: Path, tmp_path: Path) -> None:
    code = "\n".join(code for code, slow in blocks(page) if not slow)
    check(page, code, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("page", [p for p in pages() if any(s for _, s in blocks(p))],
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_every_example_of_a_page_runs(page: Path, tmp_path: Path) -> None:
    check(page, "\n".join(code for code, _ in blocks(page)), tmp_path)


def test_the_block_reader_finds_blocks_and_their_marks(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text("text\n```python\nx = 1\n```\n\n" + SLOW_MARK
                    + "\n```python\ny = x\n```\n```bash\nls\n```\n")
    assert blocks(page) == [("x = 1\n", False), ("y = x\n", True)]


def test_a_failing_example_fails_the_test(tmp_path: Path) -> None:
    with pytest.raises(AssertionError, match="ZeroDivisionError"):
        check(ROOT / "README.md", "1 / 0", tmp_path)


DOCTESTED = ["kraby_study.api.config", "kraby_study.api.answers", "kraby_study.api",
             "kraby_study", "kraby_study.api.dry_run"]
"""Docstring examples that train nothing; the others read the store the training ones write."""
TRAINING = ["kraby_study.api.run", "kraby_study.api.store", "kraby_study.api.settings_files",
            "kraby_study.api.report", "kraby_study.api.optuna_search",
            "kraby_study.api.fresh_seeds"]


def doctests(modules: list[str], cwd: Path) -> None:
    """Run the docstring examples of ``modules``, in order, in one process in ``cwd``."""
    code = ("import doctest, importlib, sys\n"
            f"failed = sum(doctest.testmod(importlib.import_module(m)).failed for m in "
            f"{modules!r})\nsys.exit(1 if failed else 0)")
    done = run_python(code, cwd)
    assert done.returncode == 0, done.stdout[-5000:] + done.stderr[-3000:]


def test_the_api_docstring_examples_run(tmp_path: Path) -> None:
    doctests(DOCTESTED, tmp_path)


@pytest.mark.slow
def test_the_api_docstring_examples_that_train_run(tmp_path: Path) -> None:
    doctests(TRAINING, tmp_path)


def test_every_module_of_the_api_has_its_examples_tested() -> None:
    modules = {f"kraby_study.api.{p.stem}" for p in (ROOT / "kraby_study" / "api").glob("*.py")
               if p.stem not in ("__init__", "outcome")}
    assert modules <= set(DOCTESTED) | set(TRAINING)
