"""The agent over a simulated flight: event-loop lag (all drivers running, and while the worker
identifies), CPU and memory, in real time.

Three processes, as in the field:
- the world (this file run as `world`): the JSBSim J-3 Cub, the emulated ArduPlane on UDP, the
  sensor ptys, both emulated XBee modules, and the scripted ground operator, who arms the
  lateral preset every --every seconds, has the pilot flip the switch and decides on the result;
- the agent: `python -m agent agent --config …`, the real entry point, with its worker;
- this parent: samples /proc for the agent (its event-loop thread apart), its worker and the
  world every 5 s, runs the same 10 ms lag probe on its own idle event loop as the machine's
  baseline, stops the agent with SIGTERM at the end and reads the agent's health records (one
  a minute) from its execution log.

--rate 400 runs the three sensors and the recorder at 400 Hz (the VN-200's IMU rate) instead
of 100 Hz. --realtime 10 sets the agent's [runtime] realtime_priority.

Nothing is accelerated: a 45-minute flight takes 45 minutes. Linux only (/proc). With
--world-nice 10 (what `make bench-agent` uses) the world runs below the agent's priority: in the
field it is not on the flight computer, and on a 2-core machine its CPU use would otherwise be
measured as the agent's lag.

    .venv/bin/python benchmarks/bench_agent.py --minutes 45 --world-nice 10  # make bench-agent
    .venv/bin/python benchmarks/bench_agent.py --minutes 3      # a quick look
    .venv/bin/python benchmarks/bench_agent.py --minutes 10 --rate 400 --realtime 10
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import secrets
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from agent.runtime import lag_percentile

HERE = Path(__file__).resolve().parent
SAMPLE_S = 5.0
TICKS = os.sysconf("SC_CLK_TCK")
PAGE = os.sysconf("SC_PAGE_SIZE")


# -- the world ---------------------------------------------------------------------------------


async def world(directory: Path, every: float, rate: float = 100.0) -> None:
    """Aircraft, radios and ground operator; writes `world.json` once the parts are up."""
    from agent.clock import LoopClock
    from agent.sim.aircraft import AircraftOptions, SimAircraft
    from agent.sim.ardupilot import Params
    from agent.sim.flight import AIR, GROUND_ADDR, SimOptions, ground_station, one_run
    from agent.sim.radio import module_pair

    clock = LoopClock()
    ports = directory / "ports"
    ports.mkdir(parents=True, exist_ok=True)
    key = bytes.fromhex((directory / "link.key").read_text())
    options = AircraftOptions(params=Params(switch_channel=7), sensor_rate_hz=rate)
    aircraft = SimAircraft(options, clock, ports)
    _, air, ground_module = module_pair(
        ports, clock, ("xbee-air", AIR), ("xbee-ground", GROUND_ADDR)
    )
    tasks = [
        asyncio.create_task(aircraft.run(), name="sim-aircraft"),
        asyncio.create_task(air.run(), name="xbee-air"),
        asyncio.create_task(ground_module.run(), name="xbee-ground"),
    ]
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGTERM, stop.set)
    runs: list[dict] = []
    try:
        while aircraft.mavlink_address is None or not air.port.plugged:
            await asyncio.sleep(0.05)
        (directory / "world.json").write_text(
            json.dumps({"mavlink": list(aircraft.mavlink_address), "ports": str(ports)})
        )
        ground = await ground_station(ground_module, key, clock, tasks)
        options = SimOptions(preset="lateral")
        while not ground.session.link_up:
            await asyncio.sleep(0.5)
        # As a pilot would: a few seconds of trimmed flight with the agent up (it must see the
        # switch low and the servo outputs for trim) before the first excitation.
        await asyncio.sleep(5.0)
        while not stop.is_set():
            if not ground.session.link_up:
                await asyncio.sleep(0.5)
                continue
            began, seen = clock.now(), len(ground.inbox)
            try:
                outcome = await one_run(options, aircraft, ground, len(runs), lambda _: None)
                runs.append(
                    {
                        "t": began,
                        "ok": "result" in outcome,
                        "result_after_s": _result_after(ground, seen),
                    }
                )
            except Exception as exc:  # a missed run is counted, the flight goes on
                aircraft.pilot.set_switch(False)
                runs.append({"t": began, "ok": False, "error": str(exc)})
            (directory / "runs.json").write_text(json.dumps(runs))
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(max(0.0, began + every - clock.now())):
                    await stop.wait()
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


def _result_after(ground, seen: int) -> float | None:
    """From the excitation's end (the agent's "finished" event, its own clock) to the result's
    arrival at the ground (both on this machine's monotonic clock): the recorder's delay, the
    identification in the worker, and the radio link."""
    from agent.link import messages

    new = list(zip(ground.inbox[seen:], ground.received_at[seen:], strict=True))
    ends = [
        m.time for m, _ in new if isinstance(m, messages.ExcitationEvent) and m.event == "finished"
    ]
    results = [t for m, t in new if isinstance(m, messages.Result)]
    return results[0] - ends[0] if ends and results else None


# -- the parent --------------------------------------------------------------------------------


def agent_config(
    directory: Path, mavlink: list, realtime: int | None = None, rate: float = 100.0
) -> str:
    ports = directory / "ports"
    runtime = f"[runtime]\nrealtime_priority = {realtime}\n" if realtime else ""
    return (
        runtime
        + f"""
[sensors.vn200]
port = "{ports / "vn200"}"
rate_hz = {rate}
[sensors.airdata]
port = "{ports / "airdata"}"
rate_hz = {rate}
[sensors.surfaces]
port = "{ports / "surfaces"}"
rate_hz = {rate}
[autopilot]
url = "udpout://{mavlink[0]}:{mavlink[1]}"
[link]
port = "{ports / "xbee-air"}"
peer = "0013A20041000002"
key_file = "link.key"
counter_file = "air.counter"
seen_file = "air.seen"
[recorder]
log_dir = "logs"
rate_hz = {rate}
"""
    )


def _cpu_s(stat: str) -> float:
    fields = stat[stat.rindex(")") + 2 :].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def proc_sample(pid: int) -> dict | None:
    """CPU seconds (the process, and its main thread: the event loop), RSS (MB), threads and
    what it is (the worker or multiprocessing's resource tracker), from /proc."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        statm = Path(f"/proc/{pid}/statm").read_text().split()
        main = Path(f"/proc/{pid}/task/{pid}/stat").read_text()
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return None
    fields = stat[stat.rindex(")") + 2 :].split()
    return {
        "cpu_s": _cpu_s(stat),
        "main_thread_cpu_s": _cpu_s(main),
        "rss_mb": int(statm[1]) * PAGE / 2**20,
        "threads": int(fields[17]),
        "tracker": b"resource_tracker" in cmdline,
    }


def children(pid: int) -> list[int]:
    kids = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        with contextlib.suppress(OSError):
            kids += [int(k) for k in (task / "children").read_text().split()]
    return kids


async def probe(lags: list[float]) -> None:
    """The same 10 ms lag probe as the agent's, on this idle loop: the machine's baseline."""
    loop = asyncio.get_running_loop()
    while True:
        start = loop.time()
        await asyncio.sleep(0.01)
        lags.append(loop.time() - start - 0.01)


async def measure(
    minutes: float,
    every: float,
    keep: Path | None,
    world_nice: int,
    realtime: int | None = None,
    rate: float = 100.0,
) -> dict:
    with contextlib.ExitStack() as stack:
        directory = keep or Path(stack.enter_context(tempfile.TemporaryDirectory()))
        directory.mkdir(parents=True, exist_ok=True)
        (directory / "link.key").write_text(secrets.token_bytes(32).hex())
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
        log = stack.enter_context(open(directory / "world.log", "w"))
        world_proc = subprocess.Popen(
            [
                sys.executable,
                __file__,
                "world",
                str(directory),
                "--every",
                str(every),
                "--rate",
                str(rate),
            ],
            env=env,
            preexec_fn=(lambda: os.nice(world_nice)) if world_nice else None,
            stdout=log,
            stderr=subprocess.STDOUT,
        )
        agent_proc = None
        try:
            for _ in range(600):
                if (directory / "world.json").exists() or world_proc.poll() is not None:
                    break
                await asyncio.sleep(0.1)
            info = json.loads((directory / "world.json").read_text())
            config = agent_config(directory, info["mavlink"], realtime, rate)
            (directory / "agent.toml").write_text(config)
            agent_log = stack.enter_context(open(directory / "agent.log", "w"))
            agent_proc = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "agent",
                    "agent",
                    "--config",
                    str(directory / "agent.toml"),
                    "--base",
                    str(directory),
                ],
                env=env,
                stdout=agent_log,
                stderr=subprocess.STDOUT,
            )
            result = await sample(directory, agent_proc, world_proc, minutes)
            return {"rate_hz": rate, "realtime": realtime, "world_nice": world_nice, **result}
        finally:
            for proc in (agent_proc, world_proc):
                if proc is not None and proc.poll() is None:
                    proc.send_signal(signal.SIGTERM)
                    try:
                        proc.wait(30)
                    except subprocess.TimeoutExpired:
                        proc.kill()


async def sample(directory: Path, agent_proc, world_proc, minutes: float) -> dict:
    baseline: list[float] = []
    probe_task = asyncio.create_task(probe(baseline))
    samples = []
    start = time.monotonic()
    end = start + 60.0 * minutes
    try:
        while time.monotonic() < end:
            await asyncio.sleep(SAMPLE_S)
            if agent_proc.poll() is not None or world_proc.poll() is not None:
                raise RuntimeError(f"a process stopped early; see the logs in {directory}")
            agent, world_now = proc_sample(agent_proc.pid), proc_sample(world_proc.pid)
            workers = [s for k in children(agent_proc.pid) if (s := proc_sample(k))]
            samples.append(
                {
                    "t": time.monotonic() - start,
                    "agent": agent,
                    "workers": workers,
                    "world": world_now,
                }
            )
            done = int((time.monotonic() - start) / 60)
            print(f"\r{done}/{minutes:g} min", end="", file=sys.stderr, flush=True)
    finally:
        probe_task.cancel()
        print(file=sys.stderr)
    agent_proc.send_signal(signal.SIGTERM)
    stopped = agent_proc.wait(30)
    health = []
    for path in (directory / "logs").glob("*_exec_*"):
        for line in path.read_text().splitlines():
            event = json.loads(line)
            if event["message"].startswith("health "):
                health.append(json.loads(event["message"][len("health ") :]))
    runs_path = directory / "runs.json"
    runs = json.loads(runs_path.read_text()) if runs_path.exists() else []
    return summarise(samples, health, baseline, runs, stopped)


def summarise(samples, health, baseline, runs, exit_code) -> dict:
    t = np.array([s["t"] for s in samples])
    rss = np.array([s["agent"]["rss_mb"] for s in samples])
    cpu = np.array([s["agent"]["cpu_s"] for s in samples])
    loop_cpu = np.array([s["agent"]["main_thread_cpu_s"] for s in samples])
    worker_cpu = np.array([sum(w["cpu_s"] for w in s["workers"]) for s in samples])
    worker_rss = np.array(
        [sum(w["rss_mb"] for w in s["workers"] if not w["tracker"]) for s in samples]
    )
    world_cpu = np.array([s["world"]["cpu_s"] for s in samples])
    half = t >= t[-1] / 2
    slope = float(np.polyfit(t[half] / 3600, rss[half], 1)[0]) if half.sum() > 2 else None
    wall = t[-1] - t[0]

    def lag(key: str) -> dict:
        rows = [h[key] for h in health if h[key]["n"]]
        if not rows:
            return {"minutes": 0}
        p99 = [r["p99_ms"] for r in rows]
        out = {
            "minutes": len(rows),
            "samples": sum(r["n"] for r in rows),
            "p50_ms_median": float(np.median([r["p50_ms"] for r in rows])),
            "p99_ms_median": float(np.median(p99)),
            "p99_ms_worst": float(max(p99)),
            "max_ms": float(max(r["max_ms"] for r in rows)),
        }
        if all("hist" in r for r in rows):  # every sample of the flight together
            hists = [r["hist"] for r in rows]
            for q, name in ((50, "p50"), (99, "p99"), (99.9, "p999")):
                out[f"{name}_ms_pooled"] = lag_percentile(hists, q)
        return out

    base = np.array(baseline) * 1000
    after = [r["result_after_s"] for r in runs if r.get("result_after_s") is not None]
    return {
        "minutes": wall / 60,
        "runs": len(runs),
        "runs_identified": sum(r["ok"] for r in runs),
        "result_after_s": {"median": float(np.median(after)), "max": float(max(after))}
        if after
        else None,
        "lag": lag("lag"),
        "lag_identifying": lag("lag_identifying"),
        "baseline_lag": {
            "p50_ms": float(np.percentile(base, 50)),
            "p99_ms": float(np.percentile(base, 99)),
            "max_ms": float(base.max()),
        },
        "agent_cpu_percent": 100 * (cpu[-1] - cpu[0]) / wall,
        "agent_loop_thread_cpu_percent": 100 * (loop_cpu[-1] - loop_cpu[0]) / wall,
        "worker_cpu_percent": 100 * (worker_cpu[-1] - worker_cpu[0]) / wall,
        "world_cpu_percent": 100 * (world_cpu[-1] - world_cpu[0]) / wall,
        "agent_rss_mb": {"first": rss[0], "last": rss[-1], "max": rss.max()},
        "agent_rss_slope_mb_per_h_second_half": slope,
        "worker_rss_mb_last": worker_rss[-1],
        "agent_threads": {
            "first": samples[0]["agent"]["threads"],
            "last": samples[-1]["agent"]["threads"],
        },
        "health_first": health[0] if health else None,
        "health_last": health[-1] if health else None,
        "agent_exit_code": exit_code,
    }


def _lag_line(label: str, lag: dict) -> str:
    nan = float("nan")
    return (
        f"  {label:<20}: {lag.get('samples', 0)} samples; all together p50 "
        f"{lag.get('p50_ms_pooled', nan):.2f}, p99 {lag.get('p99_ms_pooled', nan):.2f}, p99.9 "
        f"{lag.get('p999_ms_pooled', nan):.2f} ms; per minute p99 median "
        f"{lag.get('p99_ms_median', nan):.2f} ms, worst {lag.get('p99_ms_worst', nan):.2f} ms; "
        f"max {lag.get('max_ms', nan):.1f} ms"
    )


def _after_line(after: dict | None) -> str:
    if after is None:
        return "no result reached the ground"
    return (
        f"result at the ground after the excitation's end: median {after['median']:.2f} s, "
        f"max {after['max']:.2f} s (recorder delay, worker, radio)"
    )


def report(r: dict) -> str:
    lag, base = r["lag"], r["baseline_lag"]
    rss, slope = r["agent_rss_mb"], r["agent_rss_slope_mb_per_h_second_half"]
    lines = [
        f"simulated flight: {r['minutes']:.1f} min real time, sensors and recorder at "
        f"{r.get('rate_hz', 100):g} Hz, {r['runs']} lateral excitations, "
        f"{r['runs_identified']} identified and delivered over the radio",
        _after_line(r["result_after_s"]),
        "event-loop lag (10 ms probe, from the agent's health records; percentiles of all "
        "samples are bin upper edges, 0.05 ms bins):",
        _lag_line("agent, all drivers", lag),
        _lag_line("agent, identifying", r["lag_identifying"]),
        f"  {'idle loop, same box':<20}: p50 {base['p50_ms']:.2f} ms, p99 {base['p99_ms']:.2f} "
        f"ms, max {base['max_ms']:.1f} ms",
        f"  ratio agent/idle p99: {lag.get('p99_ms_median', float('nan')) / base['p99_ms']:.2f}",
        f"CPU (of one core): agent {r['agent_cpu_percent']:.1f} % (event-loop thread "
        f"{r['agent_loop_thread_cpu_percent']:.1f} %, MAVSDK, radio and serial threads the "
        f"rest), worker {r['worker_cpu_percent']:.1f} %, world {r['world_cpu_percent']:.1f} %",
        f"agent RSS: {rss['first']:.0f} MB first, {rss['last']:.0f} MB last, {rss['max']:.0f} MB"
        f" max; second-half slope {slope if slope is not None else float('nan'):+.1f} MB/h; "
        f"worker {r['worker_rss_mb_last']:.0f} MB",
        f"agent threads: {r['agent_threads']['first']} → {r['agent_threads']['last']}; "
        f"agent exit code after SIGTERM: {r['agent_exit_code']}",
    ]
    first, last = r["health_first"], r["health_last"]
    if first and last:  # from the agent's own health records, first and last minute
        lines.append(
            f"tasks {first['tasks']} → {last['tasks']}; open files {first['open_files']} → "
            f"{last['open_files']}; log lines dropped {last['logs']['dropped']}, lost "
            f"{last['logs'].get('lost_lines', 0)}"
        )
        counters = {k: v for k, v in sorted(last["counters"].items()) if v}
        lines.append(f"agent counters: {json.dumps(counters)}")
        lines.append(f"recorder counters: {json.dumps(last['recorder'])}")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="mode")
    w = sub.add_parser("world")
    w.add_argument("directory", type=Path)
    w.add_argument("--every", type=float, default=60.0)
    w.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--minutes", type=float, default=45.0)
    parser.add_argument("--every", type=float, default=60.0, help="s between excitations")
    parser.add_argument("--keep", type=Path, help="keep the logs in this directory")
    parser.add_argument(
        "--world-nice",
        type=int,
        default=0,
        help="run the world (aircraft, sensors, radios, ground) at this nice value",
    )
    parser.add_argument(
        "--realtime",
        type=int,
        metavar="PRIORITY",
        help="the agent's [runtime] realtime_priority (SCHED_FIFO for its loop thread)",
    )
    parser.add_argument(
        "--rate",
        type=float,
        default=100.0,
        metavar="HZ",
        help="sensor and recorder rate (100, or 400 as the VN-200's IMU rate)",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.mode == "world":
        asyncio.run(world(args.directory, args.every, args.rate))
        return
    result = asyncio.run(
        measure(args.minutes, args.every, args.keep, args.world_nice, args.realtime, args.rate)
    )
    print(json.dumps(result, default=float) if args.json else report(result))


if __name__ == "__main__":
    main()
