"""The `sysid` command: parse arguments, load config, call in. Exit 0 ok, 1 failed, 2 bad input,
130 interrupted (Ctrl-C).

One module per command, each with `add_parser(sub)` (its options; `set_defaults(run=…)`) and
`run(args) -> exit code`, importing what it needs only when it runs, so that `sysid --help`
stays quick. A command stops with `common.CommandError` (or `refused`, `failed`); `main`
turns that, a usage error, Ctrl-C and, under `--json`, a bug into its message and exit code,
once.
Every `add_parser` opens alike (name, help, description) on purpose: a command's words stay
in its own module; what commands share (options, config loading) is in `common`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from agent import __version__
from agent.cli import (
    analyze,
    config_check,
    console,
    decode,
    excite,
    export,
    identify,
    import_log,
    keygen,
    onboard,
    report,
    sim,
    sim_aircraft,
    tune,
)
from agent.cli.common import (
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    CommandError,
    Parser,
    UsageError,
    json_state,
    print_json,
    say_error,
)

COMMANDS = (
    identify,
    analyze,
    report,
    excite,
    decode,
    import_log,
    export,
    tune,
    sim_aircraft,
    onboard,
    sim,
    console,
    config_check,
    keygen,
)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="sysid",
        description="System identification of small fixed-wing "
        "aircraft, onboard and on the ground. Exit 0 ok, 1 failed, 2 bad input, "
        "130 interrupted.",
    )
    parser.add_argument("--version", action="version", version=f"sysid {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `sysid` console script. Under `--json` an unexpected error (a bug)
    or Ctrl-C still leaves exactly one JSON object on stdout; a bug's traceback goes to
    stderr, Ctrl-C's is left out (exit 130)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = build_parser().parse_args(argv)
    except UsageError as exc:
        exc.parser.print_usage(sys.stderr)
        say_error(exc.parser.prog.removeprefix("sysid "), str(exc))
        if "--json" in argv:
            print_json({"error": {"kind": "usage", "message": str(exc), "exit": EXIT_BAD_INPUT}})
        return EXIT_BAD_INPUT
    json_state.update(printed=False, error=None)
    name = getattr(args, "name", args.command)
    as_json = getattr(args, "json", False)
    try:
        code = args.run(args)
        if as_json and not json_state["printed"]:
            # A command that ended without its object: its error (every error path says one).
            message = json_state["error"] or f"exit {code}"
            print_json(
                {"error": {"kind": "error" if code else "none", "message": message, "exit": code}}
            )
        return code
    except CommandError as exc:
        say_error(name, exc.message if exc.kind == "error" else f"{exc.kind}: {exc.message}")
        if as_json and not json_state["printed"]:  # a streamed object closed with its error
            print_json({"error": {"kind": exc.kind, "message": exc.message, "exit": exc.code}})
        return exc.code
    except KeyboardInterrupt:
        message = "interrupted (Ctrl-C)"
        say_error(name, message)
        if as_json and not json_state["printed"]:
            print_json(
                {"error": {"kind": "interrupted", "message": message, "exit": EXIT_INTERRUPTED}}
            )
        return EXIT_INTERRUPTED
    except Exception as exc:
        if not as_json:
            raise
        import traceback

        traceback.print_exc()
        message = f"internal error: {type(exc).__name__}: {exc}"
        if not json_state["printed"]:
            print_json({"error": {"kind": "internal", "message": message, "exit": EXIT_FAILED}})
        return EXIT_FAILED
