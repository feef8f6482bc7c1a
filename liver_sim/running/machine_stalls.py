"""Machine stalls: spans in which this machine ran none of its threads that were due, measured by a sentinel,
so that a gap in a loop can be told from the product's own doing.

On a virtual machine the host may not run a virtual CPU for milliseconds (docs/performance.md gives what was seen here),
often on both CPUs at once, on an idle VM as beside busy loops. The guest's clocks go on, so every loop on that CPU
misses its deadlines and nothing inside the guest can tell why but a thread that should have run there: a sentinel,
one process per CPU, pinned to it at SCHED_FIFO 99 (above every loop), which sleeps to absolute deadlines
SENTINEL_PERIOD_S apart and notes each wake-up later than STALL_S. A stall is (last wake-up before it, late wake-up)
on the time.monotonic() scale; a loop's gap overlapping a stall of either CPU was, for that overlap, the machine's.

`python -m liver_sim.running.machine_stalls OUT CPU` runs the sentinel of CPU until SIGTERM or SIGINT, one JSON line
[start_s, end_s] per stall in OUT. Refused SCHED_FIFO, it would take the loops' own use of the CPU for the
machine's stalls, so it says why and exits without writing OUT: no gap is then put down to the machine.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from liver_sim.base.process_settings import set_realtime_priority
from liver_sim.running.launcher import die_with_parent

#: The sentinel wakes every this many seconds.
SENTINEL_PERIOD_S = 0.001
#: A wake-up at least this late (s) is a stall.
STALL_S = 0.002
#: The sentinel's SCHED_FIFO priority: above every loop of the product.
SENTINEL_PRIORITY = 99
#: What a report says the stalls are.
SENTINEL_DESCRIPTION = ("per CPU, a process pinned to it at SCHED_FIFO 99 waking every 1 ms; a stall is a wake-up "
                        "2 ms late or more")


def watch(out, stop, clock=time.monotonic, sleep=time.sleep) -> None:
    """Sleep to deadlines SENTINEL_PERIOD_S apart until `stop()`; write each stall to `out` as a JSON line
    [start_s, end_s] (start: the wake-up before the late one; the next deadlines restart from the late one)."""
    deadline = previous = clock()
    while not stop():
        deadline += SENTINEL_PERIOD_S
        remaining = deadline - clock()
        if remaining > 0:
            sleep(remaining)
        now = clock()
        if now - deadline >= STALL_S:
            out.write(json.dumps([previous, now]) + "\n")
            out.flush()
            deadline = now
        previous = now


def read_stalls(paths: list[Path], window_s: tuple[float, float] | None = None) -> np.ndarray:
    """The stalls (K, 2) [start_s, end_s] the sentinels wrote to `paths`, those overlapping `window_s` if given."""
    rows = [json.loads(line) for path in paths for line in Path(path).read_text().splitlines() if line.strip()]
    stalls = np.asarray(rows, dtype=float).reshape(-1, 2)
    if window_s is not None:
        stalls = stalls[(stalls[:, 1] > window_s[0]) & (stalls[:, 0] < window_s[1])]
    return stalls


class Sentinels:
    """A sentinel process per CPU this process may run on: :meth:`start` starts them, each writing
    `log_dir`/machine_stalls_cpu<N>.jsonl and dying with the thread that started it (processes.die_with_parent),
    :meth:`stop` stops them, :meth:`stalls` reads what they noted."""

    def __init__(self, log_dir: Path):
        self.files = {cpu: Path(log_dir) / f"machine_stalls_cpu{cpu}.jsonl" for cpu in sorted(os.sched_getaffinity(0))}
        self._processes = []

    def start(self) -> None:
        for cpu, path in self.files.items():
            path.parent.mkdir(parents=True, exist_ok=True)
            command = [sys.executable, "-m", "liver_sim.running.machine_stalls", str(path), str(cpu)]
            self._processes.append(subprocess.Popen(command, preexec_fn=die_with_parent(os.getpid())))

    def stop(self) -> None:
        for process in self._processes:
            process.terminate()
            process.wait(timeout=10)

    def stalls(self, window_s: tuple[float, float] | None = None) -> np.ndarray:
        return read_stalls([path for path in self.files.values() if path.exists()], window_s)


def stall_summary(stalls: np.ndarray) -> dict:
    """count, largest_s, total_s of `stalls` (K, 2), and how they were measured."""
    lengths = stalls[:, 1] - stalls[:, 0]
    return {"count": int(len(stalls)), "largest_s": float(lengths.max(initial=0.0)), "total_s": float(lengths.sum()),
            "sentinel": SENTINEL_DESCRIPTION}


def gaps_with_stalls(times_s: np.ndarray, bound_s: float, stalls: np.ndarray) -> list[dict]:
    """Each gap longer than `bound_s` between consecutive `times_s` (sorted, monotonic s), with the time the
    machine stalled inside it: {'start_s', 'gap_s', 'machine_s', 'product_s' = gap_s - machine_s}."""
    times_s = np.asarray(times_s, dtype=float)
    long = np.flatnonzero(np.diff(times_s) > bound_s)
    gaps = []
    for i in long:
        start, end = times_s[i], times_s[i + 1]
        overlap = _covered_s(stalls, start, end)
        gaps.append({"start_s": float(start), "gap_s": float(end - start), "machine_s": float(overlap),
                     "product_s": float(end - start - overlap)})
    return gaps


def _covered_s(stalls: np.ndarray, start: float, end: float) -> float:
    """How long (s) within [start, end] at least one of `stalls` lasted (overlapping stalls count once)."""
    inside = np.clip(stalls, start, end)
    inside = inside[inside[:, 1] > inside[:, 0]]
    covered, reached = 0.0, start
    for begin, finish in inside[np.argsort(inside[:, 0])]:
        if finish > reached:
            covered += finish - max(begin, reached)
            reached = finish
    return covered


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2 or not args[1].isdigit():
        print("usage: python -m liver_sim.running.machine_stalls OUT CPU", file=sys.stderr)
        return 2
    os.sched_setaffinity(0, {int(args[1])})
    refused = set_realtime_priority(SENTINEL_PRIORITY)
    if refused:
        print(f"machine_stalls: not watching CPU {args[1]}: {refused}", file=sys.stderr)
        return 1
    stopping = []
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stopping.append(True))
    with open(args[0], "w") as out:
        watch(out, lambda: bool(stopping))
    return 0


if __name__ == "__main__":
    sys.exit(main())
