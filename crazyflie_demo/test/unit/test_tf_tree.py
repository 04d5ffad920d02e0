"""The tf tree that view_frames prints: structure, rates, publishers, and what tf could not look up."""
from crazyflie_demo.tf_tree import TfTree


def chapter_tree() -> TfTree:
    """§6's two Crazyflies: the motion capture's frames below world, base_link below each (static)."""
    tree = TfTree()
    for i in range(101):                       # 100 Hz for 1 s
        t = 10.0 + i * 0.01
        tree.add("world", "/vicon/crazyflie1/crazyflie1", t, "/crazyflie_sim")
        tree.add("world", "vicon/crazyflie2/crazyflie2", t, "/crazyflie_sim")
    tree.add("/vicon/crazyflie1/crazyflie1", "/crazyflie1/base_link", 10.0, "/crazyflie1/baselink_broadcaster", True)
    tree.add("vicon/crazyflie2/crazyflie2", "crazyflie2/base_link", 10.0, "/crazyflie2/baselink_broadcaster", True)
    return tree


def test_the_chapters_tree_prints_below_world_with_rates_and_publishers():
    tree = chapter_tree()
    assert tree.roots() == ["world"]
    text = tree.text().splitlines()
    assert text == [
        "world",
        "|-- vicon/crazyflie1/crazyflie1  (100.0 Hz, from /crazyflie_sim)",
        "|   `-- crazyflie1/base_link  (static, from /crazyflie1/baselink_broadcaster)",
        "`-- vicon/crazyflie2/crazyflie2  (100.0 Hz, from /crazyflie_sim)",
        "    `-- crazyflie2/base_link  (static, from /crazyflie2/baselink_broadcaster)",
    ]


def test_separate_trees_loops_and_two_parents_are_said():
    tree = chapter_tree()
    tree.add("map", "odom", 1.0)                       # not connected to world
    tree.add("a", "b", 1.0)
    tree.add("b", "a", 1.0)                            # a loop: a's parent becomes b
    tree.add("world", "crazyflie2/base_link", 11.0)    # a second parent for a frame
    text = tree.text()
    assert "separate trees" in text and "map" in text
    assert "in a loop (tf cannot look these up): a, b" in text
    assert "published with two parents: crazyflie2/base_link: parent vicon/crazyflie2/crazyflie2, then world" \
        in text


def test_nothing_heard_says_what_to_check():
    assert "no transforms heard" in TfTree().text()


def test_dot_has_every_frame_and_edge_quoted():
    dot = chapter_tree().dot()
    assert dot.startswith("digraph tf {") and dot.rstrip().endswith("}")
    assert '"world" -> "vicon/crazyflie1/crazyflie1" [label="100.0 Hz, from /crazyflie_sim"];' in dot
    assert '"vicon/crazyflie2/crazyflie2" -> "crazyflie2/base_link" [label="static, from ' in dot
    tree = TfTree()
    tree.add('we"ird', "child", 0.0)
    assert '"we\\"ird" -> "child"' in tree.dot()
