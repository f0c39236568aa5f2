"""Smoke test of benchmarks/soak_report.py (`make soak`): the report of a kept flight
directory. A real one takes a flight of minutes (the agent writes a health record a minute,
`agent.runtime.health.HEALTH_S`), so the test writes one as the agent and bench_agent's world
leave it: an execution log of `health {json}` lines with lag histograms, and runs.json."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from agent.runtime import lag_histogram
from tests.benchmarks.bench import SLACK_S, help_text, run

TIMEOUT_S = 60
MINUTES = 4


def _lag(ms: np.ndarray) -> dict:
    p50, p99 = np.percentile(ms, [50, 99])
    return {
        "n": len(ms),
        "p50_ms": p50,
        "p99_ms": p99,
        "max_ms": float(ms.max()),
        "hist": lag_histogram(ms),
    }


def _flight(directory) -> None:
    rng = np.random.default_rng(0)
    lines = []
    for minute in range(1, MINUTES + 1):
        record = {
            "t": 60.0 * minute,
            "lag": _lag(rng.gamma(2.0, 0.3, 6000)),  # ms, a minute of the 10 ms probe
            "lag_identifying": _lag(rng.gamma(2.0, 0.5, 300)),
            "rss_mb": 170.0 + minute,
            "threads": 18,
            "tasks": 16,
            "open_files": 43,
            "counters": {"link_refused": 0, "windows": minute},
            "recorder": {"frames": 6000 * minute},
            "logs": {"dropped": 0},
        }
        message = "health " + json.dumps(record)
        lines.append(json.dumps({"t": record["t"], "level": "INFO", "message": message}))
    (directory / "logs").mkdir()
    (directory / "logs" / "0001_exec_1.jsonl").write_text("\n".join(lines) + "\n")
    runs = [{"t": 60.0 * m + 10, "ok": m != 2, "result_after_s": 1.2} for m in range(MINUTES)]
    (directory / "runs.json").write_text(json.dumps(runs))


@pytest.mark.timeout(TIMEOUT_S + SLACK_S)
def test_report_by_period(tmp_path):
    _flight(tmp_path)
    done = run("soak_report.py", str(tmp_path), "--period", "2", timeout_s=TIMEOUT_S)
    out = done.stdout
    assert f"{MINUTES} health records" in out, out
    periods = re.findall(r"^\s+(\d+–\d+|all)\s+(\d+)/(\d+)\s+([\d.]+)", out, re.MULTILINE)
    assert [p[0] for p in periods] == ["0–2", "2–4", "all"], out
    assert periods[-1][1:3] == ("3", "4")  # identified of flown, over the whole span
    pooled = re.search(r"all drivers p50 ([\d.]+) / p99 ([\d.]+)", out)
    assert pooled, out
    assert 0 < float(pooled[1]) < float(pooled[2]), out
    assert "RSS 171.0 → 174.0 MB" in out


def test_a_directory_without_health_records_is_an_error(tmp_path):
    done = run("soak_report.py", str(tmp_path), timeout_s=TIMEOUT_S, ok=False)
    assert done.returncode != 0
    assert "no health records" in done.stderr


def test_help():
    assert "--window" in help_text("soak_report.py")
