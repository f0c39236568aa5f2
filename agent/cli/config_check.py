"""`sysid config check`: validate a config file."""

from __future__ import annotations

import argparse
from pathlib import Path

from agent.cli.common import DEFAULT_CONFIG, EXIT_OK, refused


def add_parser(sub) -> None:
    parser = sub.add_parser("config", help="configuration tools")
    config_sub = parser.add_subparsers(dest="config_command", required=True)
    check = config_sub.add_parser("check", help="validate a config file")
    check.add_argument("file", nargs="?", type=Path, default=DEFAULT_CONFIG)
    check.add_argument("--ground", action="store_true", help="the file is a ground console config")
    check.set_defaults(run=run, name="config check")


def run(args: argparse.Namespace) -> int:
    from agent.config import Config, ConfigError, load_config
    from agent.ground.config import GroundConfig

    try:
        load_config(args.file, GroundConfig if args.ground else Config)
    except ConfigError as exc:
        raise refused(str(exc)) from None
    print(f"{args.file}: ok")
    return EXIT_OK
