"""docs/architecture.md's module map against the tree: every module of the driver and controller
packages listed, and nothing listed that is gone, so the map stays the place to look things up."""
from __future__ import annotations

import pathlib
import re
from typing import Dict, Set

REPO = pathlib.Path(__file__).resolve().parents[3]
MAP = REPO / "docs" / "architecture.md"
# Package roots and the prefix their modules carry in the map (the driver's go without one).
PACKAGES: Dict[pathlib.Path, str] = {
    REPO / "crazyflie_driver" / "src" / "crazyflie_driver": "",
    REPO / "crazyflie_controller" / "src" / "crazyflie_controller": "crazyflie_controller.",
}


def modules_in_tree() -> Set[str]:
    """Every module but the packages' __init__ files, dotted from its package root."""
    return {prefix + ".".join(path.relative_to(root).with_suffix("").parts)
            for root, prefix in PACKAGES.items() for path in root.rglob("*.py") if path.name != "__init__.py"}


def modules_in_map(text: str) -> Set[str]:
    """The first-column names of the tables under "## Module map". A name starting with a dot is a
    sibling of the name before it in the same cell (``protocol.param``, ``.log`` -> ``protocol.log``)."""
    section = text.split("\n## Module map", 1)[1].split("\n## ", 1)[0]
    listed: Set[str] = set()
    for line in section.splitlines():
        if not line.startswith("| `"):
            continue
        parent = ""
        for name in re.findall(r"`([^`]+)`", line.split("|")[1]):
            name = parent + name if name.startswith(".") else name
            parent = name.rsplit(".", 1)[0]
            listed.add(name)
    return listed


def test_every_module_is_in_the_map():
    missing = sorted(modules_in_tree() - modules_in_map(MAP.read_text()))
    assert missing == [], "add a row to docs/architecture.md's module map for each: %s" % ", ".join(missing)


def test_the_map_lists_no_module_that_is_gone():
    gone = sorted(modules_in_map(MAP.read_text()) - modules_in_tree())
    assert gone == [], "docs/architecture.md's module map names modules that do not exist: %s" % ", ".join(gone)


def test_the_map_reader_reads_sibling_names():
    text = ("# Doc\n\n## Module map\n\n| module | what |\n|---|---|\n"
            "| `sim.onboard.estimator`, `.flight` | x |\n\n## Next\n")
    assert modules_in_map(text) == {"sim.onboard.estimator", "sim.onboard.flight"}
    assert "server.worker" in modules_in_tree() and "crazyflie_controller.pid" in modules_in_tree()
