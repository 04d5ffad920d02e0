"""How tests and benches find what they import: nobody edits ``sys.path`` by hand.

The tests' helper packages (``support`` in crazyflie_driver/test, ``controller_support`` in
crazyflie_controller/test) are on PYTHONPATH through the devel space's environment hooks (each
package's ``env-hooks/``, registered in its CMakeLists.txt), so pytest, the rostest nodes and every
child process they start import them as they import ``crazyflie_driver``. The benches take their
paths from ``bench/bench_support.py``, the one place that sets them up, so a bench runs without the
devel space sourced too.
"""
from __future__ import annotations

import importlib.util
import pathlib
import re
from typing import List

REPO = pathlib.Path(__file__).resolve().parents[3]
BENCH_SUPPORT = REPO / "bench" / "bench_support.py"
# Changing the import path: sys.path assigned, sliced into or grown, a site directory added. Read as
# text, so a program handed to a child process (``python -c "..."``) counts as well.
PATH_EDIT = re.compile(r"sys\.path\s*(\[[^\]]*\]\s*)?(\+?=[^=]|\.(insert|append|extend|remove|pop|clear)\b)"
                       r"|site\.addsitedir")


def _python_files() -> List[pathlib.Path]:
    """The tests' files (unit, rostest nodes, support, conftests), the benches, the root conftest."""
    files = [REPO / "conftest.py"]
    for package in sorted(REPO.glob("crazyflie_*/test")):
        files += sorted(package.rglob("*.py"))
    files += sorted((REPO / "bench").rglob("*.py"))
    return [f for f in files if f not in (BENCH_SUPPORT, pathlib.Path(__file__).resolve())]   # this one: examples


def _path_edits(text: str) -> List[str]:
    return [line.strip() for line in text.splitlines() if PATH_EDIT.search(line)]


def test_the_pattern_knows_a_path_edit_from_a_read():
    edits = ["sys.path.insert(0, os.path.join(HERE, '..'))", "sys.path[:0] = [src, test]", "sys.path.append(d)",
             "sys.path += [d]", "sys.path = [d] + sys.path", "site.addsitedir(d)",
             'run([python, "-c", "import sys; sys.path.insert(0, %r); import x" % d])']
    reads = ["env = dict(PYTHONPATH=os.pathsep.join(sys.path))", "if d not in sys.path:", "sys.path == before",
             "print(sys.path[0])"]
    assert [e for e in edits if not _path_edits(e)] == []
    assert [r for r in reads if _path_edits(r)] == []


def test_no_test_or_bench_edits_sys_path():
    files = _python_files()
    assert len(files) > 100                       # the globs found the tests
    found = {str(f.relative_to(REPO)): _path_edits(f.read_text(errors="ignore")) for f in files}
    assert {f: lines for f, lines in found.items() if lines} == {}, (
        "import the tests' helpers (`support`, `controller_support`) as they are: the devel space's environment "
        "hooks put them on PYTHONPATH (source tools/env.sh); a bench imports bench_support first")


def test_every_python_bench_imports_bench_support():
    benches = sorted((REPO / "bench").glob("bench_*.py"))
    assert len(benches) > 10
    missing = [b.name for b in benches if b != BENCH_SUPPORT
               and not re.search(r"^(import bench_support|from bench_support import)", b.read_text(), re.M)]
    assert missing == []


def test_the_helper_packages_come_from_this_checkout():
    """Through the environment hooks of this checkout's devel space, not another checkout's."""
    for name, package in (("support", "crazyflie_driver"), ("controller_support", "crazyflie_controller")):
        spec = importlib.util.find_spec(name)
        assert spec is not None and spec.origin is not None, name
        assert pathlib.Path(spec.origin).resolve() == REPO / package / "test" / name / "__init__.py"
