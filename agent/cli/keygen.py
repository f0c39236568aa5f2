"""`sysid keygen`: a new link key, 32 random bytes in hex, in a file only its owner reads."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from agent.cli import common

KEY_BYTES = 32


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "keygen",
        help="make a new link key file (32 random bytes, mode 0600)",
        description="Make a new link key: 32 bytes from the operating system's random source, "
        "as hex, in a new file readable only by its owner. Copy the same file to both ends "
        "([link] key_file); the fingerprint printed lets the two be compared. An existing "
        "file is never written over.",
    )
    parser.add_argument("file", type=Path, metavar="KEY_FILE")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from agent.link.codec import key_fingerprint

    key = os.urandom(KEY_BYTES)
    try:
        # O_EXCL: a key in use is never replaced (both ends would stop hearing each other).
        fd = os.open(args.file, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        raise common.refused(
            f"{args.file} exists: a key is never written over; give another file name, or "
            "remove the old key on both ends first"
        ) from None
    except OSError as exc:
        raise common.refused(f"{args.file}: cannot be created ({exc.strerror or exc})") from None
    try:
        with os.fdopen(fd, "w") as handle:
            handle.write(key.hex() + "\n")
            handle.flush()
            os.fsync(handle.fileno())
    except OSError as exc:
        args.file.unlink(missing_ok=True)  # never half a key
        raise common.refused(f"{args.file}: not written ({exc.strerror or exc})") from None
    fingerprint = key_fingerprint(key)
    if args.json:
        common.print_json({"file": str(args.file), "fingerprint": fingerprint})
    else:
        print(f"{args.file}: a new link key, fingerprint {fingerprint}")
        print("copy this same file to the other end ([link] key_file), readable by the agent only")
    return common.EXIT_OK
