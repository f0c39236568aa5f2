"""The performance table: every number measured on this machine, now, by one command; printed
as Markdown with the date, the machine and the commit, for benchmarks/README.md.

    make bench-table                                  # 20-25 minutes here
    .venv/bin/python benchmarks/table.py --quick      # fewer samples
    .venv/bin/python benchmarks/table.py --sections identification link --seeds 1 \
        --no-peers --link-results 1                   # the smoke test: seconds

Sections, each from its own benchmark (run alone for more detail):
1. identification time and accuracy against python-control and SIPPY, side by side in this
   process (bench_identify.py: the A.2 lateral model, the thesis's multisine, 5 % noise);
2. event-loop lag of the agent while it identifies, with the sensors and recorder at 100 and
   at 400 Hz, and CPU per component (bench_agent.py: the real agent process against the
   simulated flight, an excitation every --every s);
3. bytes on air per identification result (bench_link.py: the real digi-xbee transport over
   the emulated 900HP radios);
4. abort latency, switch low to trim on the MAVLink wire, over repeated drops (bench_abort.py).

The agent runs as it would fly: [runtime] realtime_priority = 10 (SCHED_FIFO for its event
loop; refused without root or CAP_SYS_NICE, and then said so in the table), the world (JSBSim,
emulated autopilot, sensors, radios, ground) at nice 10 since it is not on the flight computer.
`--sections` measures some of the four; `--no-peers` leaves python-control and SIPPY out (they
are the `bench` extra, which `make bench-table` installs).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("JSBSIM_DEBUG", "0")  # no JSBSim banner in the table
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import asyncio
import datetime
import platform
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import bench_identify as bi  # noqa: E402
import bench_link  # noqa: E402
import numpy as np  # noqa: E402
from common import BenchError  # noqa: E402

from agent.ident import Settings  # noqa: E402

WORLD_NICE = 10
REALTIME = 10  # the agent's [runtime] realtime_priority; --realtime 0: normal scheduling


def machine() -> str:
    info = Path("/proc/cpuinfo").read_text()
    names = [
        line.split(":", 1)[1].strip() for line in info.splitlines() if line.startswith("model name")
    ]
    model = names[0] if names else platform.processor() or "unknown CPU"
    mem = next(
        line.split()[1]
        for line in Path("/proc/meminfo").read_text().splitlines()
        if line.startswith("MemTotal")
    )
    git = ["git", "-C", str(ROOT)]
    commit = (
        subprocess.run(
            [*git, "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        ).stdout.strip()
        or "unknown"
    )
    dirty = subprocess.run(
        [*git, "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True
    ).stdout.strip()
    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    return (
        f"Measured {now} on {model}, {os.cpu_count()} cores, {int(mem) / 2**20:.0f} GiB, "
        f"Linux {platform.release()}, Python {platform.python_version()}, numpy "
        f"{np.__version__}; commit {commit}{' with local changes' if dirty else ''}."
    )


SECTIONS = ("identification", "link", "abort", "lag")


def identification(seeds: int, noise: float = 0.05, peers: bool = True) -> list[str]:
    methods = [
        ("suas-sysid default (OKID/ERA + output error)", bi.run_ours(Settings())),
        ("suas-sysid OKID/ERA, no refinement", bi.run_ours(Settings(refine=False))),
    ]
    if peers:
        methods += [
            ("python-control 0.10 markov + ERA", bi.run_python_control),
            ("SIPPY N4SID", bi.run_sippy("N4SID")),
            ("SIPPY MOESP", bi.run_sippy("MOESP")),
            ("SIPPY PARSIM-K", bi.run_sippy("PARSIM-K")),
        ]
    warm, _ = bi.records(noise, 999)
    for _, method in methods:
        method(warm)
    data = [bi.records(noise, seed) for seed in range(seeds)]
    train, val = [d[0] for d in data], [d[1] for d in data]
    bound = bi.crb_relative(noise)
    lines = [
        f"**Identification** — thesis appendix A.2 lateral model, the thesis's multisine (30 s at "
        f"50 Hz), {100 * noise:g} % output noise, {seeds} seeds, one BLAS thread each. Eigenvalue "
        f"error, median over seeds (Cramér–Rao 1-σ: Dutch roll {100 * bound[0]:.2f} %, roll "
        f"{100 * bound[1]:.2f} %, spiral {100 * bound[2]:.2f} %).",
        "",
        "| method | Dutch roll | roll | spiral | validation TIC | ms per identification "
        "| time ÷ suas-sysid default |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    ours_ms = None
    for name, method in methods:
        outcomes = [method(exp) for exp in train]
        errors = np.median([bi.mode_errors(o.eigenvalues) for o in outcomes], axis=0)
        tic = statistics.median(bi.validation_tic(o, v) for o, v in zip(outcomes, val, strict=True))
        ms = 1e3 * statistics.median(o.seconds for o in outcomes)
        ours_ms = ours_ms or ms
        cells = " | ".join(f"{bi.fmt_pct(e)} %" if np.isfinite(e) else "miss" for e in errors)
        lines.append(f"| {name} | {cells} | {tic:.3f} | {ms:.1f} | {ms / ours_ms:.2f} |")
    return lines


def loop_lag(
    minutes: float, every: float, rates: tuple[float, ...], realtime: int | None
) -> list[str]:
    import bench_agent  # the simulated flight and the agent: only for this section

    results = [
        asyncio.run(
            bench_agent.measure(
                bench_agent.Flight(
                    minutes=minutes,
                    every=every,
                    world_nice=WORLD_NICE,
                    realtime=realtime,
                    rate=rate,
                )
            )
        )
        for rate in rates
    ]
    refused = any(
        (r["health_last"] or {}).get("counters", {}).get("realtime_refused") for r in results
    )
    if realtime is None:
        priority = "normal scheduling"
    else:
        priority = "normal scheduling (SCHED_FIFO refused)" if refused else f"SCHED_FIFO {realtime}"
    lines = [
        f"**Event-loop lag** — the real `sysid agent` against the simulated flight "
        f"({minutes:g} min per rate, a lateral excitation every {every:g} s, identified in the "
        f"worker), its loop thread at {priority}, the world at nice {WORLD_NICE}. A 10 ms sleep "
        "probe; percentiles of all its samples over the runs, pooled from the agent's health "
        "records (0.05 ms bins, upper edges). The result's time runs from the excitation's end "
        "(free response included) to its arrival at the ground: recorder delay, identification "
        "in the worker, the radio.",
        "",
        "| sensors and recorder | identified | result at the ground after the run (median / max) "
        "| p50 while identifying | p99 while identifying | max while identifying "
        "| p99 all drivers | p99 idle loop, same box |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    nan = float("nan")
    for r in results:
        ident, lag, base = r["lag_identifying"], r["lag"], r["baseline_lag"]
        after = r["result_after_s"] or {"median": nan, "max": nan}
        lines.append(
            f"| {r['rate_hz']:g} Hz | {r['runs_identified']}/{r['runs']} "
            f"| {after['median']:.2f} / {after['max']:.2f} s "
            f"| {ident.get('p50_ms_pooled', nan):.2f} ms "
            f"| {ident.get('p99_ms_pooled', nan):.2f} ms "
            f"| {ident.get('max_ms', nan):.1f} ms "
            f"| {lag.get('p99_ms_pooled', nan):.2f} ms | {base['p99_ms']:.2f} ms |"
        )
    lines += [
        "",
        "**CPU per component** (percent of one core over the same runs; RSS at the end)",
        "",
        "| sensors and recorder | agent event-loop thread | agent's other threads (MAVSDK, "
        "radio, serial) | identification worker | world (JSBSim, autopilot, sensors, radios, "
        "ground) | agent RSS |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        loop_cpu = r["agent_loop_thread_cpu_percent"]
        lines.append(
            f"| {r['rate_hz']:g} Hz | {loop_cpu:.1f} % | {r['agent_cpu_percent'] - loop_cpu:.1f} % "
            f"| {r['worker_cpu_percent']:.1f} % | {r['world_cpu_percent']:.1f} % "
            f"| {r['agent_rss_mb']['last']:.0f} MB |"
        )
    return lines


def link(results: int = bench_link.RUNS) -> list[str]:
    size = len(
        bench_link.msgpack.packb(
            bench_link.messages.to_dict(bench_link.full_result()), use_bin_type=True
        )
    )
    lines = [
        f"**Bytes on air per result** — one full-model result (8 states, 4 inputs, 8 outputs, "
        f"5 modes with every quality index; {size} bytes of MessagePack) through the real "
        "digi-xbee transport and the emulated 900HP radios; median of "
        f"{results} results, retries, link acks, heartbeats and status in that interval "
        "included (30 bytes of radio overhead per frame).",
        "",
        "| RF rate | loss per attempt | frames | bytes on air | delivery median | worst |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for rate, loss in ((200_000.0, 0.0), (200_000.0, 0.2), (10_000.0, 0.0)):
        frames, air, median, worst = asyncio.run(bench_link.measure(rate, loss, results))
        lines.append(
            f"| {rate / 1000:g} kb/s | {100 * loss:g} % | {frames} | {air:.0f} | {median:.2f} s "
            f"| {worst:.2f} s |"
        )
    return lines


def abort(drops: int, realtime: int | None) -> list[str]:
    import bench_abort  # the simulated flight and the agent: only for this section

    s = bench_abort.summary(asyncio.run(bench_abort.measure(drops, realtime=realtime)))
    a, b = s["report_to_trim"], s["flip_to_trim"]
    return [
        f"**Abort latency** — the pilot drops the switch at a random moment of {s['drops']} "
        "lateral runs; times stamped by the emulated ArduPlane (ArduPilot's own RCx_OPTION 46 "
        "kill off, so the trim is the agent's doing).",
        "",
        "| interval | median | p95 | max |",
        "|---|---:|---:|---:|",
        f"| RC_CHANNELS with the switch low → trim override on the wire | {a['median_ms']:.1f} ms "
        f"| {a['p95_ms']:.1f} ms | {a['max_ms']:.1f} ms |",
        f"| pilot's flip → trim override on the wire | {b['median_ms']:.1f} ms "
        f"| {b['p95_ms']:.1f} ms | {b['max_ms']:.1f} ms |",
        "",
        f"At most {s['most_commands_before_trim']} excitation command(s) went out between the "
        "switch report and the trim."
        + "".join(f" A run ended before its drop (not counted): {d}." for d in s["other_ends"]),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="3 seeds, 3 min per rate, 10 drops")
    parser.add_argument(
        "--sections", nargs="+", choices=SECTIONS, default=list(SECTIONS), help="what to measure"
    )
    parser.add_argument("--seeds", type=int)
    parser.add_argument("--no-peers", action="store_true", help="no python-control, no SIPPY")
    parser.add_argument(
        "--link-results", type=int, default=bench_link.RUNS, help="results per rate and loss"
    )
    parser.add_argument("--minutes", type=float, help="per sensor rate")
    parser.add_argument("--every", type=float, default=30.0, help="s between excitations")
    parser.add_argument("--drops", type=int)
    parser.add_argument("--rates", type=float, nargs="+", default=[100.0, 400.0])
    parser.add_argument(
        "--realtime",
        type=int,
        default=REALTIME,
        metavar="PRIORITY",
        help="the agent's realtime_priority (default 10; 0: normal scheduling)",
    )
    args = parser.parse_args()
    missing = [] if args.no_peers or "identification" not in args.sections else bi.missing_peers()
    if missing:
        parser.error(
            f"{' and '.join(missing)} not installed: pip install -e '.[bench]' (make "
            "bench-table does), or --no-peers"
        )
    realtime = args.realtime or None
    seeds = args.seeds or (3 if args.quick else 10)
    minutes = args.minutes or (3.0 if args.quick else 8.0)
    drops = args.drops or (10 if args.quick else 20)
    sections = {
        "identification": lambda: identification(seeds, peers=not args.no_peers),
        "link": lambda: link(args.link_results),
        "abort": lambda: abort(drops, realtime),
        "lag": lambda: loop_lag(minutes, args.every, tuple(args.rates), realtime),
    }
    print(f"{machine()}\n\nCommand: `make bench-table` (`benchmarks/table.py`).", flush=True)
    try:
        for name in SECTIONS:  # each printed as it is measured
            if name in args.sections:
                print("\n" + "\n".join(sections[name]()), flush=True)
    except BenchError as exc:
        sys.exit(f"table: {exc}")


if __name__ == "__main__":
    main()
