"""`sysid agent`: the onboard flight agent."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from agent.cli.common import DEFAULT_CONFIG, EXIT_OK, failed, refused


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "agent",
        help="run the onboard flight agent",
        description="The onboard agent: sensors, autopilot, recorder, "
        "excitation, identification, radio link; stop with Ctrl-C.",
    )
    parser.add_argument("--config", type=Path, default=DEFAULT_CONFIG)
    parser.add_argument(
        "--base",
        type=Path,
        default=Path("."),
        help="directory for logs, models and link state (default .)",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import asyncio

    from agent.config import ConfigError, load_config
    from agent.runtime import serve
    from drivers.xbee.driver import RadioError

    try:
        config = load_config(args.config)
        text = args.config.read_text()
    except ConfigError as exc:
        raise refused(str(exc)) from None
    listener = log_to_stderr_off_the_loop()
    try:
        asyncio.run(serve(config, text, args.base))
    except (OSError, ValueError, RadioError) as exc:  # a port that cannot open, a bad key file
        raise failed(str(exc)) from None
    finally:
        listener.stop()
    return EXIT_OK


def log_to_stderr_off_the_loop():
    """INFO and up to stderr through a queue and a listener thread: a write to stderr (a file,
    a pipe to journald) can block for 0.1 s when the disk is busy, and the loop thread must
    never wait on it. Returns the started listener."""
    import logging.handlers
    import queue

    records: queue.SimpleQueue = queue.SimpleQueue()
    console = logging.StreamHandler(sys.stderr)
    console.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s %(message)s"))
    listener = logging.handlers.QueueListener(records, console)
    root = logging.getLogger()
    root.setLevel(logging.INFO)
    root.addHandler(logging.handlers.QueueHandler(records))
    listener.start()
    return listener
