"""The link's budget for one full-model identification result (eight states, four inputs,
eight outputs: A, B, C, D, five modes with every quality index), end to end through the real
digi-xbee transport and our session over the emulated 900HP radios.

    .venv/bin/python benchmarks/bench_link.py

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

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agent.link import messages
from agent.sim.radio import RfChannel
from tests.link.pair import link_pair, wait_for
from tests.link.test_link_radio import full_result

RUNS = 5


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
                assert await wait_for(lambda k=k: len(pair.ground.inbox) > k, 60)
                times.append(loop.time() - start)
                air.append(channel.air_bytes - before)
                await asyncio.sleep(0.3)
            frames = len(pair.air.codec.encode(messages.to_dict(full_result())))
    return frames, statistics.median(air), statistics.median(times), max(times)


def main() -> None:
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
