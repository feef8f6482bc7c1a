"""Starting the product's nodes as separate processes, with the command lines a person would type
(liver_sim.base.process_settings.command_line).

A run's processes never outlive it: each gets SIGTERM when the thread that started it dies (Linux
parent-death signal; SIGTERM so that a bridge still sends its zero and a recorder closes its bag), and
each run notes its processes in a run file per ROS domain (RUN_DIR/domain-<id>.json, pids with their
kernel start times). A new run on the domain stops what a dead run left there, and refuses a domain a
live run of another process uses.
"""
from __future__ import annotations

import ctypes
import fcntl
import json
import os
import signal
import stat
import subprocess
import tempfile
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

from liver_sim.base.stop_request import ENDING_SIGNALS

#: A stopping node is signalled again (SIGINT, SIGTERM, SIGKILL) after this long (s).
STOP_TIMEOUT_S = 5.0
#: A stopping process started `patient` (a recorder closing its bag) is signalled again only after this long
#: (s) without using CPU time, so that it is never cut short while it writes ...
IDLE_BEFORE_ESCALATION_S = 5.0
#: ... or after this long (s) in all, whatever it does.
MAX_STOP_S = 300.0
#: Lines of a failed process's log shown in its report.
LOG_TAIL_LINES = 15
PR_SET_PDEATHSIG = 1


class NodeFailure(RuntimeError):
    """A process of a run that exited early or with a non-zero status: names it, its status, the tail of its log."""

    def __init__(self, failures: list[tuple[str, int, Path]], when: str):
        self.failures = failures
        parts = []
        for label, status, log in failures:
            how = (f"was killed by {signal.Signals(-status).name}" if status < 0
                   else f"exited with status {status}")
            tail = log_tail(log)
            parts.append(f"{label} {how} {when}; last lines of {log}:\n" + "\n".join(f"  | {t}" for t in tail))
        super().__init__("\n".join(parts))


def log_tail(path: Path, lines: int = LOG_TAIL_LINES) -> list[str]:
    """The last `lines` lines of a log (none if it is missing)."""
    try:
        return path.read_text(errors="replace").splitlines()[-lines:]
    except OSError:
        return []


def _process_start(pid: int) -> int | None:
    """The kernel start time of `pid` (clock ticks since boot; with the pid, a process's identity), or None
    when no such process runs (a zombie counts as gone)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat.rsplit(")", 1)[1].split()
    return None if fields[0] in ("Z", "X") else int(fields[19])


def _command_line(pid: int) -> str | None:
    """The command line of `pid` (arguments joined by NUL), or None when it cannot be read."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
    except OSError:
        return None


def _is_process(pid: int, start: int, command_line: str) -> bool:
    """Whether `pid` is still the process that was noted: same kernel start time and same command line."""
    return _process_start(pid) == start and _command_line(pid) == command_line


def run_dir() -> Path:
    """The private directory of this user's run files: $XDG_RUNTIME_DIR/liver_sim-runs (per user, 0700 by the
    XDG spec) when it is set, else <tmp>/liver_sim-runs-<uid>. Created with mode 0700; RuntimeError naming it
    when it is a symbolic link, not a directory, owned by another user or open to others (a planted directory
    could name another process to be signalled)."""
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    path = (Path(runtime) / "liver_sim-runs" if runtime
            else Path(tempfile.gettempdir()) / f"liver_sim-runs-{os.getuid()}")
    try:
        os.mkdir(path, 0o700)
    except FileExistsError:
        pass
    info = os.lstat(path)
    if stat.S_ISLNK(info.st_mode) or not stat.S_ISDIR(info.st_mode):
        raise RuntimeError(f"{path}: the run-file directory is not a directory of its own (a symbolic link or a "
                           "file); remove it or set XDG_RUNTIME_DIR")
    if info.st_uid != os.getuid() or info.st_mode & 0o077:
        raise RuntimeError(f"{path}: the run-file directory belongs to uid {info.st_uid} with mode "
                           f"{stat.S_IMODE(info.st_mode):o}; it must be this user's ({os.getuid()}) with mode 700")
    return path


def _open_private(path: Path, flags: int):
    """`path` opened without following a symbolic link (mode 0600 when created), as a text file."""
    return os.fdopen(os.open(path, flags | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600), "r+" if flags & os.O_RDWR else
                     "w" if flags & os.O_WRONLY else "r")


def _cpu_ticks(pid: int) -> int:
    """User + system CPU time of `pid` (clock ticks); -1 when it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return -1
    return int(fields[11]) + int(fields[12])


def die_with_parent(parent_pid: int):
    """preexec_fn: SIGTERM this child when the thread that started it dies (prctl PR_SET_PDEATHSIG), and at
    once if the parent is already gone. The child starts at nice 0 whatever its parent's (a node sets its own,
    liver_sim.nodes.run)."""
    prctl = ctypes.CDLL(None, use_errno=True).prctl  # looked up before the fork

    def preexec() -> None:
        prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
        os.setpriority(os.PRIO_PROCESS, 0, 0)
        if os.getppid() != parent_pid:
            os.kill(os.getpid(), signal.SIGTERM)
    return preexec




@contextmanager
def ending_signals_deferred():
    """Run the block with the ending signals held, then act on the first that came. A command ends by an
    exception its handler raises wherever the main thread is; raised inside subprocess.Popen after the fork, or
    before the child is noted, it left a node the command then never stopped (a SIGTERM to `liver-sim demo` as a
    node started). Only the main thread sets handlers; elsewhere the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught = []
    previous = {signum: signal.signal(signum, lambda signum, _frame: caught.append(signum))
                for signum in ENDING_SIGNALS}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if caught:
            signal.raise_signal(caught[0])


class RunEntry(NamedTuple):
    """One process of a run, as its run file notes it (a JSON list in this order): its label, pid, kernel start
    time (with the pid, its identity), whether it stops `patient`ly (_wait_gone) and its command line."""

    label: str
    pid: int
    start: int
    patient: bool
    command_line: str | None

    @classmethod
    def read(cls, entry: list) -> RunEntry | None:
        """The entry of a run file's list, or None when it is not one (an older or damaged file)."""
        return cls(*entry) if isinstance(entry, list) and len(entry) == len(cls._fields) else None


class RunFile:
    """The run file of a ROS domain in this user's private directory (:func:`run_dir`): {"runs": [{"owner": [pid,
    start], "log_dir", "processes": [RunEntry, …]}]}, read and written under an exclusive lock, never through a
    symbolic link; `edit` hands the processes as RunEntry, or None for an entry that is not one."""

    def __init__(self, domain: str, directory: Path | None = None):
        self.run_dir = run_dir() if directory is None else directory
        self.path = self.run_dir / f"domain-{domain}.json"

    @contextmanager
    def edit(self):
        """The runs, as a list to change in place; written back on exit."""
        with _open_private(self.run_dir / f"{self.path.name}.lock", os.O_RDWR | os.O_CREAT) as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                with _open_private(self.path, os.O_RDONLY) as file:
                    runs = json.loads(file.read())["runs"]
                for run in runs:
                    run["processes"] = [RunEntry.read(entry) for entry in run["processes"]]
            except FileNotFoundError:
                runs = []
            except (OSError, ValueError, KeyError, TypeError):
                runs = []  # a damaged run file (or a link planted in its place) names nothing to be trusted
            yield runs
            runs[:] = [run for run in runs if run["processes"]]
            if runs:
                if self.path.is_symlink():
                    self.path.unlink()
                with _open_private(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC) as file:
                    file.write(json.dumps({"runs": runs}, indent=1) + "\n")
            elif self.path.exists() or self.path.is_symlink():
                self.path.unlink()


def _alive(identity) -> bool:
    pid, start = identity
    return _process_start(pid) == start


def _noted_alive(entry: RunEntry | None) -> bool:
    """Whether a run file's process entry still names the process that was started: pid, start time and
    command line all match (an entry that is not a RunEntry never does)."""
    return entry is not None and _is_process(entry.pid, entry.start, entry.command_line)


def stop_leftovers(run_file: RunFile, progress=print) -> list[str]:
    """Stop the processes that runs of dead processes left in the run file's domain (SIGTERM, then SIGKILL
    once idle); return their labels and pids. RuntimeError when a live run of another process uses the domain."""
    me = [os.getpid(), _process_start(os.getpid())]
    stopped = []
    with run_file.edit() as runs:
        for run in runs:
            alive = [entry for entry in run["processes"] if _noted_alive(entry)]
            if _alive(run["owner"]):
                if run["owner"] != me and alive:
                    labels = ", ".join(entry.label for entry in alive)
                    raise RuntimeError(f"{run_file.path}: pid {run['owner'][0]} runs {labels} "
                                       f"on this ROS domain (logs in {run['log_dir']}); stop it or choose another "
                                       "ROS_DOMAIN_ID")
                continue
            for entry in alive:
                os.kill(entry.pid, signal.SIGTERM)
            for entry in alive:
                _wait_gone(entry.pid, entry.start, (signal.SIGKILL,), entry.patient, command_line=entry.command_line)
                stopped.append(f"{entry.label} (pid {entry.pid})")
            run["processes"] = []
    if stopped:
        progress(f"stopped what an earlier run left on this domain: {', '.join(stopped)}")
    return stopped


def _wait_gone(pid: int, start: int, escalation, patient: bool, poll=None, command_line: str | None = None) -> None:
    """Wait until the process (pid, start, and `command_line` when given) is gone (or `poll` gives its status),
    sending the next signal of `escalation` after STOP_TIMEOUT_S, or when `patient` once it has used no CPU
    time for IDLE_BEFORE_ESCALATION_S (at the latest after MAX_STOP_S)."""
    escalation = list(escalation)
    began = idle_since = time.monotonic()
    ticks = _cpu_ticks(pid)

    def same() -> bool:
        return _process_start(pid) == start and (command_line is None or _command_line(pid) == command_line)

    while (poll is None or poll() is None) and same():
        now, used = time.monotonic(), _cpu_ticks(pid)
        if used != ticks:
            ticks, idle_since = used, now
        due = (now - idle_since > IDLE_BEFORE_ESCALATION_S or now - began > MAX_STOP_S) if patient \
            else now - began > STOP_TIMEOUT_S
        if escalation and due:
            os.kill(pid, escalation.pop(0))
            idle_since = began = now
        time.sleep(0.02)


class NodeProcesses:
    """Started node processes, noted in the domain's run file, stopped with SIGINT (then SIGTERM, then
    SIGKILL: see _wait_gone) on exit or stop(). `exit_codes` keeps the status of every stopped process."""

    def __init__(self, log_dir: Path, progress=print, run_directory: Path | None = None):
        self.log_dir = log_dir
        self.processes: dict[str, subprocess.Popen] = {}
        self.exit_codes: dict[str, int] = {}
        self._identity = [os.getpid(), _process_start(os.getpid())]
        self._run_file = RunFile(os.environ.get("ROS_DOMAIN_ID") or "0", run_directory)
        stop_leftovers(self._run_file, progress)

    def start(self, label: str, args: list[str], patient: bool = False) -> subprocess.Popen:
        """Start one node; its output goes to <log_dir>/<label>.log. A `patient` one (a recorder) is given
        the time it needs to stop while it still works (_wait_gone)."""
        self.log_dir.mkdir(parents=True, exist_ok=True)
        with ending_signals_deferred(), open(self.log_dir / f"{label}.log", "w") as log:
            process = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, env=dict(os.environ),
                                       start_new_session=True, preexec_fn=die_with_parent(os.getpid()))
            self.processes[label] = process
            self.exit_codes.pop(label, None)
            with self._run_file.edit() as runs:
                run = next((r for r in runs if r["owner"] == self._identity and r["log_dir"] == str(self.log_dir)),
                           None)
                if run is None:
                    run = {"owner": self._identity, "log_dir": str(self.log_dir), "processes": []}
                    runs.append(run)
                run["processes"].append(RunEntry(label, process.pid, _process_start(process.pid), patient,
                                                 _command_line(process.pid)))
        return process

    def stop(self, label: str | list[str] | None = None) -> dict[str, int]:
        """Stop one node, a list of them, or all, politely first; return their exit statuses."""
        labels = [label] if isinstance(label, str) else list(self.processes if label is None else label)
        for name in labels:
            process = self.processes[name]
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        pids = {self.processes[name].pid for name in labels}
        with self._run_file.edit() as runs:
            patient = {e.pid for run in runs if run["owner"] == self._identity for e in run["processes"]
                       if e is not None and e.patient}
        for name in labels:
            process = self.processes[name]
            start = _process_start(process.pid)  # our unreaped child: the pid cannot have been reused
            if start is not None:
                _wait_gone(process.pid, start, (signal.SIGTERM, signal.SIGKILL), process.pid in patient,
                           process.poll)
            self.exit_codes[name] = process.wait()
        with self._run_file.edit() as runs:
            for run in runs:
                if run["owner"] == self._identity:
                    run["processes"] = [e for e in run["processes"] if e is None or e.pid not in pids]
        return {name: self.exit_codes[name] for name in labels}

    def failed(self) -> dict[str, int]:
        """Nodes that have exited, with their exit status."""
        return {name: p.returncode for name, p in self.processes.items() if p.poll() is not None}

    def check(self, when: str = "while running") -> None:
        """NodeFailure naming every node that has exited (early)."""
        failed = self.failed()
        if failed:
            raise NodeFailure([(name, status, self.log_dir / f"{name}.log") for name, status in failed.items()], when)

    def check_exit_codes(self) -> None:
        """NodeFailure naming every stopped node whose exit status was not 0."""
        bad = [(name, status, self.log_dir / f"{name}.log") for name, status in self.exit_codes.items() if status]
        if bad:
            raise NodeFailure(bad, "at stop")

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()
