"""`sysid sim-aircraft`: the simulated aircraft alone, for `sysid agent` to fly against."""

from __future__ import annotations

import argparse
from pathlib import Path

from agent.cli import common


def add_parser(sub) -> None:
    parser = sub.add_parser(
        "sim-aircraft",
        help="run the simulated aircraft alone (JSBSim, emulated ArduPlane, sensor ptys)",
        description="Fly the simulated aircraft and print where its MAVLink port and sensor "
        "pseudo-terminals are, so `sysid agent` can be pointed at it as at a real aircraft.",
    )
    common.aircraft_arguments(parser)
    parser.add_argument(
        "--mavlink-port",
        type=common.port,
        default=14555,
        help="UDP port the emulated autopilot listens on (0: any)",
    )
    parser.add_argument(
        "--pty-dir",
        type=Path,
        default=Path("sim"),
        help="directory for the sensor port links (default ./sim)",
    )
    parser.add_argument(
        "--switch-at",
        type=float,
        nargs="*",
        default=[],
        metavar="T",
        help="flip the switch at these seconds: high, low, …",
    )
    parser.add_argument("--no-noise", action="store_true", help="perfect sensors")
    parser.add_argument(
        "--sensor-rate",
        type=float,
        default=100.0,
        metavar="HZ",
        help="frame rate of the three sensors (default 100; 400 is the VN-200's IMU rate)",
    )
    parser.add_argument("--duration", type=float, help="stop after this many seconds")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import asyncio

    from agent.sim.aircraft import check_sensor_rate, serve
    from agent.sim.plant import PlantError

    options = common.aircraft_options(
        args,
        noise=not args.no_noise,
        mavlink_port=args.mavlink_port,
        sensor_rate_hz=args.sensor_rate,
    )
    try:
        check_sensor_rate(args.sensor_rate)
    except ValueError as exc:
        raise common.refused(str(exc)) from None
    announce = lambda text: print(text, flush=True)  # noqa: E731
    try:
        asyncio.run(
            serve(options, args.pty_dir, args.duration, tuple(args.switch_at), announce=announce)
        )
    except PlantError as exc:
        raise common.refused(str(exc)) from None
    except OSError as exc:
        raise common.refused(f"cannot start: {exc}") from None
    except KeyboardInterrupt:
        pass
    return common.EXIT_OK
