"""Runs that clean up after themselves, recordings that lose nothing (and count what they lose)."""
import json
import os
import signal
import stat
import subprocess
import sys

import pytest
from waiting import wait_for

from liver_sim.base.process_settings import cli_command_line
from liver_sim.running import launcher
from liver_sim.running.launcher import RunEntry, RunFile, _command_line, _process_start, run_dir, stop_leftovers
from liver_sim.sessions.bag import BagError, BagWriter, _salvaged_mcap, bag_info, check_bag
from liver_sim.sessions.gaps import SequenceGaps

from network_clients import Tally

GID_A, GID_B = bytes(range(16)), bytes(range(1, 17))


def test_gaps_are_counted_per_writer_from_sequence_numbers():
    gaps = SequenceGaps()
    gaps.already_publishing("/t", [GID_A])
    for sequence in (5, 6, 9, 10):            # A published before the recording: 7 and 8 lost
        gaps.add("/t", GID_A, sequence, "a")
    for sequence in (3, 4, 5):                # B appeared later: 1 and 2 published before it matched
        gaps.add("/t", GID_B, sequence, "b")
    gaps.add("/u", GID_A, 1)
    assert gaps.lost_by_topic() == {"/t": 4, "/u": 0} and gaps.lost == 4
    a, b = gaps.writers["/t", GID_A], gaps.writers["/t", GID_B]
    assert (a.received, a.gaps, a.before_match) == (4, 2, 0)
    assert (b.received, b.gaps, b.before_match) == (3, 0, 2)
    gaps.add("/t", GID_A, 7)                  # a late arrival fills its gap
    assert gaps.writers["/t", GID_A].gaps == 1
    gaps.began_ns = 5_000
    gaps.add("/v", GID_A, 40, "c", source_ns=4_000)  # published before the recording began: not wanted
    gaps.add("/v", GID_B, 3, "d", source_ns=6_000)   # after it: 1 and 2 lost before the match
    assert (gaps.writers["/v", GID_A].before_match, gaps.writers["/v", GID_B].before_match) == (0, 2)
    gaps.add("/v", GID_A, 45, source_ns=4_500)     # a gap between two messages from before the recording
    gaps.add("/v", GID_A, 48, source_ns=5_500)     # and one after it began: 46 and 47 lost
    assert gaps.writers["/v", GID_A].gaps == 2
    del gaps.writers["/v", GID_A], gaps.writers["/v", GID_B]
    data = gaps.custom_data()
    assert data["lost_messages"] == "3" and json.loads(data["lost_messages_by_topic"]) == {"/t": 3, "/u": 0}
    assert {w["node"] for w in json.loads(data["writers"])} == {"a", "b", ""}


def test_a_recording_fails_on_any_reliable_message_lost_after_ready_and_only_counts_best_effort_losses():
    from types import SimpleNamespace

    from liver_sim.sessions.bag import QosSpec
    from liver_sim.sessions.record import Recorder

    def failures(received: dict, overflowed=()):
        """Recorder.failures of a recording of reliable /nodes and best-effort /pose, writer A on each already
        publishing at `ready`, writer B appearing later, that received these sequence numbers."""
        gaps = SequenceGaps()
        gaps.already_publishing("/nodes", [GID_A])
        gaps.already_publishing("/pose", [GID_A])
        for (topic, gid), sequences in received.items():
            for sequence in sequences:
                gaps.add(topic, gid, sequence)
        subscriptions = [("/nodes", "", QosSpec(True, True, 300), None, None),
                         ("/pose", "", QosSpec(False, False, 1), None, None)]
        return Recorder.failures(SimpleNamespace(_subscriptions=subscriptions, gaps=gaps, overflowed=list(overflowed)))

    whole = {("/nodes", GID_A): (40, 41, 42), ("/nodes", GID_B): (1, 2), ("/pose", GID_A): (7, 8)}
    assert failures(whole) == ""                                       # A's messages before `ready` are not wanted
    assert failures({**whole, ("/pose", GID_A): (7, 9, 12)}) == ""    # best effort: counted, not a failure
    # every reliable topic, the whole mesh included: a gap, or a new writer's first messages
    assert failures({**whole, ("/nodes", GID_A): (40, 42)}) == "1 message(s) of reliable /nodes lost"
    assert (failures({**whole, ("/nodes", GID_B): (3, 4)})
            == "2 message(s) of reliable /nodes lost (2 before its writer matched)")
    assert failures(whole, ["/nodes"]) == "the history of /nodes filled up between two drains"


def sleeping_process(**kwargs) -> subprocess.Popen:
    """A process that only sleeps (10 min), for a run file to name."""
    return subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"], **kwargs)


def dead_pid() -> int:
    """The pid of a process that has ended: a run's owner that is gone."""
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def test_leftovers_of_a_dead_run_are_stopped_and_a_live_run_is_refused(tmp_path):
    leftover = sleeping_process(start_new_session=True)
    run_file = RunFile("7", tmp_path)
    try:
        with run_file.edit() as runs:
            runs.append({"owner": [dead_pid(), 1], "log_dir": "old", "processes": [
                RunEntry("liver_physics", leftover.pid, _process_start(leftover.pid), False,
                         _command_line(leftover.pid))]})
        said = []
        assert stop_leftovers(run_file, said.append) == [f"liver_physics (pid {leftover.pid})"]
        assert leftover.wait(timeout=10) == -signal.SIGTERM and "liver_physics" in said[0]
        assert not run_file.path.exists()  # nothing left to remember
        live = sleeping_process()
        with run_file.edit() as runs:
            runs.append({"owner": [live.pid, _process_start(live.pid)], "log_dir": "busy", "processes": [
                RunEntry("haptic_bridge", live.pid, _process_start(live.pid), False, _command_line(live.pid))]})
        with pytest.raises(RuntimeError, match="choose another ROS_DOMAIN_ID"):
            stop_leftovers(run_file)
        assert live.poll() is None  # another live run's process is never touched
        live.kill()
        live.wait()
    finally:
        leftover.kill()
        leftover.wait()


def test_a_process_is_signalled_only_when_pid_start_and_command_line_match(tmp_path, monkeypatch):
    other = sleeping_process(start_new_session=True)
    run_file = RunFile("8", tmp_path)
    signalled = []
    try:
        with run_file.edit() as runs:  # the pid and start time of `other`, but the command line of a node
            runs.append({"owner": [dead_pid(), 1], "log_dir": "old", "processes": [
                RunEntry("liver_physics", other.pid, _process_start(other.pid), False, "liver_physics\0--ros-args\0"),
                ["haptic_bridge", other.pid, _process_start(other.pid), False]]})  # an older entry: no command line
        with monkeypatch.context() as patch:  # every signal the launcher sends, kept instead of sent
            patch.setattr(launcher.os, "kill", lambda pid, signum: signalled.append((pid, signum)))
            assert stop_leftovers(run_file, lambda line: None) == []
        assert signalled == [], "a process that is not the one noted is never signalled"
        assert other.poll() is None
    finally:
        other.kill()
        other.wait()


def test_run_files_live_in_a_private_directory_and_never_follow_links(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    private = run_dir()
    assert private == tmp_path / "liver_sim-runs" and stat.S_IMODE(private.stat().st_mode) == 0o700
    target = tmp_path / "elsewhere.json"
    target.write_text('{"runs": [{"owner": [1, 1], "log_dir": "x", "processes": [["evil", 1, 1, false, "init"]]}]}')
    run_file = RunFile("9", private)
    run_file.path.symlink_to(target)  # a link planted in place of the run file is neither read nor written through
    with run_file.edit() as runs:
        assert runs == []
        runs.append({"owner": [os.getpid(), _process_start(os.getpid())], "log_dir": "y", "processes": [["a", 1, 1,
                                                                                                        False, ""]]})
    assert not run_file.path.is_symlink() and "evil" in target.read_text()
    private.chmod(0o755)
    with pytest.raises(RuntimeError, match="mode 755; it must be this user's"):
        run_dir()
    private.chmod(0o700)
    private.rename(tmp_path / "moved")
    (tmp_path / "liver_sim-runs").symlink_to(tmp_path / "moved")
    with pytest.raises(RuntimeError, match="symbolic link"):
        run_dir()


KILLED_WRITER = """
import os, sys
from rclpy.serialization import serialize_message
from liver_sim.sessions.bag import BagWriter
from msg_defs.forces import wrench_stamped
writer = BagWriter(sys.argv[1], sys.argv[2])
for k in range(500):
    data = serialize_message(wrench_stamped([0.0, 0.0, k * 1e-3], 1.0 + k * 1e-3, "liver"))
    writer.write("/liver/tool_wrench", "geometry_msgs/msg/WrenchStamped", 10**9 + k * 10**6, data)
    if k == 299:
        writer.flush()
os._exit(0)  # killed: no summary, no metadata.yaml
"""


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_bag_whose_recorder_was_killed_is_repaired_into_a_new_bag(tmp_path, capsys, storage):
    from liver_sim.cli.main import main

    bag = tmp_path / "killed"
    subprocess.run([sys.executable, "-c", KILLED_WRITER, str(bag), storage], check=True, timeout=60)
    with pytest.raises(BagError, match="no metadata.yaml"):
        bag_info(bag)
    before = sorted(p.name for p in bag.iterdir())
    assert main(["bag", "repair", str(bag)]) == 0
    repaired = tmp_path / "killed_repaired"
    counts = check_bag(repaired)
    assert 300 <= counts["/liver/tool_wrench"] <= 500  # everything flushed before the kill
    assert bag_info(repaired).custom_data["repaired_from"] == str(bag)
    assert sorted(p.name for p in bag.iterdir()) == before  # the damaged bag is left as it was
    assert main(["bag", "repair", str(bag)]) == 2  # and nothing is overwritten
    assert "exists already" in capsys.readouterr().err


def test_bench_record_never_replaces_an_existing_bag(tmp_path):
    from liver_sim.bench.record import new_path

    (tmp_path / "bench_session").mkdir()
    assert new_path(tmp_path / "bench_session") == tmp_path / "bench_session_2"
    with BagWriter(tmp_path / "session"):
        pass
    assert new_path(tmp_path / "other") == tmp_path / "other"


# ------------------------------------------------------------------ real processes

#: What a recorded demo starts, as its run file names them.
DEMO_PROCESSES = {"recorder", "liver_physics", "haptic_bridge", "liver_tool", "phantom_sim"}
#: How long (s) a demo may take to start its processes and move the hand, on a busy 2-core machine.
START_TIMEOUT_S = 90.0
#: How long (s) a killed demo's children may take to close (a bridge's zero, a recorder's bag) and end.
CHILDREN_GONE_S = 10.0


def start_demo(ros_env, out, duration_s=120, poses=500):
    """`liver-sim demo --record` as a separate process (its output in out/demo.out and out/demo.err), returned
    once its run file lists the recorder and the four nodes and an independent subscriber has seen `poses`
    tool poses: the simulated hand moves and the demo is in its closed-loop window. Fails with what was seen
    when that takes longer than START_TIMEOUT_S."""
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "demo.out", "w") as stdout, open(out / "demo.err", "w") as stderr:
        demo = subprocess.Popen(cli_command_line("demo", "--record", "--duration", str(duration_s), "--out",
                                                 str(out)), env=ros_env, stdout=stdout, stderr=stderr, text=True)
    tally = Tally(["/tool/pose", "/liver/nodes"])
    try:
        wait_for(lambda: set(run_processes(ros_env)) == DEMO_PROCESSES and tally.count("/tool/pose") >= poses,
                 START_TIMEOUT_S, "the demo's processes and its hand moving",
                 lambda: f"processes {sorted(run_processes(ros_env))}, messages {tally.counts()}, demo exit "
                         f"{demo.poll()}, output:\n{(out / 'demo.out').read_text()}{(out / 'demo.err').read_text()}")
    except AssertionError:
        demo.kill()
        demo.wait()
        raise
    finally:
        tally.close(linger_s=0.0)
    return demo


def run_processes(ros_env):
    """{label: pid} of the processes the run file of ros_env's domain lists (none while it has none)."""
    path = RunFile(ros_env["ROS_DOMAIN_ID"]).path
    try:
        runs = json.loads(path.read_text())["runs"]
    except (OSError, ValueError):
        return {}
    return {label: pid for run in runs for label, pid, *_ in run["processes"]}


def alive(pid):
    try:
        with open(f"/proc/{pid}/stat") as file:
            stat = file.read()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] not in ("Z", "X")


def on_disk(bag, topic: str) -> int:
    """How many messages of `topic` the MCAP file of the bag being recorded at `bag` holds so far (the recorder
    closes a chunk every second; what a kill would leave there)."""
    files = sorted(bag.glob("*.mcap"))
    if not files:
        return 0
    try:
        with _salvaged_mcap(files[0]) as (_, messages):
            return sum(1 for connection, *_ in messages if connection.topic == topic)
    except (ValueError, OSError):  # not even a header written yet
        return 0


def test_sigkill_of_the_demo_leaves_no_process_of_its_run(ros_env, tmp_path):
    demo = start_demo(ros_env, tmp_path)
    # the recorder has matched the physics and written (a kill before its first drain leaves an empty bag)
    wait_for(lambda: on_disk(tmp_path / "session", "/liver/nodes") > 0, START_TIMEOUT_S,
             "the recorder writing /liver/nodes", lambda: f"{on_disk(tmp_path / 'session', '/liver/nodes')} on disk")
    children = run_processes(ros_env)
    assert set(children) == DEMO_PROCESSES
    demo.kill()
    demo.wait()
    # each child dies with its parent (PR_SET_PDEATHSIG), the bridge's zero and the recorder's bag on the way
    wait_for(lambda: not any(alive(pid) for pid in children.values()), CHILDREN_GONE_S, "every child of the run gone",
             lambda: f"alive: {sorted(label for label, pid in children.items() if alive(pid))}")
    assert check_bag(tmp_path / "session")["/liver/nodes"] > 0  # the recorder closed its bag on the way


def test_a_node_that_crashes_is_reported_by_name_with_its_log(ros_env, tmp_path):
    demo = start_demo(ros_env, tmp_path)
    os.kill(run_processes(ros_env)["liver_physics"], signal.SIGSEGV)
    demo.wait(timeout=120)
    error = (tmp_path / "demo.err").read_text()
    assert demo.returncode == 1
    assert error.startswith("liver-sim: error: liver_physics was killed by SIGSEGV while running; last lines of "
                            f"{tmp_path / 'logs' / 'liver_physics.log'}")
    assert "Traceback" not in error
    assert not RunFile(ros_env["ROS_DOMAIN_ID"]).path.exists()  # every other process was stopped


def test_a_recorded_demo_under_load_loses_nothing_the_publishers_numbered(recorded_demo):
    """The shared recorded demo ran beside a core-bound process; a stop keeps every message a node published
    before it was asked to stop (docs/contract.md, "What a stopped run keeps")."""
    tally = recorded_demo.tally
    bag = recorded_demo.out / "session"
    info = bag_info(bag)
    counts = check_bag(bag)
    writers = json.loads(info.custom_data["writers"])
    reliable = {"/liver/nodes", "/liver/contact_plane", "/liver/tool_wrench", "/phantom/servo_cf",
                "/diagnostics", "/liver/surface", "/tool/device_map"}
    lost = json.loads(info.custom_data["lost_messages_by_topic"])
    before_stop = tally.last(before_ns=int(recorded_demo.summary["stop_requested_unix_s"] * 1e9))
    assert {topic for topic, _ in before_stop} >= reliable - {"/liver/surface", "/tool/device_map"}
    # nothing published after the recorder said ready is lost on a reliable topic, the whole mesh included:
    # not in transit, not before a writer matched (its transient-local history covers discovery)
    assert reliable <= set(lost) and all(lost[t] == 0 for t in reliable), lost
    assert int(info.custom_data["lost_messages"]) == sum(lost.values())
    for topic in counts:
        assert counts[topic] == sum(w["received"] for w in writers if w["topic"] == topic)
    for w in writers:
        # every message from the writer's first, numbered by the writer itself, is in the bag or counted lost
        assert w["received"] + w["gaps"] + w["before_match"] == w["last"], w
        if w["topic"] in reliable:
            assert w["gaps"] == 0 and w["before_match"] == 0 and w["first"] == 1, w
            # every message a reliable writer published before the stop, as an independent client saw them
            assert w["last"] >= before_stop.get((w["topic"], w["gid"]), 0), w
    seen = {key for key in tally.last() if key[0] in reliable}
    assert seen <= {(w["topic"], w["gid"]) for w in writers}
    assert counts["/liver/nodes"] > 500 and counts["/phantom/servo_cf"] > 4000
