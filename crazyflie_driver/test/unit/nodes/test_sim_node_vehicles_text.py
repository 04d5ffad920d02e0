"""sim node: ~vehicles given as YAML text or a file path, and hiding a vehicle from motion capture."""
from __future__ import annotations

import pytest

from crazyflie_driver.sim.node_config import MocapConfig, SimConfigError, mocap_model, vehicles_from_params
from crazyflie_driver.sim.room.world import World


def test_vehicles_as_yaml_text_like_the_launch_files_pass_it():
    text = ("[{uri: 'radio://0/80/2M/E7E7E7E701', name: crazyflie1, x: 0.0, y: 0.0}, "
            "{uri: 'radio://0/80/2M/E7E7E7E702', name: crazyflie2, x: 0, y: -0.75}]")
    v = vehicles_from_params({"vehicles": text})
    assert [s.name for s in v] == ["crazyflie1", "crazyflie2"]
    assert v[1].position == (0.0, -0.75, 0.0)
    assert v[0].uri == "radio://0/80/2M/E7E7E7E701"


def test_vehicles_as_a_yaml_file_path(tmp_path):
    f = tmp_path / "v.yaml"
    f.write_text("vehicles:\n  - {uri: 'radio://0/90/2M', name: cf, z: 0.1}\n")
    v = vehicles_from_params({"vehicles": str(f)})
    assert len(v) == 1 and v[0].name == "cf" and v[0].position == (0.0, 0.0, 0.1)


def test_vehicles_text_that_is_not_yaml_is_a_clear_error():
    with pytest.raises(SimConfigError, match="vehicles"):
        vehicles_from_params({"vehicles": "[{uri: 'radio://0/80/2M'"})
    with pytest.raises(SimConfigError, match="list"):
        vehicles_from_params({"vehicles": "just words"})


def test_a_hidden_vehicle_is_missing_from_frames_until_shown_again():
    w = World(speed=0.0, seed=1)
    w.add_vehicle("cf1", (0.1, 0.2, 0.0))
    w.add_vehicle("cf2", (0.5, 0.0, 0.0))
    model = mocap_model(w, MocapConfig()).attach()     # the node's model: 100 Hz, no noise, no latency
    w.step(20)
    assert {f.name for f in model.pop_frames()} == {"cf1", "cf2"}
    model.set_visible("cf1", False)
    assert not model.visible("cf1")
    w.step(20)
    assert {f.name for f in model.pop_frames()} == {"cf2"}
    model.set_visible("cf1", True)
    w.step(20)
    frames = model.pop_frames()
    assert {f.name for f in frames} == {"cf1", "cf2"}
    cf1 = [f for f in frames if f.name == "cf1"][-1]
    assert cf1.position.tolist() == pytest.approx([0.1, 0.2, 0.0])
    with pytest.raises(KeyError):
        model.set_visible("ghost", False)
