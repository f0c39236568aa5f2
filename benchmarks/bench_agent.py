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
of 100 Hz. --realtime 10 sets the agent's [runtime] realtime_priority. --until-runs N ends the
flight once N excitations are over (the smoke test flies one); the lag percentiles come from
the agent's health records, one a minute, so a flight shorter than that measures CPU, memory
and the identification but not the lag.

It stops with an error and exit code 1 when it cannot measure what it is for: the world or the
agent does not start or stops early, the link does not come up, or no excitation is
identified. Its working directory (the key, the configuration, world.log, agent.log and the
agent's logs in logs/) is then kept, and named; after a measured flight it is removed unless
--keep named it.

Nothing is accelerated: a 45-minute flight takes 45 minutes. Linux only (/proc). With
--world-nice 10 (what `make bench-agent` uses) the world runs below the agent's priority: in the
field it is not on the flight computer, and on a 2-core machine its CPU use would otherwise be
measured as the agent's lag.

    .venv/bin/python benchmarks/bench_agent.py --minutes 45 --world-nice 10  # make bench-agent
    .venv/bin/python benchmarks/bench_agent.py --minutes 3      # a quick look
    .venv/bin/python benchmarks/bench_agent.py --minutes 3 --until-runs 1 --settle 2  # smoke test
    .venv/bin/python benchmarks/bench_agent.py --minutes 10 --rate 400 --realtime 10
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from common import BenchError, tail, write_key

from agent.runtime import lag_percentile
from agent.runtime.health import HEALTH_S

HERE = Path(__file__).resolve().parent
SAMPLE_S = 5.0
TICK_S = 0.5  # how often the parent looks at the processes and the runs between samples
# The world's start: JSBSim's trim, the emulated autopilot, sensors and radios (about 5 s
# here; a busy machine takes several times that).
WORLD_START_S = 120.0
# From the agent's start to the link's first exchange: its imports, the worker's warm-up, the
# radios' opening and the session's handshake (about 10 s here).
LINK_S = 90.0
STOP_S = 30.0  # SIGTERM to exit: the agent aborts any run and flushes its logs
TICKS = os.sysconf("SC_CLK_TCK")
PAGE = os.sysconf("SC_PAGE_SIZE")


# -- the world ---------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class Flight:
    """What to fly and how (the command line's options)."""

    minutes: float = 45.0
    """Real-time length; the flight ends sooner with `until_runs`."""
    every: float = 60.0
    """Seconds from one excitation's start to the next's."""
    until_runs: int | None = None
    """End once this many excitations are over (identified or not)."""
    settle: float = 5.0
    """Seconds of trimmed flight, once the link is up, before the first excitation."""
    world_nice: int = 0
    """The world's nice value (it is not on the flight computer)."""
    realtime: int | None = None
    """The agent's [runtime] realtime_priority."""
    rate: float = 100.0
    """Sensor and recorder rate (Hz)."""


async def world(directory: Path, every: float, rate: float = 100.0, settle: float = 5.0) -> None:
    """Aircraft, radios and ground operator; writes `world.json` once the parts are up,
    `link.json` once the ground hears the agent, `runs.json` after each excitation. SIGTERM
    ends it between runs, or while it waits for the link."""
    from agent.clock import LoopClock
    from agent.sim.aircraft import AircraftOptions, SimAircraft
    from agent.sim.ardupilot import Params
    from agent.sim.flight import AIR, GROUND_ADDR, SimOptions, ground_station, one_run
    from agent.sim.radio import module_pair

    clock = LoopClock()
    ports = directory / "ports"
    ports.mkdir(parents=True, exist_ok=True)
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
        _publish(
            directory / "world.json",
            {"mavlink": list(aircraft.mavlink_address), "ports": str(ports)},
        )
        ground = await ground_station(
            module=ground_module, directory=directory, clock=clock, tasks=tasks
        )
        options = SimOptions(preset="lateral")
        while not ground.session.link_up:
            if await _stopped_within(stop, 0.5):
                return
        _publish(directory / "link.json", {"up_at": clock.now()})
        # As a pilot would: a few seconds of trimmed flight with the agent up (it must see the
        # switch low and the servo outputs for trim) before the first excitation.
        await _stopped_within(stop, settle)
        while not stop.is_set():
            if not ground.session.link_up:
                await _stopped_within(stop, 0.5)
                continue
            began, seen = clock.now(), len(ground.inbox)
            try:
                outcome = await one_run(options, aircraft, ground, len(runs), lambda _: None)
                runs.append(
                    {
                        "t": began,
                        "ok": "result" in outcome,
                        "result_after_s": _result_after(ground, seen),
                        **({"error": outcome["failure"]} if "failure" in outcome else {}),
                    }
                )
            except Exception as exc:  # a missed run is counted and said, the flight goes on
                aircraft.pilot.set_switch(False)
                runs.append({"t": began, "ok": False, "error": f"{type(exc).__name__}: {exc}"})
            _publish(directory / "runs.json", runs)
            await _stopped_within(stop, max(0.0, began + every - clock.now()))
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


def _publish(path: Path, value) -> None:
    """`value` as JSON in `path`, whole: the parent reads these files while the world runs."""
    part = path.with_suffix(".part")
    part.write_text(json.dumps(value))
    part.replace(path)


async def _stopped_within(stop: asyncio.Event, seconds: float) -> bool:
    """Wait `seconds`, or less if `stop` is set; whether it is."""
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(seconds):
            await stop.wait()
    return stop.is_set()


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


async def measure(flight: Flight, keep: Path | None = None) -> dict:
    """The flight measured (see `summarise`). Raises BenchError when it could not be; its
    directory is then kept (`keep`, or a new temporary one) and named on stderr."""
    directory = keep or Path(tempfile.mkdtemp(prefix="bench-agent-"))
    directory.mkdir(parents=True, exist_ok=True)
    measured = False
    try:
        result = await _fly(directory, flight)
        measured = True
    finally:
        if not measured:
            print(f"bench_agent: the logs are kept in {directory}", file=sys.stderr)
        elif keep is None:
            shutil.rmtree(directory, ignore_errors=True)
    return {
        "rate_hz": flight.rate,
        "realtime": flight.realtime,
        "world_nice": flight.world_nice,
        "flight": asdict(flight),
        **result,
    }


async def _fly(directory: Path, flight: Flight) -> dict:
    write_key(directory / "link.key")
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    with contextlib.ExitStack() as stack:
        log = stack.enter_context(open(directory / "world.log", "w"))
        world_proc = subprocess.Popen(
            [
                *(sys.executable, __file__, "--world", str(directory)),
                *("--every", str(flight.every), "--rate", str(flight.rate)),
                *("--settle", str(flight.settle)),
            ],
            env=env,
            preexec_fn=(lambda: os.nice(flight.world_nice)) if flight.world_nice else None,
            stdout=log,
            stderr=subprocess.STDOUT,
        )
        agent_proc = None
        try:
            info = await _world_up(directory, world_proc)
            config = agent_config(directory, info["mavlink"], flight.realtime, flight.rate)
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
            await _link_up(directory, agent_proc, world_proc)
            result = await sample(
                directory, agent_proc, world_proc, flight.minutes, flight.until_runs
            )
        finally:
            for proc in (agent_proc, world_proc):
                if proc is not None and proc.poll() is None:
                    proc.send_signal(signal.SIGTERM)
                    try:
                        proc.wait(STOP_S)
                    except subprocess.TimeoutExpired:
                        proc.kill()
                        proc.wait()
    _check(result, flight.minutes, flight.until_runs)
    return result


def _stopped(directory: Path, agent_proc, world_proc) -> None:
    """BenchError, with the end of its log, if the agent or the world has stopped."""
    for name, proc in (("agent", agent_proc), ("world", world_proc)):
        if proc is not None and proc.poll() is not None:
            raise BenchError(
                f"the {name} process stopped early (exit code {proc.returncode}); the end of "
                f"{directory / f'{name}.log'}:\n{tail(directory / f'{name}.log')}"
            )


async def _world_up(directory: Path, world_proc) -> dict:
    """The world's `world.json` (its MAVLink address), once it is up."""
    deadline = time.monotonic() + WORLD_START_S
    while not (directory / "world.json").exists():
        _stopped(directory, None, world_proc)
        if time.monotonic() > deadline:
            raise BenchError(f"the world did not start in {WORLD_START_S:g} s")
        await asyncio.sleep(0.1)
    return json.loads((directory / "world.json").read_text())


async def _link_up(directory: Path, agent_proc, world_proc) -> None:
    """Return once the world's ground end has heard the agent over the link."""
    deadline = time.monotonic() + LINK_S
    while not (directory / "link.json").exists():
        _stopped(directory, agent_proc, world_proc)
        if time.monotonic() > deadline:
            said = [
                line
                for path in [directory / "agent.log", *(directory / "logs").glob("*_exec_*")]
                for line in _lines(path)
                if "link refused" in line
            ]
            why = f"; the agent said: {said[-1].strip()}" if said else ""
            raise BenchError(
                f"the link did not come up in {LINK_S:g} s of the agent's start{why}; the end "
                f"of {directory / 'agent.log'}:\n{tail(directory / 'agent.log')}"
            )
        await asyncio.sleep(TICK_S)


def _lines(path: Path) -> list[str]:
    try:
        return path.read_text(errors="replace").splitlines()
    except OSError:
        return []


def _runs(directory: Path) -> list[dict]:
    """The world's record of each excitation so far (written whole after each)."""
    path = directory / "runs.json"
    return json.loads(path.read_text()) if path.exists() else []


def _check(result: dict, minutes: float, until_runs: int | None) -> None:
    """BenchError when the flight did not measure what it is for."""
    if result["runs_identified"] == 0:
        errors = sorted({r["error"] for r in result["run_errors"]})
        raise BenchError(
            f"no excitation was identified and delivered ({result['runs']} flown"
            + (f"; {'; '.join(errors)}" if errors else "")
            + ")"
        )
    if until_runs is None and minutes * 60 >= 2 * HEALTH_S and not result["lag"]["minutes"]:
        raise BenchError("the agent wrote no health record: the loop lag was not measured")


async def sample(
    directory: Path, agent_proc, world_proc, minutes: float, until_runs: int | None = None
) -> dict:
    baseline: list[float] = []
    probe_task = asyncio.create_task(probe(baseline))
    samples = []
    start = time.monotonic()
    end, due = start + 60.0 * minutes, start + SAMPLE_S
    try:
        while time.monotonic() < end:
            await asyncio.sleep(TICK_S)
            _stopped(directory, agent_proc, world_proc)
            over = until_runs is not None and len(_runs(directory)) >= until_runs
            if time.monotonic() < due and not over:
                continue
            due += SAMPLE_S
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
            if over:
                break
    finally:
        probe_task.cancel()
        print(file=sys.stderr)
    if len(samples) < 2:
        raise BenchError(f"the flight was too short to measure: {len(samples)} sample(s)")
    agent_proc.send_signal(signal.SIGTERM)
    stopped = agent_proc.wait(STOP_S)
    health = []
    for path in sorted((directory / "logs").glob("*_exec_*")):
        for line in path.read_text().splitlines():
            event = json.loads(line)
            if event["message"].startswith("health "):
                health.append(json.loads(event["message"][len("health ") :]))
    return summarise(samples, health, baseline, _runs(directory), stopped)


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
        "run_errors": [
            {"t": r["t"], "error": r.get("error", "no result")} for r in runs if not r["ok"]
        ],
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


def _lag_lines(r: dict) -> list[str]:
    if not r["lag"]["minutes"]:
        return [
            f"  agent: not measured (no health record; the agent writes one every {HEALTH_S:g} s)"
        ]
    return [
        _lag_line("agent, all drivers", r["lag"]),
        _lag_line("agent, identifying", r["lag_identifying"]),
    ]


def report(r: dict) -> str:
    lag, base = r["lag"], r["baseline_lag"]
    rss, slope = r["agent_rss_mb"], r["agent_rss_slope_mb_per_h_second_half"]
    lines = [
        f"simulated flight: {r['minutes']:.1f} min real time, sensors and recorder at "
        f"{r.get('rate_hz', 100):g} Hz, {r['runs']} lateral excitations, "
        f"{r['runs_identified']} identified and delivered over the radio",
        *(f"  not identified at {e['t']:.0f} s: {e['error']}" for e in r["run_errors"]),
        _after_line(r["result_after_s"]),
        "event-loop lag (10 ms probe, from the agent's health records; percentiles of all "
        "samples are bin upper edges, 0.05 ms bins):",
        *_lag_lines(r),
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
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--world", type=Path, metavar="DIR", help=argparse.SUPPRESS)  # a child
    parser.add_argument("--minutes", type=float, default=45.0, help="real-time minutes to fly")
    parser.add_argument("--every", type=float, default=60.0, help="s between excitations")
    parser.add_argument(
        "--until-runs",
        type=int,
        metavar="N",
        help="end the flight once N excitations are over (or at --minutes, if sooner)",
    )
    parser.add_argument(
        "--settle",
        type=float,
        default=5.0,
        metavar="S",
        help="s of trimmed flight before the first excitation, once the link is up",
    )
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
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = parser.parse_args()
    if args.world is not None:
        asyncio.run(world(args.world, args.every, args.rate, args.settle))
        return
    flight = Flight(
        minutes=args.minutes,
        every=args.every,
        until_runs=args.until_runs,
        settle=args.settle,
        world_nice=args.world_nice,
        realtime=args.realtime,
        rate=args.rate,
    )
    try:
        result = asyncio.run(measure(flight, args.keep))
    except BenchError as exc:
        sys.exit(f"bench_agent: {exc}")
    print(json.dumps(result, default=float) if args.json else report(result))


if __name__ == "__main__":
    main()
