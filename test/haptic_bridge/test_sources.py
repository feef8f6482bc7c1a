"""haptic_bridge.sources without ROS: a sample counts only from its source node's pinned writer; namesakes make the
source ambiguous; refusals are counted and named."""
from haptic_bridge.sources import ACCEPT, REFUSE, UNKNOWN, UNNAMED_WRITER, WriterGate

GENUINE, SPOOF, RIVAL, LATE = b"g" * 16, b"s" * 16, b"r" * 16, b"l" * 16
SOURCE = "/liver_tool"


def gate() -> WriterGate:
    return WriterGate(SOURCE, "device_map_node")


def test_only_the_source_nodes_writer_is_accepted_and_rivals_are_counted_by_name():
    g = gate()
    g.update({GENUINE: SOURCE, RIVAL: "/ceo_rival_physics"}, [SOURCE, "/ceo_rival_physics"])
    assert g.judge(GENUINE) == ACCEPT and g.problem() is None
    assert g.judge(RIVAL) == REFUSE and g.judge(RIVAL) == REFUSE
    assert g.refused == 2 and g.rivals() == ["/ceo_rival_physics (2)"]


def test_a_writer_the_graph_has_not_named_is_unknown_and_counted_only_when_refused():
    g = gate()
    g.update({GENUINE: SOURCE}, [SOURCE])
    assert g.judge(LATE) == UNKNOWN and g.refused == 0
    g.refuse(LATE)
    assert g.rivals() == [f"{UNNAMED_WRITER} (1)"]


def test_two_nodes_of_the_sources_name_refuse_everything_until_one_leaves_and_the_pinned_writer_stays():
    g = gate()
    g.update({GENUINE: SOURCE}, [SOURCE])
    g.update({GENUINE: SOURCE, SPOOF: SOURCE}, [SOURCE, SOURCE])
    assert g.ambiguous and g.judge(GENUINE) == REFUSE and g.judge(SPOOF) == REFUSE
    assert "two nodes named /liver_tool" in g.problem()
    g.update({GENUINE: SOURCE}, [SOURCE])  # the spoof left
    assert not g.ambiguous and g.judge(GENUINE) == ACCEPT


def test_a_namesake_seen_before_the_node_list_shows_it_still_makes_the_source_ambiguous():
    g = gate()
    g.update({GENUINE: SOURCE}, [SOURCE])
    g.update({GENUINE: SOURCE, SPOOF: SOURCE}, [SOURCE])  # two writers named as the source on one topic
    assert g.ambiguous and g.accepted is None


def test_the_pin_moves_only_when_the_pinned_writer_leaves_the_graph():
    g = gate()
    g.update({GENUINE: SOURCE}, [SOURCE])
    g.update({}, [])  # the source's node left (a restart)
    assert g.judge(GENUINE) != ACCEPT and g.problem().startswith("no writer of /liver_tool")
    g.update({SPOOF: SOURCE}, [SOURCE])  # the restarted node: a new writer
    assert g.judge(SPOOF) == ACCEPT and g.judge(GENUINE) != ACCEPT
