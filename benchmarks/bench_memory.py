"""Peak memory and time of `sysid identify` on long records (the 2 GB bound at 5 million rows).

Writes a record of N rows — time, aileron, rudder, beta, p, r, phi: the appendix A.2 lateral
model under a multisine, with sensor noise, at 100 Hz — then runs `sysid identify` on it in
a child process and reports the child's peak resident memory (getrusage) and wall time; with
--parse-only the child only reads the record (agent.analysis.records.read_record).

    .venv/bin/python benchmarks/bench_memory.py --rows 300000 1000000 5000000 [--parse-only]
    .venv/bin/python benchmarks/bench_memory.py --rows 1000000 --method time
    .venv/bin/python benchmarks/bench_memory.py --rows 6000     # the smoke test: one minute

`--axes lateral` names the channels by role, so `auto` is the aircraft method (frequency
domain); `--method time` measures OKID/ERA with output-error refinement on the same record.

Linux or macOS (ru_maxrss). A 5-million-row record is about 400 MB on disk, written under
--dir (default: a temporary directory, removed afterwards). A child that fails is reported
with the end of its error output, and the benchmark then exits with code 1.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from agent.ident import reference  # noqa: E402

DT = 0.01
BLOCK = 200_000


def write_record(path: Path, rows: int) -> None:
    """The A.2 lateral record repeated to `rows` rows (its 60 s, then again), time running on."""
    noise = {"beta": 1e-3, "p": 1e-3, "r": 1e-3, "phi": 1e-3}
    record = reference.make_record(reference.LATERAL, dt=DT, duration=60.0, seed=3, noise=noise)
    columns = record.columns()
    names = ["aileron", "rudder", "beta", "p", "r", "phi"]
    table = np.column_stack([columns[n] for n in names])
    with path.open("w") as handle:
        handle.write("time," + ",".join(names) + "\n")
        for start in range(0, rows, BLOCK):
            count = min(BLOCK, rows - start)
            index = np.arange(start, start + count)
            block = np.column_stack([index * DT, table[index % len(table)]])
            np.savetxt(handle, block, delimiter=",", fmt="%.9g")


def child(args: list[str]) -> tuple[int, float, float, str]:
    """(exit code, wall s, peak RSS MB, stderr) of one child process."""
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, cwd=ROOT, check=False
    )
    wall = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    per_mb = 1024 * 1024 if sys.platform == "darwin" else 1024  # bytes on macOS, KB on Linux
    # ru_maxrss of the children is the largest of any so far: main() runs them ascending.
    return done.returncode, wall, peak / per_mb, done.stderr


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--rows", type=int, nargs="+", default=[300_000], help="record lengths")
    parser.add_argument("--parse-only", action="store_true", help="only read the record")
    parser.add_argument("--method", default="auto", help="identify's --method (auto: aircraft)")
    parser.add_argument("--dir", type=Path, help="where the records are written")
    args = parser.parse_args()
    failed = []
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        print("rows       MB on disk   exit   wall s   peak RSS MB   last stderr line")
        for rows in sorted(args.rows):  # ascending: ru_maxrss of children only grows
            path = Path(tmp) / f"record_{rows}.csv"
            write_record(path, rows)
            if args.parse_only:
                names = ["aileron", "rudder", "beta", "p", "r", "phi"]
                code = (
                    "from agent.analysis.records import read_record; "
                    f"read_record({str(path)!r}, {names!r})"
                )
                run = ["-c", code]
            else:
                run = [
                    "-m",
                    "agent",
                    "identify",
                    str(path),
                    "--axes",
                    "lateral",
                    "--json",
                    "--method",
                    args.method,
                ]
            exit_code, wall, peak, stderr = child(run)
            size = path.stat().st_size / 1e6
            last = (stderr.strip().splitlines() or [""])[-1][:120]
            print(
                f"{rows:<10d} {size:10.0f}   {exit_code:4d}   {wall:6.1f}   {peak:11.0f}   {last}",
                flush=True,
            )
            if exit_code:
                failed.append(rows)
                print(f"the child on {rows} rows failed; its error output:", file=sys.stderr)
                print(stderr[-4000:], file=sys.stderr)
            path.unlink()
    if failed:
        sys.exit(f"bench_memory: identification failed on {failed} rows")


if __name__ == "__main__":
    main()
