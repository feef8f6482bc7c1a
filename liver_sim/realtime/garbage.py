"""The garbage-collector policy of a node process: the record of every pass (GARBAGE), then after start-up
no automatic full collection (:func:`freeze_garbage`); the executor runs it (:func:`collect_garbage`)."""
from __future__ import annotations

import gc
import time
from collections import deque


class GarbageLog:
    """When the garbage collector ran in this process (gc.callbacks): the last COLLECTIONS_KEPT passes as
    (monotonic start s, end s, generation), the number and longest duration of full (generation 2) ones, and
    how many objects the last :func:`freeze_garbage` froze (counted then: gc.get_freeze_count() walks them
    all, milliseconds with the GIL held, too long for a diagnostics call beside a 1 kHz loop)."""

    COLLECTIONS_KEPT = 64

    def __init__(self):
        self.passes = deque(maxlen=self.COLLECTIONS_KEPT)
        self.full_collections = 0
        self.full_collection_max_s = 0.0
        self.frozen_objects = 0
        self._started = 0.0
        gc.callbacks.append(self._callback)

    def _callback(self, phase: str, info: dict) -> None:
        now = time.monotonic()
        if phase == "start":
            self._started = now
            return
        self.passes.append((self._started, now, info["generation"]))
        if info["generation"] == 2:
            self.full_collections += 1
            self.full_collection_max_s = max(self.full_collection_max_s, now - self._started)

    def during(self, start_s: float, end_s: float) -> list[tuple[float, float, int]]:
        """The passes that overlapped [start_s, end_s] (monotonic s)."""
        return [p for p in list(self.passes) if p[0] < end_s and p[1] > start_s]


#: The collector's record in this process (installed on import, before any node starts).
GARBAGE = GarbageLog()
#: Generation-2 threshold after :func:`freeze_garbage`: never reached, so no automatic full collection.
NO_AUTOMATIC_FULL_COLLECTION = 2 ** 31 - 1
#: How often (s) a node runs the full collection itself, from its executor (never from a loop thread).
FULL_COLLECTION_PERIOD_S = 10.0


def freeze_garbage() -> None:
    """After start-up: collect, then move every object alive into the permanent generation (gc.freeze), which
    no collection scans again, and stop automatic full collections (generation 2 threshold never reached):
    a loop thread then only ever pays for young generations; :func:`collect_garbage` does the full one."""
    gc.collect()
    gc.freeze()
    GARBAGE.frozen_objects = gc.get_freeze_count()
    young, middle, _ = gc.get_threshold()
    gc.set_threshold(young, middle, NO_AUTOMATIC_FULL_COLLECTION)


def collect_garbage() -> None:
    """A full collection of what is not frozen (short after :func:`freeze_garbage`); from the executor."""
    gc.collect(2)


def garbage_fields() -> dict:
    """Diagnostics of the collector policy: frozen objects, automatic full collection on or off, full
    collections run and the longest (s)."""
    return {"gc_frozen_objects": GARBAGE.frozen_objects,
            "gc_automatic_full_collection": gc.get_threshold()[2] < NO_AUTOMATIC_FULL_COLLECTION,
            "gc_full_collections": GARBAGE.full_collections, "gc_full_collection_max_s": GARBAGE.full_collection_max_s}
