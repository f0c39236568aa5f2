"""What a long flight did to the agent, period by period, from the directory `bench_agent.py
--keep DIR` (or `make soak`) left: the agent's health records (one a minute, in its execution
log) and the ground's record of each excitation.

    .venv/bin/python benchmarks/soak_report.py soak-logs               # 30-minute periods
    .venv/bin/python benchmarks/soak_report.py soak-logs --window 0 45 # minutes 0-45 only

Per period: excitations identified, the agent's RSS, threads, asyncio tasks and open files at
its end, and the event-loop lag of all its samples together (p99 with all drivers, p99 and max
while identifying). Then the whole span and the counters that moved.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from agent.runtime import lag_percentile


def health_records(directory: Path) -> list[dict]:
    records = []
    for path in sorted((directory / "logs").glob("*_exec_*")):
        for line in path.read_text().splitlines():
            message = json.loads(line)["message"]
            if message.startswith("health "):
                records.append(json.loads(message[len("health ") :]))
    return records


def _pooled(rows: list[dict], key: str, q: float) -> float:
    hists = [r[key]["hist"] for r in rows if r[key]["n"]]
    return lag_percentile(hists, q) if hists else float("nan")


def _row(label: str, rows: list[dict], runs: list[dict]) -> str:
    last = rows[-1]
    ident = [r for r in rows if r["lag_identifying"]["n"]]
    worst = max((r["lag_identifying"]["max_ms"] for r in ident), default=float("nan"))
    return (
        f"{label:>9} {sum(r['ok'] for r in runs):>4}/{len(runs):<4}{last['rss_mb']:>8.1f}"
        f"{last['threads']:>8}{last['tasks']:>6}{last['open_files']:>6}"
        f"{_pooled(rows, 'lag', 99):>10.2f}{_pooled(rows, 'lag_identifying', 99):>10.2f}"
        f"{worst:>9.1f}"
    )


def report(directory: Path, period_min: float, window: tuple[float, float] | None) -> str:
    records = health_records(directory)
    if not records or "hist" not in records[0]["lag"]:
        raise SystemExit(f"{directory}: no health records with lag histograms")
    runs_path = directory / "runs.json"
    runs = json.loads(runs_path.read_text()) if runs_path.exists() else []
    t0 = records[0]["t"] - 60.0  # each record covers the minute before it
    minute = [round((r["t"] - t0) / 60.0, 1) for r in records]  # a record a minute, ±ms
    if window:
        keep = [window[0] < m <= window[1] for m in minute]
        records = [r for r, k in zip(records, keep, strict=True) if k]
        minute = [m for m, k in zip(minute, keep, strict=True) if k]
    lines = [
        f"{directory}: {len(records)} health records, minutes {minute[0] - 1:.0f}–"
        f"{minute[-1]:.0f} of the flight",
        f"{'minutes':>9} {'identified':<9}{'RSS MB':>8}{'threads':>8}{'tasks':>6}{'files':>6}"
        f"{'p99 all':>10}{'p99 ident':>10}{'max id':>9}",
    ]
    start = minute[0] - 1
    while start < minute[-1]:
        end = start + period_min
        rows = [r for r, m in zip(records, minute, strict=True) if start < m <= end]
        span = [run for run in runs if start < (run["t"] - t0) / 60 <= end]
        if rows:
            lines.append(_row(f"{start:.0f}–{min(end, minute[-1]):.0f}", rows, span))
        start = end
    span = [run for run in runs if minute[0] - 1 < (run["t"] - t0) / 60 <= minute[-1]]
    lines.append(_row("all", records, span))
    first, last = records[0], records[-1]
    lines.append(
        f"lag, all samples together: all drivers p50 {_pooled(records, 'lag', 50):.2f} / p99 "
        f"{_pooled(records, 'lag', 99):.2f} / p99.9 {_pooled(records, 'lag', 99.9):.2f} ms; "
        f"identifying ({sum(r['lag_identifying']['n'] for r in records)} samples) p50 "
        f"{_pooled(records, 'lag_identifying', 50):.2f} / p99 "
        f"{_pooled(records, 'lag_identifying', 99):.2f} / p99.9 "
        f"{_pooled(records, 'lag_identifying', 99.9):.2f} ms (bin upper edges, 0.05 ms bins)"
    )
    lines.append(
        f"RSS {first['rss_mb']:.1f} → {last['rss_mb']:.1f} MB (max "
        f"{max(r['rss_mb'] for r in records):.1f}); threads {first['threads']} → "
        f"{last['threads']}; tasks {first['tasks']} → {last['tasks']}; open files "
        f"{first['open_files']} → {last['open_files']}"
    )
    moved = {k: v for k, v in sorted(last["counters"].items()) if v != first["counters"].get(k)}
    lines.append(f"agent counters at the end: {json.dumps(moved)}")
    lines.append(f"recorder counters at the end: {json.dumps(last['recorder'])}")
    lines.append(f"logs at the end: {json.dumps(last['logs'])}")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("directory", type=Path)
    parser.add_argument("--period", type=float, default=30.0, help="minutes per row")
    parser.add_argument(
        "--window",
        type=float,
        nargs=2,
        metavar=("FROM", "TO"),
        help="only these minutes of the flight",
    )
    args = parser.parse_args()
    print(report(args.directory, args.period, tuple(args.window) if args.window else None))


if __name__ == "__main__":
    main()
