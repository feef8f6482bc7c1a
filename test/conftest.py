"""Session-wide settings for the liver_sim test suite.

* DDS stays on loopback: ROS_AUTOMATIC_DISCOVERY_RANGE is forced to
  LOCALHOST for this process and everything it starts, whatever the
  environment says, and ROS_STATIC_PEERS / ROS_LOCALHOST_ONLY are removed
  (static peers would reach other hosts; the latter is deprecated and would
  override the range).
* Plots never open windows: MPLBACKEND=Agg.
* ROS domains: the session keeps the ROS_DOMAIN_ID it was given (the Makefile
  picks one) unless another liver_sim test session on this machine holds it.
  Tests that start ROS processes or contexts take the ``ros_domain_id``
  fixture: a domain of their own, held under an exclusive file lock for the
  duration of the test, so that no two tests -- in this session, in
  pytest-xdist workers, or in another checkout's test run on the same machine
  -- ever share one.
* One closed-loop run for the tests that watch one: ``recorded_demo`` runs
  ``liver-sim demo --record --view`` once per session, beside a core-bound
  process, an independent subscriber and a Foxglove client of the view, and
  several tests assert on its summary, pictures, recording and what the
  subscriber and the client saw.
* Two phases: the ``ros`` tests that start processes keeping a rate (nodes,
  closed loops) are marked ``rate_loops``. ``make test`` first runs everything
  else on two pytest-xdist workers (``-m "not rate_loops"``: the ROS-free
  tests and the ``no_rate_loops`` ones, recorders, replays and clients at
  normal priority), then the ``rate_loops`` tests in order in one process
  with nothing else of the suite computing (``-m rate_loops``): their loops
  get the machine's cores as a rig's would. A closed loop beside a worker
  computing physics lost its rate on two cores.
* Two hands: the tests that run two device sides at once in real time (the
  ``two_hands_demo`` fixture's, and those marked ``two_hands``) need more
  than two cores (docs/devices.md#two-hands): on a machine with fewer than
  TWO_HANDS_MIN_CORES they are skipped with that reason, unless
  LIVER_SIM_TWO_HANDS=1 asks for them (``make test-two-hands``).
* Test tiers: every test that takes ``ros_domain_id`` (directly, through
  ``ros_env`` or through another fixture), or is listed in
  ``ROS_WITHOUT_FIXTURE``, is marked ``ros``: it starts node processes or an
  rclpy context and talks DDS. The rest is the ROS-free tier,
  ``pytest -m "not ros"`` (``make test-quick``); ``make test`` runs both.

These settings are made at import time, before any test module imports
rclpy or matplotlib.
"""
import os
import socket
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pytest
from ros_domains import VALID_DOMAIN_IDS, claim_domain_id, try_lock

from liver_sim.base.process_settings import use_dds_profile

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_STATIC_PEERS", None)
os.environ.pop("ROS_LOCALHOST_ONLY", None)
os.environ["MPLBACKEND"] = "Agg"
use_dds_profile()  # the product's Fast DDS profile, for the in-process participants as for the nodes

def _session_domain():
    """The session's own domain: the given one unless another session holds it."""
    given = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if given.isdigit() and int(given) in VALID_DOMAIN_IDS:
        handle = try_lock(int(given))
        if handle is not None:
            return int(given), handle
    return claim_domain_id()


SESSION_DOMAIN_ID, _SESSION_LOCK = _session_domain()
os.environ["ROS_DOMAIN_ID"] = str(SESSION_DOMAIN_ID)


def pytest_unconfigure(config):
    _SESSION_LOCK.close()


#: Cores a machine gives this process from which the two-hand real-time tests run: two device sides at 1 kHz, the
#: physics with two contacts, a recorder and a live view took more than 2 cores on the AMD EPYC VM (docs/devices.md).
TWO_HANDS_MIN_CORES = 4
#: The environment variable that runs the two-hand tests on fewer cores (to measure what they need, or on a fast day).
TWO_HANDS_VARIABLE = "LIVER_SIM_TWO_HANDS"
#: The fixtures of the two-hand tests: a test that takes one is marked ``two_hands``.
TWO_HANDS_FIXTURES = frozenset({"two_hands_demo"})


def _two_hands_skip() -> str | None:
    """Why the two-hand tests do not run here (None: they do)."""
    cores = len(os.sched_getaffinity(0))
    if cores >= TWO_HANDS_MIN_CORES or os.environ.get(TWO_HANDS_VARIABLE) == "1":
        return None
    return (f"two device sides in real time need {TWO_HANDS_MIN_CORES} cores, this machine gives {cores} "
            f"(docs/devices.md#two-hands; {TWO_HANDS_VARIABLE}=1 or `make test-two-hands` runs them anyway)")


#: Fixtures that give a test a ROS domain of its own: what starting ROS processes or contexts takes.
ROS_FIXTURES = frozenset({"ros_domain_id", "ros_env", "recorded_demo", "two_hands_demo"})
#: Tests (name prefixes, parameters included) that open an rclpy context in this process without those
#: fixtures: `liver-sim replay` on a bag that is found damaged only once its publishers are up.
ROS_WITHOUT_FIXTURE = ("test_a_damaged_bag_is_refused_with_a_clear_error[replay-",)


@pytest.hookimpl(tryfirst=True)  # before pytest's -m and pytest-xdist's groups read the markers
def pytest_collection_modifyitems(config, items):
    """Mark ``ros`` every test whose fixture closure holds one of ROS_FIXTURES, or named in ROS_WITHOUT_FIXTURE, and
    ``rate_loops`` those of them not marked ``no_rate_loops``; the latter also form one xdist group, so that under
    ``pytest -n 2 --dist loadgroup`` they still run one after the other on one worker, sharing its session
    fixtures (``make test`` runs them in a phase of their own, see the module doc). Two-hand tests (module doc) are
    marked ``two_hands`` and skipped where the machine has too few cores."""
    two_hands_skip = _two_hands_skip()
    for item in items:
        if TWO_HANDS_FIXTURES.intersection(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.two_hands)
        if two_hands_skip and item.get_closest_marker("two_hands") is not None:
            item.add_marker(pytest.mark.skip(reason=two_hands_skip))
        if (ROS_FIXTURES.intersection(getattr(item, "fixturenames", ()))
                or item.name.startswith(ROS_WITHOUT_FIXTURE)):
            item.add_marker(pytest.mark.ros)
            if item.get_closest_marker("no_rate_loops") is None:
                item.add_marker(pytest.mark.rate_loops)
                item.add_marker(pytest.mark.xdist_group("ros"))


class XdistGroupIds:
    """pytest-xdist 3.8 puts a test in its group by suffixing ``item._nodeid`` with ``@group``, which pytest 9 no
    longer reads (a node keeps its id in ``_id``): carry the suffix over, so that ``--dist loadgroup`` keeps the
    ros tests on one worker. Without it they spread over both workers, two closed loops at once."""

    @pytest.hookimpl(trylast=True)
    def pytest_collection_modifyitems(self, items):
        for item in items:
            suffixed = item.__dict__.get("_nodeid")
            if suffixed and suffixed != item.nodeid:
                item._id = type(item._id).parse(suffixed)  # pytest 9's structured node id, by its own class


def pytest_configure(config):
    config.pluginmanager.register(XdistGroupIds(), "liver_sim_xdist_group_ids")


def pytest_report_header(config):
    return (f"ROS: ROS_DOMAIN_ID={SESSION_DOMAIN_ID} (session), "
            f"ROS_AUTOMATIC_DISCOVERY_RANGE="
            f"{os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']}, "
            f"MPLBACKEND={os.environ['MPLBACKEND']}")


@pytest.fixture
def ros_domain_id(monkeypatch):
    """A ROS_DOMAIN_ID (int) that no other running test uses.

    It is also set in ``os.environ`` for the duration of the test, so both
    ``rclpy.init()`` in the test process and subprocesses started with the
    default environment use it. Pass it explicitly where you build an
    environment yourself (or use the ``ros_env`` fixture).
    """
    domain_id, handle = claim_domain_id(exclude={SESSION_DOMAIN_ID})
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain_id))
    try:
        yield domain_id
    finally:
        handle.close()


@pytest.fixture
def ros_env(ros_domain_id):
    """A copy of ``os.environ`` for ROS subprocesses: own domain, loopback only."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(ros_domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_STATIC_PEERS", None)
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


@pytest.fixture
def rng():
    """A seeded random generator: the same draws on every run."""
    return np.random.default_rng(7)


#: The shared run's length (s): the press demo's own (DemoMesh.press: press, slide, release and rest).
RECORDED_DEMO_S = 14.0


#: Scenes per second the shared run's view is asked for.
VIEW_RATE_HZ = 40.0


@dataclass(frozen=True)
class RecordedDemo:
    """What the shared run left: `out` (summary.json/.md, pictures, view.png, logs/, the bag in session/), the demo's
    `summary`, `tally`, the independent subscriber's numbering of every writer (network_clients.Tally), and `view`,
    what a Foxglove client received from the live view serving `view_rate_hz` scenes a second
    (foxglove_client.listen's (serverInfo, channels, received), or None if it never connected)."""

    out: Path
    summary: dict
    tally: object
    view: tuple | None
    view_rate_hz: float = VIEW_RATE_HZ

    @cached_property
    def bag(self) -> dict:
        """The recording, read once by rosbags alone (network_clients.read_bag)."""
        from network_clients import read_bag

        return read_bag(self.out / "session")


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@contextmanager
def own_domain():
    """A ROS domain of its own for a session fixture's run: locked (claim_domain_id) and set as ROS_DOMAIN_ID while
    the block runs."""
    domain_id, handle = claim_domain_id(exclude={SESSION_DOMAIN_ID})
    try:
        with pytest.MonkeyPatch.context() as patch:
            patch.setenv("ROS_DOMAIN_ID", str(domain_id))
            yield domain_id
    finally:
        handle.close()


@pytest.fixture(scope="session")
def recorded_demo(tmp_path_factory):
    """`liver-sim demo --record --view` (the press scenario, RECORDED_DEMO_S) run once per session in a ROS domain
    of its own, beside one more core-bound process at normal priority once the network is up (run_demo's
    extra_load), an independent subscriber and a Foxglove client of the live view, as a rig with a busy machine
    would run it. The tests that watch a closed loop share
    it instead of each starting its own network."""
    # rclpy loads here, for the tests of the ros tier only: the ROS-free tier never starts this fixture
    from foxglove_client import VIEW_TOPICS, Watcher

    from liver_sim.studies.demo import run_demo

    from network_clients import Tally

    out = tmp_path_factory.mktemp("recorded_demo")
    with own_domain():
        tally = Tally()
        port = free_port()
        watcher = Watcher(port, list(VIEW_TOPICS))
        try:
            summary = run_demo(out, duration_s=RECORDED_DEMO_S, progress=lambda line: None,
                               record_storage="mcap", view=["--port", str(port), "--rate", f"{VIEW_RATE_HZ:g}"],
                               extra_load=1, check_domain=False)  # the domain is the fixture's own
        finally:
            view = watcher.stop()
            tally.close()
    return RecordedDemo(out, summary, tally, view)


@dataclass(frozen=True)
class TwoHandsDemo:
    """What the shared two-hand run left: `out` (summary.json/.md, force.png, liver_two_hands.png, view.png, logs/,
    the bag in session/), the demo's `summary`, and `view`, what a Foxglove client received from its live view (as
    RecordedDemo.view)."""

    out: Path
    summary: dict
    view: tuple | None


@pytest.fixture(scope="session")
def two_hands_demo(tmp_path_factory):
    """`liver-sim demo --tools 2 --record --view` (studies.two_hands: the left grasps and lifts the edge, the right
    presses and cuts beside it) run once per session in a ROS domain of its own, with a Foxglove client of the view;
    the tests of two hands share it."""
    from foxglove_client import VIEW_TOPICS, Watcher

    from liver_sim.studies.two_hands import run_two_hands

    out = tmp_path_factory.mktemp("two_hands_demo")
    with own_domain():
        port = free_port()
        watcher = Watcher(port, list(VIEW_TOPICS), enough=300, seconds=12.0)  # the lift and the cut
        try:
            summary = run_two_hands(out, progress=lambda line: None, record_storage="mcap",
                                    view=["--port", str(port)], check_domain=False)  # the domain is the fixture's own
        finally:
            view = watcher.stop()
    return TwoHandsDemo(out, summary, view)


@pytest.fixture
def rig_factory(ros_domain_id):
    """Makes bridge_rig.Rig test sides (the physics and tool of a haptic_bridge process) in the test's domain,
    closed after the test."""
    from bridge_rig import Rig  # rclpy loads here, for the ros tier only

    rigs = []

    def make(**kwargs) -> Rig:
        rigs.append(Rig(**kwargs))
        return rigs[-1]
    try:
        yield make
    finally:
        for rig in rigs:
            rig.close()
