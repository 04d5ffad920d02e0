"""One docstring markup in the whole repository: reStructuredText (``code``, :class:`Name`), never
Markdown's single backticks, which reST reads as something else."""
from __future__ import annotations

import ast
import pathlib
import re

REPO = pathlib.Path(__file__).resolve().parents[3]
SINGLE_BACKTICKS = re.compile(r"(?<![`:])`[^`\n]+`(?![`_])")     # not ``code``, :role:`x`, nor `link`_
ROLE = re.compile(r":[\w:+-]+:`[^`\n]+`")                          # :class:`x`, read before the above
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
             for path in FILES for line, doc in _docstrings(path)
             for m in SINGLE_BACKTICKS.finditer(ROLE.sub("ROLE", doc))]
    assert wrong == [], "use ``code`` in docstrings, not `code`"


# A Python-domain role followed by anything but one single-backticked target: :class:'x',
# :class: `x`, :func:x and :meth:``x`` all render as plain text (or warnings), not as a link.
PY_ROLE = r":(?:py:)?(?:class|func|meth|attr|mod|data|const|exc|obj|ref|doc|term):"
MALFORMED_ROLE = re.compile(PY_ROLE + r"(?!`[^`\s][^`]*`(?!`))\S*")


def test_roles_are_wellformed():
    wrong = ["%s:%d %s" % (path.relative_to(REPO), line, m.group(0))
             for path in FILES for line, doc in _docstrings(path) for m in MALFORMED_ROLE.finditer(doc)]
    assert wrong == [], "write a role as :class:`Name` (one pair of single backticks, no space)"


def test_malformed_roles_are_caught():
    for bad in (":class:'Name'", ":class: `Name`", ":func:name", ":meth:``name``", ":class:` Name`"):
        assert MALFORMED_ROLE.search(bad), bad
    for good in (":class:`Name`", ":meth:`~pkg.mod.Cls.meth`", ":py:func:`f`", ":param x: the value"):
        assert not MALFORMED_ROLE.search(good), good


# Dotted paths into the package written in docstrings (``crazyflie_driver.server.worker``,
# ``sim.world_server.WorldServer``) must name modules that exist: the tree moves, the prose must follow.
SRC = REPO / "crazyflie_driver" / "src" / "crazyflie_driver"
MODULE_PATH = re.compile(r"(?<![\w.])(?:crazyflie_driver\.(?!msg\b|srv\b)((?:\w+\.)*\w+)|(sim(?:\.\w+)+))")
NOT_MODULES = {"launch", "py", "yaml", "test", "md", "txt"}      # file names such as sim.launch


def _resolves(dotted: str) -> bool:
    """Packages while there are packages, then a module; what follows a module is an attribute."""
    parts = dotted.split(".")
    if parts[-1] in NOT_MODULES:
        return True
    here = SRC
    for part in parts:
        if (here / part / "__init__.py").exists():
            here = here / part
        elif (here / (part + ".py")).exists():
            return True
        else:    # an attribute of the package itself (its __init__ defines or imports it)
            init = (here / "__init__.py").read_text()
            return here != SRC and re.search(r"\b%s\b" % re.escape(part), init) is not None
    return True


def test_module_paths_in_docstrings_exist():
    wrong = ["%s:%d %s" % (path.relative_to(REPO), line, m.group(0))
             for path in FILES for line, doc in _docstrings(path) for m in MODULE_PATH.finditer(doc)
             if not _resolves(m.group(1) or m.group(2))]
    assert wrong == [], "a docstring names a module that does not exist (moved?)"


def test_stale_module_paths_are_caught():
    for stale in ("sim.server.WorldServer", "sim.mocap.MocapModel", "crazyflie_driver.sim.fake_usb"):
        m = MODULE_PATH.search(stale)
        assert m and not _resolves(m.group(1) or m.group(2)), stale
    for live in ("sim.world_server.WorldServer", "crazyflie_driver.server.worker", "sim.launch"):
        m = MODULE_PATH.search(live)
        assert m and _resolves(m.group(1) or m.group(2)), live
