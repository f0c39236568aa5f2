"""What the DataFlash and ULog writers share: a binary log file written from start to end,
closed by `close()` or at the end of a `with` block."""

from __future__ import annotations

from pathlib import Path
from typing import Self


class LogFile:
    """A binary log file open for writing from construction on."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._file = self.path.open("wb")

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
