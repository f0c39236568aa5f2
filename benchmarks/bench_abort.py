"""Abort latency: the pilot drops the excitation switch mid-run; how long until the agent's trim
override is on the MAVLink wire.

    .venv/bin/python benchmarks/bench_abort.py --drops 30 [--realtime 10] [--json]
    .venv/bin/python benchmarks/bench_abort.py --drops 1 --json   # the smoke test

The whole simulated flight (JSBSim J-3 Cub, the emulated ArduPlane on UDP, sensor ptys, radios,
the scripted ground) runs here; the agent is the real `sysid agent` in its own process. The
emulated ArduPlane stamps, with the one clock of this process, every RC_CHANNELS it sends (the
switch position, 20 Hz) and every RC_CHANNELS_OVERRIDE it receives. ArduPilot's own kill
(RCx_OPTION 46: overrides ignored while the switch is low) is off, so what reaches the aircraft
is the agent's doing alone.

For each drop (a lateral preset armed, the switch flipped high, dropped at a random moment
0.5–3 s into the run; then the safety pilot levels the wings) two intervals:
- report → trim: from the first RC_CHANNELS carrying the low switch to the first override
  holding the trim (the agent's reaction: MAVSDK, the loop, one command period of 20 ms);
- flip → trim: from the pilot's flip (what the pilot feels; adds the telemetry period).

It stops with exit code 1 when no drop could be measured (every run ended before its drop);
the flight's directory (the agent's logs) is then kept and named.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import random
import re
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("JSBSIM_DEBUG", "0")  # no JSBSim banner on stdout

from common import BenchError

from agent.excitation.plan import preset
from agent.link import messages
from agent.sim.ardupilot import Params
from agent.sim.flight import SimOptions, simulated, until

CHANNEL = {"aileron": 1, "elevator": 2, "throttle": 3, "rudder": 4}


async def _until(predicate, timeout: float, what: str):
    found = await until(predicate, timeout, poll_s=0.01)
    if found is None:
        raise TimeoutError(f"no {what} in {timeout:g} s")
    return found


async def level_wings(aircraft, timeout: float = 20.0) -> None:
    """The safety pilot levels the wings with the aileron stick (a cut doublet leaves the
    aircraft banked, and twenty of them in a row would leave it outside the envelope), then
    puts the stick back at trim: |bank| < 2° and |roll rate| < 1°/s for a second."""
    loop = asyncio.get_running_loop()
    pilot, trim = aircraft.pilot, aircraft.pilot.stick(1)
    end, level_since = loop.time() + timeout, None
    try:
        while loop.time() < end:
            phi, p = aircraft.truth["phi"], aircraft.truth["p"]
            push = max(-150.0, min(150.0, -(500.0 * phi + 200.0 * p)))  # µs; + aileron rolls right
            pilot.set_stick(1, round(trim + push))
            if abs(phi) < math.radians(2) and abs(p) < math.radians(1):
                level_since = level_since or loop.time()
                if loop.time() - level_since >= 1.0:
                    return
            else:
                level_since = None
            await asyncio.sleep(0.02)
        raise RuntimeError(f"the wings are not level after {timeout:g} s")
    finally:
        pilot.set_stick(1, trim)


def _events(ground, since: int, event: str) -> list:
    return [
        m
        for m in ground.inbox[since:]
        if isinstance(m, messages.ExcitationEvent) and m.event == event
    ]


async def measure(drops: int, seed: int = 0, realtime: int | None = None) -> list[dict]:
    """One dict per drop: report_to_trim_s, flip_to_trim_s, commands_before_trim (or
    other_end: a run that ended before its drop). The flight's directory is removed after a
    measurement and kept, and named on stderr, after an error."""
    directory = Path(tempfile.mkdtemp(prefix="bench-abort-"))
    try:
        out = await _drops(directory, drops, seed, realtime)
    except BaseException:
        print(f"bench_abort: the logs are kept in {directory}", file=sys.stderr)
        raise
    if not any("other_end" not in d for d in out):
        print(f"bench_abort: the logs are kept in {directory}", file=sys.stderr)
        raise BenchError(f"no drop was measured: every run ended before it ({out})")
    shutil.rmtree(directory, ignore_errors=True)
    return out


async def _drops(directory: Path, drops: int, seed: int, realtime: int | None) -> list[dict]:
    rng = random.Random(seed)
    params = Params(switch_channel=7, switch_option_46=False)
    options = SimOptions(preset="lateral", realtime_priority=realtime, directory=directory)
    out = []
    async with simulated(options, params, agent_process=True) as sim:
        ap, ground, pilot, clock = sim.aircraft.autopilot, sim.ground, sim.aircraft.pilot, sim.clock
        for k in range(drops):
            ack = await ground.command(messages.Arm(plan=preset("lateral", plan_id=f"drop-{k}")))
            if not ack.ok:
                raise RuntimeError(f"the agent refused the plan: {ack.reason}")
            seen = len(ground.inbox)
            pilot.set_switch(True)
            begun = await _until(
                lambda s=seen: _events(ground, s, "started") or _events(ground, s, "refused"),
                10,
                "start",
            )
            if begun[0].event == "refused":
                raise RuntimeError(f"drop {k}: the agent refused the start: {begun[0].detail}")
            started = begun[0]
            await asyncio.sleep(rng.uniform(0.5, 3.0))
            dropped = clock.now()
            pilot.set_switch(False)
            aborted = (await _until(lambda s=seen: _events(ground, s, "aborted"), 5, "abort"))[0]
            await asyncio.sleep(0.5)
            if "switch" not in aborted.detail:  # the run ended otherwise before the drop
                out.append({"other_end": aborted.detail})
                await level_wings(sim.aircraft)
                await asyncio.sleep(1.5)
                continue
            trim = {
                CHANNEL[name]: int(us) for name, us in re.findall(r"(\w+) (\d+) µs", started.detail)
            }
            wire = list(ap.wire)
            reports = [
                t for t, kind, *rest in wire if kind == "switch" and t >= dropped and rest[0] < 1500
            ]
            if not reports:
                raise RuntimeError(f"drop {k}: no RC_CHANNELS with the switch low on the wire")
            after = [
                (t, values)
                for t, kind, values, _ in (e for e in wire if e[1] == "override")
                if t >= reports[0]
            ]
            trims = [i for i, (_, values) in enumerate(after) if values == trim]
            if not trims:
                raise RuntimeError(f"drop {k}: no trim override {trim} after the switch report")
            reported, first = reports[0], trims[0]
            t_trim = after[first][0]
            out.append(
                {
                    "report_to_trim_s": t_trim - reported,
                    "flip_to_trim_s": t_trim - dropped,
                    "commands_before_trim": first,
                }
            )
            await level_wings(sim.aircraft)
            await asyncio.sleep(1.5)  # trimmed flight (the agent captures trim) before the next
    return out


def summary(runs: list[dict]) -> dict:
    drops = [d for d in runs if "other_end" not in d]
    other = [d["other_end"] for d in runs if "other_end" in d]

    def stats(key: str) -> dict:
        ms = sorted(1e3 * d[key] for d in drops)
        return {
            "median_ms": statistics.median(ms),
            "p95_ms": ms[min(len(ms) - 1, round(0.95 * (len(ms) - 1)))],
            "max_ms": ms[-1],
        }

    return {
        "drops": len(drops),
        "other_ends": other,
        "report_to_trim": stats("report_to_trim_s"),
        "flip_to_trim": stats("flip_to_trim_s"),
        "most_commands_before_trim": max(d["commands_before_trim"] for d in drops),
    }


def report(s: dict) -> str:
    a, b = s["report_to_trim"], s["flip_to_trim"]
    return (
        f"abort latency over {s['drops']} switch drops mid-run:\n"
        f"  switch report on the wire → trim on the wire: median {a['median_ms']:.1f} ms, "
        f"p95 {a['p95_ms']:.1f} ms, max {a['max_ms']:.1f} ms\n"
        f"  pilot's flip → trim on the wire:               median {b['median_ms']:.1f} ms, "
        f"p95 {b['p95_ms']:.1f} ms, max {b['max_ms']:.1f} ms\n"
        f"  excitation commands after the report, before the trim: at most "
        f"{s['most_commands_before_trim']}"
        + "".join(f"\n  a run that ended before its drop: {d}" for d in s["other_ends"])
    )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--drops", type=int, default=30, help="runs, each with one drop")
    parser.add_argument("--seed", type=int, default=0, help="of the drops' moments")
    parser.add_argument(
        "--realtime", type=int, metavar="PRIORITY", help="the agent's [runtime] realtime_priority"
    )
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = parser.parse_args()
    if args.drops < 1:
        parser.error("--drops: at least 1")
    try:
        s = summary(asyncio.run(measure(args.drops, args.seed, args.realtime)))
    except BenchError as exc:
        sys.exit(f"bench_abort: {exc}")
    print(json.dumps(s) if args.json else report(s))


if __name__ == "__main__":
    main()
