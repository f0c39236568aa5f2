"""`sysid` in a process of its own under an address-space limit, for inputs that take
gigabytes when a bound is missing (/dev/zero, a sweep of 10⁸ values, a decimation of 10⁷):
a missing bound is then a MemoryError in that process — a failed test — not a machine out of
memory, nor a test that never ends.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# The analysis commands map about 550 MB of address space themselves (numpy, scipy and
# matplotlib, one BLAS thread); this leaves them some 450 MB for a test's input.
LIMIT_BYTES = 1 << 30
# A bounded command refuses such an input within seconds; an unbounded one reaches the limit
# in about as long. Generous for a loaded machine.
TIMEOUT_S = 120


def sysid(
    *args: str, cwd: Path, limit: int = LIMIT_BYTES, stdout=subprocess.PIPE
) -> subprocess.CompletedProcess:
    """`python -m agent ARGS` in `cwd` with at most `limit` bytes of address space."""

    def cap() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    return subprocess.run(
        [sys.executable, "-m", "agent", *args],
        cwd=cwd,
        stdout=stdout,
        stderr=subprocess.PIPE,
        text=True,
        timeout=TIMEOUT_S,
        preexec_fn=cap,
        env={
            "PYTHONPATH": str(ROOT),
            "PATH": os.environ.get("PATH", "/usr/bin:/bin"),
            "OPENBLAS_NUM_THREADS": "1",
            "MPLBACKEND": "Agg",
        },
        check=False,
    )
