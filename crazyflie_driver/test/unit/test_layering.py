"""The package's layers, read from its import statements (lazy imports inside functions included).

crtp < radio < protocol < server < nodes: a module imports only from its own layer or lower ones.
``sim`` plays the hardware, so it may use the lower layers' facts (crtp, radio) but nothing of the
server or the nodes; ``radio``, ``protocol``, ``server`` and ``mocap`` never import ``sim``. The
backend choice (``usb_choice``) is the one bridge from the radio to the simulated air, and only
entry points (nodes, tools, tests, benchmarks) use it. Only ``nodes`` imports rospy or ROS messages.
Inside ``server``, swarm mode (``server.swarm``) builds on the per-Crazyflie path (worker, registry,
safety, onboard commands), which never imports the swarm; every swarm module lives in that package.
Inside ``sim``, each part sits in the package of what it plays: ``sim.onboard`` (the Crazyflie's
flight software), ``sim.crtp`` (its radio side), ``sim.room`` (physics, sensors, battery, motion
capture, world stepping), ``sim.air`` (dongles, media, UDP); ``sim.world_server`` and ``sim.node_config``
compose them. The
arrows between them are ``SIM_ARROWS`` (docs/architecture.md, "The simulator's parts").
"""
from __future__ import annotations

import ast
import pathlib
from typing import Dict, List, Set, Tuple

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[2] / "src" / "crazyflie_driver"

ORDER = ("crtp", "radio", "protocol", "server", "nodes")
BASE = {"errors", "clock"}                                # importable from everywhere
ROS = {"rospy", "rosgraph", "rostest", "roslib", "genpy", "tf2_ros", "geometry_msgs", "sensor_msgs", "std_msgs",
       "std_srvs", "visualization_msgs"}
# The simulated world's own ROS node runs the simulator: it is an entry point of sim, not a user of it.
SIM_ENTRY_POINTS = {"crazyflie_driver.nodes.sim_node"}


def _modules() -> Dict[str, pathlib.Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = ("crazyflie_driver",) + path.relative_to(PACKAGE).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imports(path: pathlib.Path) -> Set[str]:
    """Every module name an import statement of the file names (``from a import b`` gives a and a.b)."""
    names: Set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, "%s: relative import of %r" % (path, node.module)
            names.add(node.module)
            names.update("%s.%s" % (node.module, a.name) for a in node.names)
    return names


def _layer(module: str) -> str:
    """``crazyflie_driver.radio.link`` -> ``radio``; ``crazyflie_driver.usb_choice`` -> ``usb_choice``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


MODULES = _modules()
GRAPH: Dict[str, Set[str]] = {m: _imports(p) for m, p in MODULES.items()}


def _edges() -> List[Tuple[str, str, str, str]]:
    """(module, its layer, imported module of this package, that one's layer)."""
    out = []
    for module, names in GRAPH.items():
        for name in names:
            if name.startswith("crazyflie_driver.") and name in MODULES:
                out.append((module, _layer(module), name, _layer(name)))
    return out


def test_the_package_has_the_layers_this_test_knows():
    layers = {_layer(m) for m in MODULES} - {""}
    assert layers == set(ORDER) | BASE | {"sim", "mocap", "usb_choice"}


def test_no_layer_imports_a_higher_one():
    rank = {layer: i for i, layer in enumerate(ORDER)}
    wrong = [(m, n) for m, lm, n, ln in _edges() if lm in rank and ln in rank and rank[ln] > rank[lm]]
    assert wrong == []


def test_mocap_uses_only_the_base():
    wrong = [(m, n) for m, lm, n, ln in _edges() if lm == "mocap" and ln not in BASE | {"mocap"}]
    assert wrong == []


def test_sim_imports_nothing_of_the_server_or_the_nodes():
    wrong = [(m, n) for m, lm, n, ln in _edges() if lm == "sim" and ln in {"protocol", "server", "nodes", "usb_choice"}]
    assert wrong == []


def test_only_the_backend_choice_and_the_simulators_node_import_sim():
    wrong = [(m, n) for m, lm, n, ln in _edges()
             if ln == "sim" and lm != "sim" and lm != "usb_choice" and m not in SIM_ENTRY_POINTS]
    assert wrong == []


def test_only_entry_points_choose_the_backend():
    wrong = [(m, n) for m, lm, n, ln in _edges() if ln == "usb_choice" and lm not in {"nodes", "usb_choice"}]
    assert wrong == []


def _sublayer(module: str) -> str:
    """``crazyflie_driver.server.swarm.watch`` -> ``server.swarm``; other modules: their layer."""
    parts = module.split(".")
    return "server.swarm" if parts[1:3] == ["server", "swarm"] else _layer(module)


# What each part of the simulator may import of the others. ``sim.base``: the simulator's shared
# modules at its top (rows of vehicle state, the world's clock, process priority).
SIM_PARTS = ("onboard", "crtp", "room", "air")
SIM_ARROWS: Dict[str, Set[str]] = {
    "sim.base": set(),
    "sim.onboard": {"sim.base"},
    "sim.crtp": {"sim.onboard", "sim.base"},               # the radio side hands setpoints to the flight code
    "sim.room": {"sim.onboard", "sim.base"},               # the world steps each vehicle's flight code
    "sim.air": {"sim.base"},
    "sim.root": {"sim.onboard", "sim.crtp", "sim.room", "sim.air", "sim.base"},
}
#: The simulator's composition roots at its top, which wire every part: the world server process and the
#: sim node's plan (its parameters turned into a world, motion capture and faults).
SIM_ROOTS = ("world_server", "node_config")


def _sim_part(module: str) -> str:
    """``crazyflie_driver.sim.room.world`` -> its part, ``"sim.room"``; a module at the top -> the shared base."""
    parts = module.split(".")
    if parts[2] in SIM_PARTS:
        return "sim." + parts[2]
    return "sim.root" if parts[2] in SIM_ROOTS else "sim.base"


def test_every_sim_module_has_a_part():
    assert {_sim_part(m) for m in MODULES if _layer(m) == "sim" and m != "crazyflie_driver.sim"} == set(SIM_ARROWS)
    for part in SIM_PARTS:
        assert (PACKAGE / "sim" / part / "__init__.py").is_file()


def test_the_simulators_parts_import_only_along_their_arrows():
    wrong = sorted((m, n) for m, lm, n, ln in _edges() if lm == ln == "sim" and m != "crazyflie_driver.sim"
                   and _sim_part(m) != _sim_part(n) and _sim_part(n) not in SIM_ARROWS[_sim_part(m)])
    assert wrong == []


def test_the_per_crazyflie_server_never_imports_the_swarm():
    wrong = [(m, n) for m, lm, n, _ in _edges() if lm == "server" and _sublayer(m) == "server"
             and _sublayer(n) == "server.swarm"]
    assert wrong == []


def test_every_swarm_module_lives_in_the_swarm_package():
    flat = sorted(m for m in MODULES if _sublayer(m) == "server" and m.split(".")[-1].startswith(
        ("swarm_", "mocap_stream", "estimator_placement")))
    assert flat == []
    assert (PACKAGE / "server" / "swarm" / "__init__.py").is_file()


def test_no_ros_below_the_nodes():
    wrong = sorted((m, n) for m, names in GRAPH.items() for n in names
                   if n.split(".")[0] in ROS and _layer(m) != "nodes")
    assert wrong == []


def test_no_import_cycles_between_modules():
    cycles = []
    state: Dict[str, int] = {}           # 1: on the current path, 2: done

    def visit(module: str, path: List[str]) -> None:
        state[module] = 1
        for name in sorted(GRAPH[module]):
            if name not in MODULES or name == module or module.startswith(name + "."):
                continue                  # outside the package, or the module's own package __init__
            if state.get(name) == 1:
                cycles.append(path[path.index(name):] + [name])
            elif name not in state:
                visit(name, path + [name])
        state[module] = 2

    for module in MODULES:
        if module not in state:
            visit(module, [module])
    assert cycles == []


@pytest.mark.parametrize("layer", ORDER + ("sim", "mocap"))
def test_every_layer_is_a_package(layer):
    assert (PACKAGE / layer / "__init__.py").is_file()
