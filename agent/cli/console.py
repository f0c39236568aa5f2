"""`sysid console`: the ground console (Textual) on the XBee link."""

from __future__ import annotations

import argparse
from pathlib import Path

from agent.cli import common


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "console",
        help="the ground console (Textual) on the XBee link",
        description="Vehicle status, excitation, identification settings, results and the "
        "model-update decision; everything received is also in the ground log.",
    )
    common.service_options(parser, Path("ground.toml"), "the ground log, key and link state")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import asyncio

    from agent.clock import LoopClock
    from agent.ground.app import Console
    from agent.ground.config import GroundConfig
    from agent.ground.station import GroundStation
    from drivers.xbee.driver import RadioError

    config = common.read_config(args.config, GroundConfig)

    async def console() -> None:
        station = GroundStation(config, LoopClock(), base=args.base)
        try:
            await station.open()  # a port or key problem is reported before the screen opens
        except BaseException:
            await station.close()
            raise
        await Console(station).run_async()

    try:
        asyncio.run(console())
    except (OSError, ValueError, RadioError) as exc:
        raise common.failed(str(exc)) from None
    return common.EXIT_OK
