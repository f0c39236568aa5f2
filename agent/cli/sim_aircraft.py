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
    parser.add_argument("--aircraft", default="J3Cub", help="JSBSim aircraft (default J3Cub)")
    parser.add_argument("--speed-kts", type=float, default=60.0)
    parser.add_argument("--altitude-ft", type=float, default=1000.0)
    parser.add_argument(
        "--turbulence",
        type=common.turbulence,
        default=0.0,
        help="Dryden intensity: 0 none, 1 light (W20 = 5 ft/s), 5 ≈ MIL-F-8785C light (15 kt), "
        "at most 15 (severe)",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--no-vanes",
        action="store_true",
        help="air data with the airspeed only (no α, β vanes): the agent synthesises α and β "
        "from the INS",
    )
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
        altitude_ft=args.altitude_ft,
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
