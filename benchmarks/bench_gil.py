"""How long the event loop's thread waits for the GIL while the log writer thread formats an
excitation log, at several switch intervals (`sys.setswitchinterval`, the agent's
`SWITCH_INTERVAL_S`).

    .venv/bin/python benchmarks/bench_gil.py [--cycles 40] [--intervals 1,0.5,0.25,0.1]
    .venv/bin/python benchmarks/bench_gil.py --cycles 2 --intervals 0.25   # the smoke test

Each interval runs in its own process (the loop thread at SCHED_FIFO 10 when allowed, as the
agent with `realtime_priority`): the real `LogWriter` and `Logbook` write a 19 s, 83-column
excitation log at 100 Hz (the agent's window with its margins) every 0.45 s, and a 10 ms sleep
probe, the agent's lag probe, measures how late the loop wakes in the 0.15 s after each hand-
over (writing) and in the 0.3 s after that (idle). Prints p50, p99 and max of both, in ms.
A child that fails stops the benchmark (exit code 1) with its error output.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


async def _probe(seconds: float, into: list[float]) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + seconds
    while loop.time() < end:
        t0 = loop.time()
        await asyncio.sleep(0.01)
        into.append(loop.time() - t0 - 0.01)


async def _one(interval_s: float, cycles: int) -> str:
    from agent.excitation.scheduler import Window
    from agent.logs import Logbook, LogWriter

    realtime = "SCHED_FIFO 10"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
    except (OSError, AttributeError):
        realtime = "normal scheduling"
    sys.setswitchinterval(interval_s)
    columns = ["time", *(f"c{k}" for k in range(82))]
    rng = np.random.default_rng(0)
    rows = np.column_stack([np.arange(1900) * 0.01, rng.normal(size=(1900, 82))])
    writing: list[float] = []
    idle: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        writer = LogWriter(Path(tmp))
        try:
            book = Logbook(writer, columns, ["-"] * len(columns), "0" * 64, 100.0)
            for _ in range(cycles):
                book.excitation(Window("bench", "lateral", 0.0, 19.0, "finished", ""), rows)
                await _probe(0.15, writing)
                await _probe(0.3, idle)
        finally:
            writer.close()
    w, i = np.array(writing) * 1e3, np.array(idle) * 1e3
    return (
        f"| {interval_s * 1e3:g} ms | {np.median(w):.2f} / {np.percentile(w, 99):.2f} / "
        f"{w.max():.2f} | {np.median(i):.2f} / {np.percentile(i, 99):.2f} / {i.max():.2f} "
        f"| {w.size} + {i.size} | {realtime} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--cycles", type=int, default=40, help="excitation logs written")
    parser.add_argument("--intervals", default="1,0.5,0.25,0.1", help="ms, comma-separated")
    parser.add_argument("--one", type=float, help=argparse.SUPPRESS)  # a child: one interval
    args = parser.parse_args()
    if args.cycles < 1:
        parser.error("--cycles: at least 1")
    if args.one is not None:
        print(asyncio.run(_one(args.one / 1000, args.cycles)))
        return
    print(
        "| switch interval | lag writing p50 / p99 / max (ms) | idle p50 / p99 / max (ms) "
        "| samples | loop thread |"
    )
    print("|---|---|---|---|---|")
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    for ms in args.intervals.split(","):
        done = subprocess.run(
            [sys.executable, __file__, "--one", ms, "--cycles", str(args.cycles)],
            capture_output=True,
            text=True,
            env=env,
            check=False,
        )
        if done.returncode:
            sys.exit(
                f"bench_gil: the {ms} ms child failed (exit code {done.returncode}):\n"
                f"{done.stdout}{done.stderr}"
            )
        print(done.stdout.strip(), flush=True)


if __name__ == "__main__":
    main()
