"""The files a command writes: never one of the files it reads, never one file twice, never
half a file.

Files are compared as files, by device and inode after following every link, not as path
strings: `./c.bin`, a symbolic link to it and a hard link to it are all `c.bin`. Each file is
written to a temporary file beside it, flushed to the disk, and renamed over the old one
(`os.replace`, atomic on POSIX), so a write that fails (a full disk, a bug, Ctrl-C) leaves the
old file, or none, and never a cut one. A device or a pipe (`/dev/stdout`) is written directly.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import stat
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import BinaryIO


class OutputError(ValueError):
    """An output that would destroy an input or another output; the message names both."""


def _identity(path: Path) -> tuple[int, int] | None:
    """(device, inode) of the file `path` names, links followed; None if there is none."""
    try:
        info = os.stat(path)
    except OSError:
        return None
    return info.st_dev, info.st_ino


class Outputs:
    """The outputs of one command, checked against its inputs (path → what it is, e.g.
    "the log being imported"; None paths are left out) and against each other."""

    def __init__(self, inputs: Mapping[Path | str | None, str]):
        self._inputs: dict[tuple[int, int], tuple[Path, str]] = {}
        for path, what in inputs.items():
            if path is not None and (found := _identity(Path(path))) is not None:
                self._inputs.setdefault(found, (Path(path), what))
        self._claimed: dict[Path, Path] = {}  # resolved → as given

    def claim(self, path: Path | str, option: str = "--out") -> Path:
        """The resolved path `path` will be written at; OutputError when it is a file the
        command reads, or one it already writes."""
        given = Path(path)
        target = Path(os.path.realpath(given))
        found = _identity(target)
        if found is not None and found in self._inputs and _regular(target):
            source, what = self._inputs[found]
            raise OutputError(
                f"{option} {given}: that is {source}, {what}; the command would destroy it: "
                f"give another {option}"
            )
        for other_target, other in self._claimed.items():
            same = other_target == target or (
                found is not None and found == _identity(other_target)
            )
            if same:
                raise OutputError(
                    f"{option} {given}: the same file as {other}, which this command also "
                    "writes: give each output its own file"
                )
        self._claimed[target] = given
        return target

    def claimed(self, path: Path | str) -> Path:
        """The resolved path of `path`, claimed now if it was not already."""
        target = Path(os.path.realpath(path))
        return target if target in self._claimed else self.claim(path)

    @contextlib.contextmanager
    def open(self, path: Path | str) -> Iterator[BinaryIO]:
        """A binary file to write `path` through: renamed over `path` when the block ends
        well, removed when it raises."""
        target = self.claimed(path)
        if target.exists() and not _regular(target):  # a device or a pipe: no rename there
            with target.open("wb") as handle:
                yield handle
            return
        mode = stat.S_IMODE(target.stat().st_mode) if target.exists() else None
        temporary, handle = _temporary(target)
        try:
            with handle:
                yield handle
                handle.flush()
                os.fsync(handle.fileno())
            if mode is not None:
                os.chmod(temporary, mode)
            os.replace(temporary, target)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(temporary)
            raise
        _sync_directory(target.parent)

    def write_bytes(self, path: Path | str, data: bytes) -> None:
        """`data` as the whole of `path`, through a temporary file."""
        with self.open(path) as handle:
            handle.write(data)

    def write_text(self, path: Path | str, text: str) -> None:
        """`text` (UTF-8) as the whole of `path`, through a temporary file."""
        self.write_bytes(path, text.encode("utf-8"))


def _regular(path: Path) -> bool:
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except OSError:
        return False


def _temporary(target: Path) -> tuple[Path, BinaryIO]:
    """A new hidden file beside `target` (same directory, so the rename stays on one file
    system), created with the mode a new file gets (0o666 less the umask)."""
    while True:
        name = target.with_name(f".{target.name}.{secrets.token_hex(4)}.tmp")
        try:
            fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o666)
        except FileExistsError:
            continue
        return name, os.fdopen(fd, "wb")


def _sync_directory(directory: Path) -> None:
    """The rename itself on the disk; some file systems cannot sync a directory: no matter."""
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
