"""One docstring markup in the whole repository: reStructuredText (``code``, :class:`Name`), never
Markdown's single backticks, which reST reads as something else."""
from __future__ import annotations

import ast
import pathlib
import re

REPO = pathlib.Path(__file__).resolve().parents[3]
SINGLE_BACKTICKS = re.compile(r"(?<![`:])`[^`\n]+`(?![`_])")     # not ``code``, :role:`x`, nor `link`_
FILES = sorted(p for top in list(REPO.glob("crazyflie_*")) + [REPO / "bench", REPO / "tools"]
               for p in top.rglob("*.py") if ".ws" not in p.parts)


def _docstrings(path: pathlib.Path):
    tree = ast.parse(path.read_text(), str(path))
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                yield getattr(node, "lineno", 1), doc


def test_there_are_files_to_check():
    assert len(FILES) > 100


def test_docstrings_use_restructuredtext():
    wrong = ["%s:%d %s" % (path.relative_to(REPO), line, m.group(0))
             for path in FILES for line, doc in _docstrings(path) for m in SINGLE_BACKTICKS.finditer(doc)]
    assert wrong == [], "use ``code`` in docstrings, not `code`"
