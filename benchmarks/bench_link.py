"""The link's budget for one full-model identification result (eight states, four inputs,
eight outputs: A, B, C, D, five modes with every quality index), end to end through the real
digi-xbee transport and our session over the emulated 900HP radios; and during a run, the
bytes on air each second with the status alone and with the live view beside it, and the
delivery of a result handed over during it.

    .venv/bin/python benchmarks/bench_link.py [--live-only]

Prints, at the 900HP's two RF data rates (200 kb/s and the long-range 10 kb/s) and with 0 and
20 % loss per over-the-air attempt: message bytes (MessagePack), frames, bytes on air while
one result is delivered (30 bytes of radio overhead per frame assumed; retries, link acks,
heartbeats and status in that interval included), and the median and worst time from handing
the result to the session to its delivery on the ground, over 5 results.
"""

from __future__ import annotations

import asyncio
import statistics
import sys
import tempfile
from pathlib import Path

import msgpack
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agent.config import Live
from agent.link import messages
from agent.sim.radio import RfChannel
from tests.link.pair import link_pair, wait_for
from tests.link.test_link_radio import full_result

RUNS = 5
RUN_S = 20.0  # a run's length for the live-view budget
LIVE_SHARE = Live().max_air_share  # the agent's default gate


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


async def measure_run(rate: float, live: bool) -> tuple[float, float, float, int]:
    """Bytes on air per second over a RUN_S run (status every second, and the live view every
    second if `live`), the delivery time of a full-model result handed over mid-run, and the
    median delivery time of an abort sent from the ground at five moments of the run."""
    channel = RfChannel(data_rate_bps=rate, loss=0.0, retries=3, seed=1)
    with tempfile.TemporaryDirectory() as tmp:
        async with link_pair(Path(tmp), channel=channel) as pair:
            await asyncio.sleep(0.5)
            loop = asyncio.get_running_loop()
            session, before, start = pair.air.session, channel.air_bytes, loop.time()
            arrived: list[float] = []

            async def watch() -> None:  # when the result reaches the ground
                await wait_for(lambda: any(m.kind == "result" for m in pair.ground.inbox))
                arrived.append(loop.time())

            async def abort(n: int) -> float:  # from the ground to the aircraft
                sent = loop.time()
                pair.ground.session.send_reliable(messages.Abort(reason=f"bench {n}"))
                await wait_for(lambda: len(pair.air.inbox) > n)
                return loop.time() - sent

            watcher, aborts, sent_live = None, [], 0
            for k in range(int(RUN_S)):
                session.send_status(status(float(k)))
                if live and session.air_share() <= LIVE_SHARE:  # as agent/runtime/live.py
                    session.send_live(lateral_live(k))
                    sent_live += 1
                if k == RUN_S // 2:
                    handed = loop.time()
                    session.send_reliable(full_result("mid-run"))
                    watcher = asyncio.create_task(watch())
                if k % 4 == 1:  # 0.3 s into the second: status and live on air or just sent
                    await asyncio.sleep(0.3)
                    aborts.append(await abort(len(aborts)))
                await asyncio.sleep(max(0.0, start + k + 1 - loop.time()))
            await watcher
            delivered = arrived[0] - handed
            per_second = (channel.air_bytes - before) / (loop.time() - start)
    return per_second, delivered, statistics.median(aborts), sent_live


async def measure(rate: float, loss: float) -> tuple[int, int, float, float]:
    channel = RfChannel(data_rate_bps=rate, loss=loss, retries=3, seed=1)
    with tempfile.TemporaryDirectory() as tmp:
        async with link_pair(Path(tmp), channel=channel) as pair:
            await asyncio.sleep(0.5)
            loop = asyncio.get_running_loop()
            times, air = [], []
            for k in range(RUNS):
                before, start = channel.air_bytes, loop.time()
                pair.air.session.send_reliable(full_result(f"m{k}"))
                assert await wait_for(lambda k=k: len(pair.ground.inbox) > k)
                times.append(loop.time() - start)
                air.append(channel.air_bytes - before)
                await asyncio.sleep(0.3)
            frames = len(pair.air.codec.encode(messages.to_dict(full_result())))
    return frames, statistics.median(air), statistics.median(times), max(times)


def main() -> None:
    if "--live-only" not in sys.argv:
        results()
    live_size = len(msgpack.packb(messages.to_dict(lateral_live(5)), use_bin_type=True))
    status_size = len(msgpack.packb(messages.to_dict(status(5.0)), use_bin_type=True))
    print(
        f"\nduring a {RUN_S:g} s run: status {status_size} B/s of MessagePack, live view "
        f"{live_size} B/s (8 channels × 10 samples)"
    )
    print(
        f"{'RF rate':>10}{'live':>6}{'on air (B/s)':>14}{'result delivered (s)':>22}"
        f"{'abort delivered (s)':>21}{'live views sent':>17}"
    )
    for rate in (200_000.0, 10_000.0):
        for live in (False, True):
            per_second, delivered, abort, sent = asyncio.run(measure_run(rate, live))
            print(
                f"{rate / 1000:>8g}k{'on' if live else 'off':>6}{per_second:>14.0f}"
                f"{delivered:>22.2f}{abort:>21.3f}{sent:>17}",
                flush=True,
            )


def results() -> None:
    size = len(msgpack.packb(messages.to_dict(full_result()), use_bin_type=True))
    print(f"full-model result: {size} bytes of MessagePack")
    print(
        f"{'RF rate':>10}{'loss':>7}{'frames':>8}{'on air (B)':>12}{'median s':>10}{'worst s':>9}"
    )
    for rate in (200_000.0, 10_000.0):
        for loss in (0.0, 0.2):
            frames, air, median, worst = asyncio.run(measure(rate, loss))
            cells = f"{frames:>8}{air:>12.0f}{median:>10.3f}{worst:>9.3f}"
            print(f"{rate / 1000:>8g}k{loss:>7.0%}{cells}", flush=True)


if __name__ == "__main__":
    main()
