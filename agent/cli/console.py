"""`sysid console`: the ground console (Textual) on the XBee link."""

from __future__ import annotations

import argparse
from pathlib import Path

from agent.cli.common import EXIT_OK, failed, refused


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "console",
        help="the ground console (Textual) on the XBee link",
        description="Vehicle status, excitation, identification settings, results and the "
        "model-update decision; everything received is also in the ground log.",
    )
    parser.add_argument("--config", type=Path, default=Path("ground.toml"))
    parser.add_argument(
        "--base",
        type=Path,
        default=Path("."),
        help="directory for the ground log, key and link state (default .)",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import asyncio

    from agent.clock import LoopClock
    from agent.config import ConfigError, load_config
    from agent.ground.app import Console
    from agent.ground.config import GroundConfig
    from agent.ground.station import GroundStation
    from drivers.xbee.driver import RadioError

    try:
        config = load_config(args.config, GroundConfig)
    except ConfigError as exc:
        raise refused(str(exc)) from None

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
        raise failed(str(exc)) from None
    return EXIT_OK
