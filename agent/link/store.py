"""The link's state on disk, beside the sans-I/O codec: this end's frame counter and the replay
state (the highest counter accepted from each source), so that neither is ever reused or
forgotten across restarts.

Counter file: one decimal number, the end of the block of counters reserved, written (fsynced)
before any counter of the block goes out. Seen file: JSON `{"key": <fingerprint>, "floors":
{<source address, 16 hex digits>: <highest counter accepted>}}`, bound to the key's
fingerprint; each write goes through a temporary file, fsynced, and a rename. Both are read
strictly: anything that is not a counter refuses the link with the reason (docs/link.md).
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Mapping
from pathlib import Path

log = logging.getLogger(__name__)

# Counters reserved per write of the counter file: a reboot skips at most this many.
COUNTER_BLOCK = 1 << 16
# The frame header's counter is a uint64; files holding more (or a jump near it) are refused.
COUNTER_MAX = 1 << 63


class CounterStore:
    """The sender's frame counter, never reused across restarts.

    With a file, counters are reserved in blocks: the file holds the end of the reserved block,
    written (and fsynced) before any counter of the block is used. A disk that cannot be
    written costs this end its sending (each attempt to reserve raises OSError, which the
    session counts; at start it is logged), never its receiving, so an Abort still arrives
    and acts. Without a file, the counter starts at the wall clock in
    microseconds (monotonic across restarts while the clock is)."""

    def __init__(self, path: Path | None = None):
        self._path = path
        if path is None:
            self._next, self._reserved = time.time_ns() // 1000, 1 << 63
        else:
            start = _read_counter(path) if path.exists() else 0
            self._next, self._reserved = start, start
            try:  # the file says from the start that this end has used the key
                self._reserve()
            except OSError as exc:
                log.error("%s: frame counters not reserved (%s); sending waits for it", path, exc)

    def _reserve(self) -> None:
        end = self._next + COUNTER_BLOCK
        tmp = self._path.with_suffix(".tmp")
        with open(tmp, "w") as handle:
            handle.write(str(end))
            handle.flush()
            os.fsync(handle.fileno())
        tmp.replace(self._path)
        self._reserved = end  # only once it is on disk

    def next(self) -> int:
        """The next counter; OSError when its block cannot be reserved on disk."""
        if self._next >= self._reserved:
            self._reserve()
        value = self._next
        self._next += 1
        return value


def _read_counter(path: Path) -> int:
    """The counter file's number; ValueError naming the file when it is not one in range."""
    try:
        text = path.read_text().strip()
        value = int(text) if text.isdigit() and len(text) <= 20 else -1
    except (OSError, ValueError) as exc:  # UnicodeDecodeError is a ValueError
        raise ValueError(f"{path}: the frame counter is unreadable ({exc})") from exc
    if not 0 <= value < COUNTER_MAX:
        raise ValueError(
            f"{path}: the frame counter {text[:40]!r} is not a whole number below 2**63: "
            "restore the file or give both ends a new key (sysid keygen)"
        )
    return value


def read_floors(path: Path, fingerprint: str) -> dict[bytes, int]:
    """The highest counter accepted from each source, from the seen file; ValueError naming
    the file and what to do when it is not a replay state. A state of another key (its
    fingerprint differs) says nothing of this key's frames: empty."""
    try:
        document = json.loads(path.read_text())
        if isinstance(document, dict) and "floors" in document:
            if document.get("key") != fingerprint:
                log.warning("%s: replay state of another key; starting empty", path)
                return {}
            document = document["floors"]
        if not isinstance(document, dict):
            raise ValueError(f"a map of sources, not {type(document).__name__}")
        floors = {_address(k): _floor(v) for k, v in document.items()}
    except (OSError, ValueError, RecursionError) as exc:  # json and Unicode errors included
        raise ValueError(
            f"{path}: the replay state is unreadable ({exc}); without it every frame "
            "recorded under this key would be accepted again: restore the file or "
            "give both ends a new key (sysid keygen)"
        ) from exc
    return floors


def _address(text: object) -> bytes:
    if not isinstance(text, str) or len(text) != 16:
        raise ValueError(f"{str(text)[:40]!r} is not a 64-bit radio address in hex")
    return bytes.fromhex(text)


def _floor(value: object) -> int:
    # JSON's Infinity and 1e400 are floats, and a bool is an int to Python: neither is a counter.
    if type(value) is not int or not -1 <= value < COUNTER_MAX:
        raise ValueError(f"{str(value)[:40]!r} is not a frame counter (a whole number ≥ -1)")
    return value


class SeenStore:
    """The replay state's file: the highest counter accepted from each source (the codec's
    `floors()`), bound to the key's fingerprint, and what of it is known to be on disk."""

    def __init__(self, path: Path, fingerprint: str):
        self.path, self.fingerprint = path, fingerprint
        self._saved: dict[bytes, int] = {}

    def load(self) -> dict[bytes, int]:
        """The floors on disk ({} when there is no file yet), which count as saved; ValueError
        naming the file and what to do when it is not a replay state."""
        floors = read_floors(self.path, self.fingerprint) if self.path.exists() else {}
        self._saved = dict(floors)
        return floors

    def changed(self, floors: Mapping[bytes, int]) -> dict[bytes, int] | None:
        """A snapshot of `floors` to write, taken on the caller's thread; None: the file
        already holds them."""
        snapshot = dict(floors)
        return None if snapshot == self._saved else snapshot

    def write(self, snapshot: Mapping[bytes, int]) -> None:
        """Write a snapshot, fsynced, through a temporary file (file-system work: the session
        runs it off the event loop). Raises OSError as the disk does."""
        tmp = self.path.with_suffix(".tmp")
        floors = {a.hex(): h for a, h in snapshot.items()}
        with open(tmp, "w") as handle:
            handle.write(json.dumps({"key": self.fingerprint, "floors": floors}))
            handle.flush()
            os.fsync(handle.fileno())
        tmp.replace(self.path)

    def mark_saved(self, snapshot: dict[bytes, int]) -> None:
        """A snapshot is on disk (call only once `write` has returned)."""
        self._saved = snapshot

    def save(self, floors: Mapping[bytes, int]) -> bool:
        """Write `floors` if the file does not hold them yet (True: written; False: nothing
        new). OSError when the disk refuses: the state is then still unsaved, and the next
        call tries again."""
        snapshot = self.changed(floors)
        if snapshot is None:
            return False
        self.write(snapshot)
        self.mark_saved(snapshot)
        return True
