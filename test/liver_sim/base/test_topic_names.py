"""A tool's topics by namespace (liver_sim.base.topic_names) and a node's command line in one
(liver_sim.base.process_settings.command_line): the root namespace keeps the contract's absolute names."""
from liver_sim.base.process_settings import command_line
from liver_sim.base.topic_names import TOOL_NAME, TOOL_TOPICS, TOPIC_NAMES, in_namespace, tool_namespace, tool_topic


def test_a_tools_topics_resolve_in_its_namespace_and_the_root_keeps_todays_names():
    for key in TOOL_TOPICS:
        assert in_namespace(tool_topic(key), tool_namespace("")) == TOPIC_NAMES[key]
    assert in_namespace(tool_topic("servo_cf"), tool_namespace("left")) == "/left/phantom/servo_cf"
    assert in_namespace(tool_topic("contact_plane"), "/right/") == "/right/liver/contact_plane"
    assert in_namespace("/MTML/servo_cf", "/left") == "/MTML/servo_cf"  # an absolute name stays
    assert TOOL_NAME.fullmatch("left_2") and not TOOL_NAME.fullmatch("2left") and not TOOL_NAME.fullmatch("a/b")


def test_a_command_line_in_a_namespace_remaps_it_before_the_parameters():
    root, left = command_line("haptic_bridge"), command_line("haptic_bridge", {"max_force_n": 1.5}, namespace="/left")
    assert "__ns:=/left" not in " ".join(root) and not any(arg.startswith("__ns") for arg in root)
    ros_args = left[left.index("--ros-args") + 1:]
    assert ros_args[:2] == ["-r", "__ns:=/left"] and ros_args[2] == "--params-file"
    assert ros_args[-2:] == ["-p", "max_force_n:=1.5"]
