"""The link's budget for one full-model identification result (eight states, four inputs,
eight outputs: A, B, C, D, five modes with every quality index), end to end through the real
digi-xbee transport and our session over the emulated 900HP radios; and during a run, the
bytes on air each second with the status alone and with the live view beside it, and the
delivery of a result handed over during it.

    .venv/bin/python benchmarks/bench_link.py [--live-only | --no-live]
    .venv/bin/python benchmarks/bench_link.py --results 1 --rates 200 --losses 0 --run-s 4

Prints, at the 900HP's two RF data rates (200 kb/s and the long-range 10 kb/s) and with 0 and
20 % loss per over-the-air attempt: message bytes (MessagePack), frames, bytes on air while
one result is delivered (30 bytes of radio overhead per frame assumed; retries, link acks,
heartbeats and status in that interval included), and the median and worst time from handing
the result to the session to its delivery on the ground, over 5 results.

Both ends are built as the agent and the console build theirs (`build_endpoint`: one key
file, each end's counter and replay state), on two emulated modules sharing one channel.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import statistics
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import msgpack
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from common import BenchError, write_key

from agent.clock import LoopClock
from agent.config import Link, Live
from agent.ident.document import ModeDocument
from agent.link import messages
from agent.link.codec import AIRCRAFT, GROUND
from agent.link.endpoint import build_endpoint
from agent.link.session import LinkSession
from agent.sim.radio import RfChannel, module_pair
from drivers.xbee.driver import XBeeRadio

RUNS = 5  # results delivered per rate and loss
RUN_S = 20.0  # a run's length for the live-view budget
LIVE_SHARE = Live().max_air_share  # the agent's default gate
AIR_ADDR = bytes.fromhex("0013A20040000001")
GROUND_ADDR = bytes.fromhex("0013A20040000002")
# The link's first exchange: digi-xbee opening both emulated modules, then a heartbeat each
# way (about a second here).
LINK_S = 30.0
# One message's delivery: the full result at 10 kb/s with 20 % loss per attempt took 3 s at
# worst here; far beyond that the link is broken, not slow.
DELIVERY_S = 60.0
POLL_S = 0.01


@dataclass
class End:
    """One end of the link: its radio, its session and the messages it received."""

    radio: XBeeRadio
    session: LinkSession
    inbox: list = field(default_factory=list)


@dataclass
class Pair:
    air: End
    ground: End


async def until(predicate: Callable[[], object], timeout_s: float, what: str) -> None:
    """Return once predicate() holds; BenchError naming `what` after `timeout_s`."""
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout_s
    while not predicate():
        if loop.time() > end:
            raise BenchError(f"{what}: not within {timeout_s:g} s")
        await asyncio.sleep(POLL_S)


@contextlib.asynccontextmanager
async def link_pair(directory: Path, channel: RfChannel):
    """The aircraft's and the ground's ends, linked over `channel`; torn down in order."""
    clock = LoopClock()
    write_key(directory / "link.key")
    _, air_module, ground_module = module_pair(
        directory, clock, ("xbee-air", AIR_ADDR), ("xbee-ground", GROUND_ADDR), channel=channel
    )
    modules = [
        asyncio.create_task(m.run(), name=f"xbee-{m.name}") for m in (air_module, ground_module)
    ]
    tasks: list[asyncio.Task] = []
    ends = {}
    try:
        for name, role, module, peer in (
            ("air", AIRCRAFT, air_module, GROUND_ADDR),
            ("ground", GROUND, ground_module, AIR_ADDR),
        ):
            inbox: list = []
            config = Link(
                port=str(module.path),
                peer=peer.hex(),
                key_file="link.key",
                counter_file=f"{name}.counter",
                seen_file=f"{name}.seen",
            )
            radio, session = build_endpoint(
                cfg=config,
                role=role,
                base=directory,
                clock=clock,
                on_message=lambda m, _seq, box=inbox: box.append(m),
            )
            ends[name] = End(radio, session, inbox)
            tasks.append(asyncio.create_task(session.run(), name=f"session-{name}"))
            tasks.append(asyncio.create_task(radio.watch(), name=f"radio-{name}"))
        pair = Pair(ends["air"], ends["ground"])
        await until(
            lambda: pair.air.session.link_up and pair.ground.session.link_up,
            LINK_S,
            "the link between the emulated modules did not come up",
        )
        yield pair
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        for end in ends.values():
            await end.radio.close()
        for task in modules:
            task.cancel()
        await asyncio.gather(*modules, return_exceptions=True)


def full_result(model_id: str = "m1") -> messages.Result:
    """A full-model result: eight states, four inputs, eight outputs, five modes."""
    rng = np.random.default_rng(0)
    mode = ModeDocument(
        name="Dutch roll",
        eigenvalue=(-0.6, 2.2),
        frequency_rad_s=2.28,
        damping=0.26,
        time_constant_s=None,
        msv=0.3,
        mci=0.8,
        moi=0.7,
        emac=0.95,
        mpc=0.3,
        cmi=0.7,
        eigenvalue_std=(0.021, 0.048),
        frequency_std_rad_s=0.05,
        damping_std=0.012,
    )
    m = lambda r, c: rng.normal(size=(r, c)).tolist()  # noqa: E731
    return messages.Result(
        model_id=model_id,
        axes="full",
        dt=0.04,
        inputs=["throttle", "elevator", "aileron", "rudder"],
        outputs=["Vt", "alpha", "q", "theta", "beta", "p", "r", "phi"],
        modes=[mode] * 5,
        tic=[0.1] * 8,
        tic_avg=0.1,
        stable=True,
        suggest_update=True,
        reasons=["TIC 0.10 better than nominal 0.14"],
        A=m(8, 8),
        B=m(8, 4),
        C=m(8, 8),
        D=m(8, 4),
    )


def lateral_live(k: int) -> messages.Live:
    """One second of a lateral run's live view as `agent.runtime.live` builds it: eight
    channels of ten samples in tenths of a degree (or °/s), the plan's progress."""
    t = np.arange(10) * 0.1 + k
    waves = {
        "aileron_cmd": 40 * np.sign(np.sin(1.3 * t)),
        "aileron": 38 * np.sign(np.sin(1.3 * t - 0.1)),
        "rudder_cmd": 40 * np.sign(np.sin(0.9 * t)),
        "rudder": 37 * np.sign(np.sin(0.9 * t - 0.1)),
        "beta": 25 * np.sin(2.1 * t),
        "p": 300 * np.sin(1.3 * t - 0.5),
        "r": 120 * np.sin(2.1 * t - 0.8),
        "phi": 150 * np.sin(0.7 * t),
    }
    return messages.Live(
        time=float(t[0]),
        dt=0.1,
        plan_id="lateral-1",
        plan_fraction=k / 41,
        plan_s=41.0,
        tenths={name: [round(v) for v in values] for name, values in waves.items()},
    )


def status(t: float) -> messages.Status:
    """A status as the agent sends it every second (sensors, recorder counters)."""
    sensor = {"state": "open", "rate_hz": 100.0, "gaps": 0.0, "crc_errors": 0.0, "age_s": 0.01}
    return messages.Status(
        time=t,
        flight_mode="MANUAL",
        airspeed=22.0,
        altitude=305.0,
        alpha=0.05,
        beta=0.0,
        roll=0.02,
        pitch=0.05,
        yaw=1.2,
        excitation="running",
        loop_lag_ms=1.2,
        nominal={"lateral": "lat-3"},
        recorder={"frames": 120000.0, "catch_up_frames": 3.0, "late_samples": 12.0},
        sensors={name: sensor for name in ("vn200", "airdata", "surfaces")},
    )


async def measure_run(
    rate: float, live: bool, run_s: float = RUN_S
) -> tuple[float, float, float, int]:
    """Bytes on air per second over a `run_s` run (status every second, and the live view
    every second if `live`), the delivery time of a full-model result handed over mid-run,
    and the median delivery time of an abort sent from the ground at moments of the run."""
    channel = RfChannel(data_rate_bps=rate, loss=0.0, retries=3, seed=1)
    with tempfile.TemporaryDirectory() as tmp:
        async with link_pair(Path(tmp), channel) as pair:
            await asyncio.sleep(0.5)
            loop = asyncio.get_running_loop()
            session, before, start = pair.air.session, channel.air_bytes, loop.time()
            arrived: list[float] = []

            async def watch() -> None:  # when the result reaches the ground
                await until(
                    lambda: any(m.kind == "result" for m in pair.ground.inbox),
                    DELIVERY_S,
                    "the result handed over mid-run did not reach the ground",
                )
                arrived.append(loop.time())

            async def abort(n: int) -> float:  # from the ground to the aircraft
                sent = loop.time()
                pair.ground.session.send_reliable(messages.Abort(reason=f"bench {n}"))
                await until(lambda: len(pair.air.inbox) > n, DELIVERY_S, f"abort {n}")
                return loop.time() - sent

            watcher, aborts, sent_live = None, [], 0
            for k in range(int(run_s)):
                session.send_status(status(float(k)))
                if live and session.air_share() <= LIVE_SHARE:  # as agent/runtime/live.py
                    session.send_live(lateral_live(k))
                    sent_live += 1
                if k == int(run_s) // 2:
                    handed = loop.time()
                    session.send_reliable(full_result("mid-run"))
                    watcher = asyncio.create_task(watch(), name="bench-result-watch")
                if k % 4 == 1:  # 0.3 s into the second: status and live on air or just sent
                    await asyncio.sleep(0.3)
                    aborts.append(await abort(len(aborts)))
                await asyncio.sleep(max(0.0, start + k + 1 - loop.time()))
            await watcher
            delivered = arrived[0] - handed
            per_second = (channel.air_bytes - before) / (loop.time() - start)
    return per_second, delivered, statistics.median(aborts), sent_live


async def measure(rate: float, loss: float, runs: int = RUNS) -> tuple[int, int, float, float]:
    """Frames of one full result, and over `runs` results the median bytes on air and the
    median and worst delivery time."""
    channel = RfChannel(data_rate_bps=rate, loss=loss, retries=3, seed=1)
    with tempfile.TemporaryDirectory() as tmp:
        async with link_pair(Path(tmp), channel) as pair:
            await asyncio.sleep(0.5)
            loop = asyncio.get_running_loop()
            times, air = [], []
            for k in range(runs):
                before, start = channel.air_bytes, loop.time()
                pair.air.session.send_reliable(full_result(f"m{k}"))
                await until(lambda k=k: len(pair.ground.inbox) > k, DELIVERY_S, f"result {k + 1}")
                times.append(loop.time() - start)
                air.append(channel.air_bytes - before)
                await asyncio.sleep(0.3)
            frames = len(pair.air.session.codec.encode(messages.to_dict(full_result())))
    return frames, statistics.median(air), statistics.median(times), max(times)


def results(rates: list[float], losses: list[float], runs: int) -> None:
    size = len(msgpack.packb(messages.to_dict(full_result()), use_bin_type=True))
    print(f"full-model result: {size} bytes of MessagePack")
    print(
        f"{'RF rate':>10}{'loss':>7}{'frames':>8}{'on air (B)':>12}{'median s':>10}{'worst s':>9}"
    )
    for rate in rates:
        for loss in losses:
            frames, air, median, worst = asyncio.run(measure(rate, loss, runs))
            cells = f"{frames:>8}{air:>12.0f}{median:>10.3f}{worst:>9.3f}"
            print(f"{rate / 1000:>8g}k{loss:>7.0%}{cells}", flush=True)


def during_run(rates: list[float], run_s: float) -> None:
    live_size = len(msgpack.packb(messages.to_dict(lateral_live(5)), use_bin_type=True))
    status_size = len(msgpack.packb(messages.to_dict(status(5.0)), use_bin_type=True))
    print(
        f"\nduring a {run_s:g} s run: status {status_size} B/s of MessagePack, live view "
        f"{live_size} B/s (8 channels × 10 samples)"
    )
    print(
        f"{'RF rate':>10}{'live':>6}{'on air (B/s)':>14}{'result delivered (s)':>22}"
        f"{'abort delivered (s)':>21}{'live views sent':>17}"
    )
    for rate in rates:
        for live in (False, True):
            per_second, delivered, abort, sent = asyncio.run(measure_run(rate, live, run_s))
            print(
                f"{rate / 1000:>8g}k{'on' if live else 'off':>6}{per_second:>14.0f}"
                f"{delivered:>22.2f}{abort:>21.3f}{sent:>17}",
                flush=True,
            )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    what = parser.add_mutually_exclusive_group()
    what.add_argument("--live-only", action="store_true", help="only the run's budget")
    what.add_argument("--no-live", action="store_true", help="only the results' delivery")
    parser.add_argument(
        "--rates", type=float, nargs="+", default=[200.0, 10.0], metavar="KBPS", help="RF rates"
    )
    parser.add_argument(
        "--losses",
        type=float,
        nargs="+",
        default=[0.0, 0.2],
        metavar="P",
        help="loss per over-the-air attempt (0-1)",
    )
    parser.add_argument("--results", type=int, default=RUNS, help="results per rate and loss")
    parser.add_argument(
        "--run-s", type=float, default=RUN_S, help="the run's length for its budget (s, ≥ 2)"
    )
    args = parser.parse_args()
    if args.results < 1 or args.run_s < 2 or not all(0 <= p < 1 for p in args.losses):
        parser.error("--results ≥ 1, --run-s ≥ 2 and each loss in [0, 1)")
    rates = [1000.0 * r for r in args.rates]
    try:
        if not args.live_only:
            results(rates, args.losses, args.results)
        if not args.no_live:
            during_run(rates, args.run_s)
    except BenchError as exc:
        sys.exit(f"bench_link: {exc}")


if __name__ == "__main__":
    main()
