"""What several benchmarks share: the link key file, and the error a benchmark stops with."""

from __future__ import annotations

import os
import secrets
from pathlib import Path

KEY_BYTES = 32  # as `sysid keygen`


class BenchError(RuntimeError):
    """The benchmark could not measure what it is for (the message says what, and where its
    logs were kept); its command exits non-zero."""


def write_key(path: Path) -> bytes:
    """A new random link key in `path` (hex), created readable by its owner alone, as `sysid
    keygen` makes it: `agent.config.load_key` refuses a key file other users can read."""
    key = secrets.token_bytes(KEY_BYTES)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as handle:
        handle.write(key.hex() + "\n")
    return key


def tail(path: Path, lines: int = 15) -> str:
    """The last `lines` lines of a log file, indented, for an error message ("" if none)."""
    try:
        text = path.read_text(errors="replace").splitlines()[-lines:]
    except OSError:
        return ""
    return "\n".join(f"    {line}" for line in text)
