"""`sysid decode`: a raw sensor capture through the drivers' codecs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from agent.cli import common

# The codecs' names (drivers.decode.CODECS, which imports every codec: kept out of `--help`;
# tests/test_cli_decode.py checks the two agree).
DEVICES = ("airdata", "surfaces", "vn200", "vn200-ascii")


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "decode",
        help="decode a raw sensor capture",
        description="Decode a raw capture (bytes as read from the port) with the drivers' codecs.",
    )
    parser.add_argument(
        "device", choices=DEVICES, metavar="DEVICE", help=f"one of {', '.join(DEVICES)}"
    )
    parser.add_argument("file", type=Path, metavar="FILE")
    parser.add_argument("--json", action="store_true", help="one JSON object per message")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from drivers.decode import as_json, as_text, decode_file

    try:
        args.file.open("rb").close()
    except OSError as exc:
        raise common.refused(f"{args.file}: cannot be read ({exc.strerror or exc})") from None
    messages, stats = decode_file(args.device, args.file)
    try:
        if args.json:  # one object, streamed: the messages, then the stream's statistics
            common.print_json_items(
                "messages", (as_json(m) for m in messages), lambda: {"stats": stats.as_dict()}
            )
        else:
            for message in messages:
                print(as_text(message))
            print("stats: " + ", ".join(f"{k} {v}" for k, v in stats.as_dict().items()))
    except BrokenPipeError:  # the reader (head, less) went away: nothing more to say
        sys.stdout = None
    return common.EXIT_OK
