"""`sysid agent`: the onboard flight agent."""

from __future__ import annotations

import argparse
import sys

from agent.cli import common


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "agent",
        help="run the onboard flight agent",
        description="The onboard agent: sensors, autopilot, recorder, "
        "excitation, identification, radio link; stop with Ctrl-C.",
    )
    common.service_options(parser, common.DEFAULT_CONFIG, "logs, models and link state")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import asyncio

    from agent.runtime import serve
    from drivers.xbee.driver import RadioError

    config = common.read_config(args.config)
    text = args.config.read_text()
    listener = log_to_stderr_off_the_loop()
    try:
        asyncio.run(serve(config, text, args.base))
    except (OSError, ValueError, RadioError) as exc:  # a port that cannot open, a bad key file
        raise common.failed(str(exc)) from None
    finally:
        listener.stop()
    return common.EXIT_OK


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
