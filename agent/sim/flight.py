"""`sysid sim`: a whole flight with no hardware — the simulated aircraft (JSBSim, emulated
ArduPlane, sensor ptys), emulated radios, the real agent, and a scripted ground operator who
arms a preset, has the pilot flip the switch, receives the result over the radio link and
decides on it."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import secrets
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from agent import sizing
from agent.clock import LoopClock
from agent.config import (
    AirDataPort,
    Autopilot,
    Config,
    Envelope,
    Excitation,
    IdentificationConfig,
    Link,
    Recorder,
    Runtime,
    Sensors,
    SurfacePort,
    VectorNav,
    to_toml,
)
from agent.excitation.plan import planned_s, preset
from agent.link import messages
from agent.link.codec import GROUND
from agent.link.endpoint import build_endpoint
from agent.link.session import LinkSession
from agent.runtime import Agent
from agent.sim.aircraft import TICK_HZ, AircraftOptions, SimAircraft
from agent.sim.ardupilot import Params
from agent.sim.pace import Overdue, Pace, Stopped
from agent.sim.pilot import recovered
from agent.sim.plant import KT, PlantError
from agent.sim.radio import EmulatedXBee, RfChannel, module_pair
from agent.sim.truth import CHECK_TIC, check, linear_truth
from drivers.xbee.driver import RadioError, XBeeRadio

log = logging.getLogger(__name__)

AIR = bytes.fromhex("0013A20041000001")
GROUND_ADDR = bytes.fromhex("0013A20041000002")
# Deadlines of the scripted operator on a quiet machine (s): connection, an acknowledgement
# (arming the full preset renders its multisines first), a result after the plan ends
# (recorder margin + identification + radio). Each stretches with the slowness measured while
# it runs (agent.sim.pace): a busy laptop still flies.
CONNECT_S, ACK_S, RESULT_S = 30.0, 10.0, 90.0
# The simulated world counts as in real time within this (its sensors' frames then arrive
# within the recorder's assembly delay).
CAUGHT_UP_S = 0.1
OPEN_ATTEMPTS = 3


class SimError(RuntimeError):
    """The simulated flight did not get where it should (the message says where)."""


@dataclass
class SimOptions:
    plane: AircraftOptions = field(default_factory=AircraftOptions)
    """The simulated aircraft (the flight sets its ArduPlane parameters and DataFlash log)."""
    preset: str = "full"
    runs: int = 1
    directory: Path | None = None
    progress: object = None  # callable(str) for progress lines
    realtime_priority: int | None = None
    """The agent's [runtime] realtime_priority (the benchmarks run it as in the field)."""
    sizing: bool = False
    """The scripted operator has each plan sized by the aircraft (a SizeRequest, agent/sizing.py)
    and arms the sized plan; False: it arms the preset at its own amplitudes."""
    until_accepted: bool = False
    """Stop after the first run whose model the operator accepts (`runs` is then the most)."""


@dataclass
class Ground:
    """The scripted operator's end of the link."""

    session: LinkSession
    radio: XBeeRadio
    inbox: list = field(default_factory=list)
    received_at: list = field(default_factory=list)
    """When each inbox message arrived (monotonic s, the agent's clock base on this machine)."""
    acks: dict = field(default_factory=dict)
    accepted: bool = False
    pace: Pace = field(default_factory=lambda: Pace(LoopClock()))
    """What the operator's deadlines stretch with (the flight's sets the simulator and the
    agent's processes)."""

    def on_message(self, message, seq) -> None:
        if isinstance(message, messages.Ack):
            self.acks[message.ref] = message
        else:
            self.inbox.append(message)
            self.received_at.append(time.monotonic())

    def flight_mode(self) -> str | None:
        """The flight mode in the aircraft's latest status (None: no status, or no autopilot)."""
        for message in reversed(self.inbox):
            if isinstance(message, messages.Status):
                return message.flight_mode
        return None

    async def command(self, message) -> messages.Ack:
        seq = self.session.send_reliable(message)
        await wait(
            self.pace, lambda: seq in self.acks, f"no acknowledgement of {message.kind}", ACK_S
        )
        return self.acks[seq]


async def wait(pace: Pace, predicate, failure: str, base_s: float, fixed_s: float = 0.0):
    """predicate()'s first truthy value; SimError "`failure` in N s" once the deadline,
    stretched for a busy machine, has passed (`Pace.until`)."""
    found = await pace.until(predicate, base_s, fixed_s)
    if isinstance(found, Overdue):
        raise SimError(found.message(failure))
    if isinstance(found, Stopped):
        raise SimError(f"{failure}: {found.reason}")
    return found


async def until(predicate, timeout: float, poll_s: float = 0.05):
    """predicate()'s first truthy value, polled every `poll_s`; None after `timeout` seconds
    (the simulator's and the benchmarks' waits: each has its own reason for its bound)."""
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not (found := predicate()):
        if loop.time() > end:
            return None
        await asyncio.sleep(poll_s)
    return found


# The simulated aircraft's envelope around its trim, as an operator would set it for that
# aircraft: the default (12–35 m/s and 40 m of height, a small UAV's) refused every plan on a
# 90 kt PA-28, then aborted the full preset when its phugoid had lost 40 m. The height limit
# is this many seconds of the trim airspeed (93 m on the Cub, 139 m on the PA-28).
ENVELOPE_SPEED = (0.6, 1.3)
ENVELOPE_HEIGHT_S = 3.0


def agent_config(
    tmp: Path,
    ports: Path,
    mavlink: tuple[str, int],
    axes: str,
    realtime_priority: int | None = None,
    speed_kts: float = 60.0,
    glide_deg: float | None = None,
    true_airspeed: float | None = None,
    vanes: bool = True,
) -> Config:
    """The simulated flight's agent configuration: the defaults but for the sensor ports under
    `ports`, the autopilot at `mavlink`, the link's files under `tmp`, the log directory, the
    identification's axes, the real-time priority, and an envelope fitting the simulated
    aircraft at `speed_kts`. `glide_deg`: an unpowered aircraft's trim glide angle — it has
    no throttle to excite, and its height limit adds what the glide itself loses over the
    longest run. `true_airspeed` (m/s): the trim's, which the air data measure and the
    envelope's airspeeds are taken about (default: `speed_kts`). `vanes` False: the air data
    measure the airspeed only (`sysid sim --no-vanes`)."""
    trim = true_airspeed or speed_kts * KT
    excitation = Excitation()
    height = max(40.0, ENVELOPE_HEIGHT_S * trim)
    surfaces = excitation.surfaces
    if glide_deg is not None:
        surfaces = {c: v for c, v in surfaces.items() if c != "throttle"}
        sink = trim * np.sin(np.radians(-glide_deg))
        height += sink * excitation.envelope.max_duration_s
    return Config(
        runtime=Runtime(realtime_priority=realtime_priority),
        excitation=Excitation(
            surfaces=surfaces,
            envelope=Envelope(
                min_airspeed=ENVELOPE_SPEED[0] * trim,
                max_airspeed=ENVELOPE_SPEED[1] * trim,
                max_altitude_loss_m=height,
            ),
        ),
        identification=IdentificationConfig(axes=axes),
        sensors=Sensors(
            vn200=VectorNav(port=str(ports / "vn200")),
            airdata=AirDataPort(port=str(ports / "airdata"), vanes=vanes),
            surfaces=SurfacePort(port=str(ports / "surfaces")),
        ),
        autopilot=Autopilot(url=f"udpout://{mavlink[0]}:{mavlink[1]}"),
        link=Link(
            port=str(ports / "xbee-air"),
            peer=GROUND_ADDR.hex(),
            key_file=str(tmp / "link.key"),
            # The aircraft's link state in a folder of its own, as on a flight computer's
            # card: a test can fill that file system alone (tests/sim/test_sim_hardening.py).
            counter_file=str(tmp / "air" / "link.counter"),
            seen_file=str(tmp / "air" / "link.seen"),
        ),
        recorder=Recorder(log_dir=str(tmp / "logs")),
    )


class AgentProcess:
    """The real `sysid agent` entry point in its own process, for faults only a process can
    have (kill -9) and for the benchmark; output in agent-N.log in the flight's directory."""

    def __init__(self, directory: Path, config: Config):
        self.directory = directory
        self.config_path = directory / "agent.toml"
        self.config_path.write_text(to_toml(config))
        self.proc: subprocess.Popen | None = None
        self.starts = 0

    def start(self) -> None:
        self.starts += 1
        log = open(self.directory / f"agent-{self.starts}.log", "w")  # noqa: SIM115
        with log:
            env = {
                **os.environ,
                "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "1"),
            }
            self.proc = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "agent",
                    "agent",
                    "--config",
                    str(self.config_path),
                    "--base",
                    str(self.directory),
                ],
                stdout=log,
                stderr=subprocess.STDOUT,
                env=env,
            )

    @property
    def pid(self) -> int | None:
        return None if self.proc is None else self.proc.pid

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def kill(self, sig: int = signal.SIGKILL) -> None:
        if self.alive():
            self.proc.send_signal(sig)

    async def stop(self, timeout: float = 20.0) -> int | None:
        """SIGTERM (the agent's clean shutdown), then SIGKILL after `timeout`."""
        if self.proc is None:
            return None
        self.kill(signal.SIGTERM)
        try:
            return await asyncio.to_thread(self.proc.wait, timeout)
        except subprocess.TimeoutExpired:
            self.kill(signal.SIGKILL)
            return await asyncio.to_thread(self.proc.wait)


@dataclass
class SimFlight:
    """A simulated flight in progress: every part, for the scripted operator and for the
    fault tests that cut, unplug or silence one of them."""

    options: SimOptions
    directory: Path
    clock: LoopClock
    aircraft: SimAircraft
    channel: RfChannel
    air_module: EmulatedXBee
    ground_module: EmulatedXBee
    agent: Agent | AgentProcess
    """In this process, or (agent_process=True) the real entry point in its own."""
    ground: Ground | None


async def fly(options: SimOptions) -> dict:
    """Fly the scripted session; returns what `sysid sim` prints."""
    say = options.progress or (lambda text: None)
    async with simulated(options) as sim:
        outcomes = []
        for run in range(options.runs):
            outcomes.append(await one_run(options, sim.aircraft, sim.ground, run, say))
            if options.until_accepted and outcomes[-1].get("decision") == "accept":
                break
    # After the flight is torn down: the truth's linearisation takes seconds (tens on a busy
    # machine) and would hold the event loop the agent and the aircraft still ran on.
    return _report(options, sim.aircraft, sim.agent, outcomes, sim.ground)


@contextlib.asynccontextmanager
async def simulated(
    options: SimOptions,
    params: Params | None = None,
    operator: bool = True,
    agent_process: bool = False,
):
    """The aircraft, radios, agent and ground, connected and in trimmed flight; torn down in
    order on exit. `params`: the emulated ArduPlane's (default: switch on channel 7).
    `operator`: False leaves the ground radio free for the console (`sim.ground` is None).
    `agent_process`: run `sysid agent` as its own process (`sim.agent` is an AgentProcess;
    needs the operator, whose link coming up tells that the agent is up)."""
    say = options.progress or (lambda text: None)
    with contextlib.ExitStack() as stack:
        # Absolute: the agent resolves its config's paths against this directory, and a
        # relative one (`--keep flight`) was taken twice (flight/flight/link.key: no link).
        tmp = (
            Path(options.directory).resolve()
            if options.directory
            else Path(stack.enter_context(tempfile.TemporaryDirectory()))
        )
        params = params or Params(switch_channel=7)
        async with _parts(options, Path(tmp), params, say, operator, agent_process) as sim:
            yield sim


@contextlib.asynccontextmanager
async def _parts(
    options: SimOptions, tmp: Path, params: Params, say, operator: bool, agent_process: bool
):
    clock = LoopClock()
    ports = tmp / "ports"
    ports.mkdir(parents=True, exist_ok=True)
    # A new key for each flight, in a file created readable by its owner alone, as `sysid
    # keygen` makes it: `load_key` refuses a key other users can read, on both ends.
    (tmp / "link.key").unlink(missing_ok=True)
    fd = os.open(tmp / "link.key", os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as handle:
        handle.write(secrets.token_bytes(32).hex() + "\n")
    plane = replace(options.plane, params=params, dataflash=tmp / "ardupilot.bin")
    aircraft = SimAircraft(plane, clock, ports)
    channel, air, ground_module = module_pair(
        ports, clock, ("xbee-air", AIR), ("xbee-ground", GROUND_ADDR)
    )
    tasks = [
        asyncio.create_task(aircraft.run(), name="sim-aircraft"),
        asyncio.create_task(air.run(), name="xbee-air"),
        asyncio.create_task(ground_module.run(), name="xbee-ground"),
    ]
    ground = agent = None

    def workers() -> list[int | None]:
        """The agent's processes besides this one, whose CPU waits stretch deadlines too."""
        if isinstance(agent, AgentProcess):
            return [agent.pid]
        return [] if agent is None else [agent.identification.worker_pid]

    pace = Pace(clock, flown=lambda: aircraft.ticks / TICK_HZ, pids=workers)
    pace.stopped = lambda: _stopped(tasks[0])
    try:
        await wait(
            pace,
            lambda: (
                aircraft.mavlink_address is not None
                and air.port.plugged
                and ground_module.port.plugged
            ),
            "the simulated aircraft did not start",
            CONNECT_S,
        )
        axes = preset(options.preset).axes
        glide = None if aircraft.plant.engines else aircraft.plant.glide_deg
        config = agent_config(
            tmp,
            ports,
            aircraft.mavlink_address,
            axes,
            options.realtime_priority,
            plane.speed_kts,
            glide_deg=glide,
            true_airspeed=aircraft.plant.true_airspeed,
            vanes=plane.vanes,
        )
        if agent_process:
            agent = AgentProcess(tmp, config)
            agent.start()
        else:
            agent = Agent(config, base=tmp, clock=clock)
            tasks.append(asyncio.create_task(agent.run(), name="agent"))
        if operator:
            ground = await ground_station(
                module=ground_module, directory=tmp, clock=clock, tasks=tasks
            )
            ground.pace = pace
        say(f"simulated {plane.aircraft} at {plane.speed_kts:g} kt; agent up")

        def connected() -> bool:
            if agent_process:  # the agent's status names the autopilot's flight mode
                return ground is not None and ground.flight_mode() is not None
            return agent.autopilot.connected and (ground is None or ground.session.link_up)

        late = await pace.until(connected, CONNECT_S)
        if isinstance(late, Stopped):
            raise SimError(f"the agent did not connect: {late.reason}")
        if isinstance(late, Overdue):
            if agent_process:
                missing = "the autopilot and the ground (no status with a flight mode)"
            else:
                parts = [
                    ("the autopilot", agent.autopilot.connected),
                    ("the ground", ground is None or ground.session.link_up),
                ]
                missing = " and ".join(name for name, up in parts if not up)
            raise SimError(late.message(f"the agent did not connect to {missing}"))
        await asyncio.sleep(1.0)  # trimmed flight before the first excitation
        yield SimFlight(options, tmp, clock, aircraft, channel, air, ground_module, agent, ground)
    finally:
        # The agent and the ground stop first (their radios close while the emulated modules
        # still exist), then the radios and the aircraft.
        inner = [t for t in tasks if t.get_name() in ("agent", "ground-session", "ground-radio")]
        for task in inner:
            task.cancel()
        await asyncio.gather(*inner, return_exceptions=True)
        if agent_process and agent is not None:
            await agent.stop()
        if ground is not None:
            await ground.radio.close()
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


async def ground_station(
    *, module: EmulatedXBee, directory: Path, clock: LoopClock, tasks: list[asyncio.Task]
) -> Ground:
    """The scripted operator's end: the link as the ground console builds it (`build_endpoint`,
    the flight's key, its own counter and replay state), on the ground's emulated module."""
    config = Link(
        port=str(module.path),
        peer=AIR.hex(),
        key_file="link.key",
        counter_file="ground.counter",
        seen_file="ground.seen",
    )
    ground = Ground(None, None)  # type: ignore[arg-type]
    radio, ground.session = build_endpoint(
        cfg=config, role=GROUND, base=directory, clock=clock, on_message=ground.on_message
    )
    ground.radio = radio
    for attempt in range(OPEN_ATTEMPTS):
        try:
            await radio.open()
            break
        except RadioError as exc:
            # Once in a few dozen starts here digi-xbee's open of an emulated module timed out,
            # its reader spinning on "readiness to read but returned no data": try again.
            if attempt == OPEN_ATTEMPTS - 1:
                raise
            log.warning("simulated ground radio: %s; opening again", exc)
    tasks.append(asyncio.create_task(ground.session.run(), name="ground-session"))
    tasks.append(asyncio.create_task(radio.watch(), name="ground-radio"))
    return ground


async def one_run(options: SimOptions, aircraft: SimAircraft, ground: Ground, run: int, say):
    controls = ("elevator", "aileron", "rudder")
    if aircraft.plant.engines:
        controls = ("throttle", *controls)
    plan = preset(options.preset, plan_id=f"{options.preset}-{run + 1}", controls=controls)
    ack = await ground.command(messages.IdentSettings(axes=plan.axes))
    sized = None
    if options.sizing:
        plan, sized = await size(ground, plan)
        for line in sizing.message_lines(sized):
            say(f"run {run + 1}: {line}")
    ack = await ground.command(messages.Arm(plan=plan))
    if not ack.ok:
        raise SimError(f"the agent refused the plan: {ack.reason}")
    # A busy machine can leave the simulated world behind real time (its sensors' frames late,
    # a driver taking a second's silence for an unplugged device): the pilot waits for it, as
    # no real aircraft falls behind.
    await wait(
        ground.pace,
        lambda: aircraft.behind() < CAUGHT_UP_S,
        "the simulated world not back to real time",
        ACK_S,
    )
    if aircraft.recoveries:  # the safety pilot has the aircraft in FBWA: back near the trim
        await wait(
            ground.pace,
            lambda: recovered(aircraft.truth, aircraft.trimmed),
            "the aircraft not recovered from its departure",
            RESULT_S,
        )
    say(f"run {run + 1}: {plan.id} armed; the pilot flips the switch")
    seen = len(ground.inbox)
    aircraft.pilot.set_switch(True)

    def ends(m) -> bool:
        """A result or a failure ends the run's wait; so does the run aborted (the agent does
        not identify an aborted run: no result follows)."""
        aborted = isinstance(m, messages.ExcitationEvent) and m.event == "aborted"
        return (aborted and m.plan_id == plan.id) or isinstance(
            m, messages.Result | messages.Failure
        )

    def answered() -> bool:
        return any(ends(m) for m in ground.inbox[seen:])

    failure = f"no identification result for {plan.id}"
    await wait(ground.pace, answered, failure, RESULT_S, fixed_s=planned_s(plan))
    aircraft.pilot.set_switch(False)
    answer = next(m for m in ground.inbox[seen:] if ends(m))
    events = [m.event for m in ground.inbox[seen:] if isinstance(m, messages.ExcitationEvent)]
    if isinstance(answer, messages.ExcitationEvent):
        reason = f"{plan.id} aborted: {answer.detail}"
        say(f"run {run + 1}: {reason}")
        return {"plan": plan.id, "events": events, "failure": reason, "sizing": sized}
    if isinstance(answer, messages.Failure):
        say(f"run {run + 1}: identification failed: {answer.reason}")
        return {"plan": plan.id, "events": events, "failure": answer.reason, "sizing": sized}
    # A build-up run calibrates the next (its small response stands least above the noise):
    # the operator does not make its model nominal; the sized run's is the first.
    build_up = sized is not None and sized.build_up
    accept = not build_up and _operator_accepts(answer, first=not ground.accepted)
    decision = "accept" if accept else "reject"
    ack = await ground.command(messages.Decision(model_id=answer.model_id, accept=accept))
    ground.accepted |= accept and ack.ok
    say(
        f"run {run + 1}: result {answer.model_id} received; operator: {decision} "
        f"({'ok' if ack.ok else ack.reason})"
    )
    return {
        "plan": plan.id,
        "events": events,
        "result": answer,
        "decision": decision,
        "sizing": sized,
    }


async def size(ground: Ground, plan) -> tuple:
    """The aircraft's sizing of `plan` (a SizeRequest answered by a Sizing message): the sized
    plan and the message. SimError when the aircraft refuses it or predicts it out of the
    envelope."""
    seen = len(ground.inbox)
    ack = await ground.command(messages.SizeRequest(plan=plan))
    if not ack.ok:
        raise SimError(f"the agent would not size the plan: {ack.reason}")

    def answered():
        return next((m for m in ground.inbox[seen:] if isinstance(m, messages.Sizing)), None)

    sized = await wait(ground.pace, answered, f"no sizing of {plan.id}", ACK_S)
    if sized.refusals:
        raise SimError(f"{plan.id}: the aircraft predicts " + "; ".join(sized.refusals))
    return sized.plan, sized


async def pilot_follows_arming(sim: SimFlight, delay_s: float = 2.0) -> None:
    """For `sysid sim --interactive`: the safety pilot flips the switch high a moment after a
    plan is armed, and back low once the run is over (a real pilot does this on the radio)."""
    pilot, scheduler = sim.aircraft.pilot, sim.agent.scheduler
    armed_at = None
    while True:
        await asyncio.sleep(0.1)
        status, now = scheduler.status, sim.clock.now()
        if status == "armed" and not pilot.switch_high:
            armed_at = armed_at or now
            if now - armed_at >= delay_s:
                pilot.set_switch(True)
        elif status == "idle" and pilot.switch_high:
            pilot.set_switch(False)
            armed_at = None
        elif status != "armed":
            armed_at = None


async def interactive(options: SimOptions) -> None:
    """`sysid sim --interactive`: the console instead of the scripted operator."""
    async with console_flight(options) as (_, app):
        await app.run_async()


@contextlib.asynccontextmanager
async def console_flight(options: SimOptions):
    """The simulated flight with the ground console (not yet running) on the ground radio,
    and the simulated pilot flipping the switch for armed plans; yields (sim, app)."""
    from agent.config import Link
    from agent.ground.app import Console
    from agent.ground.config import GroundConfig
    from agent.ground.station import GroundStation

    async with simulated(options, operator=False) as sim:
        config = GroundConfig(
            link=Link(
                port=str(sim.ground_module.path),
                peer=AIR.hex(),
                key_file="link.key",
                counter_file="ground.counter",
                seen_file="ground.seen",
            ),
            log_dir="ground-logs",
        )
        station = GroundStation(config, sim.clock, base=sim.directory)
        pilot = asyncio.create_task(pilot_follows_arming(sim), name="sim-pilot")
        try:
            yield sim, Console(station)
        finally:
            pilot.cancel()
            await asyncio.gather(pilot, return_exceptions=True)


def _operator_accepts(result: messages.Result, first: bool) -> bool:
    """The scripted operator: follows the suggestion; with no nominal model yet, accepts a
    stable candidate that passes the fit step (agent.models: TIC_jj < 0.3, or in unmeasured
    turbulence the excited bins and a repeat) and has every mode its axes must have as the
    first nominal, even if the quality step flagged a mode — a human establishing a baseline
    would."""
    if result.suggest_update:
        return True
    checks = result.checks
    return first and all(checks.get(step, False) for step in ("stability", "fit", "modes"))


def _stopped(task: asyncio.Task) -> str | None:
    """Why the simulated aircraft stopped flying (None: it flies): what ended its task."""
    if not task.done():
        return None
    if task.cancelled():
        return "the simulated aircraft was stopped"
    exc = task.exception()
    return f"the simulated aircraft stopped: {exc}" if exc else "the simulated aircraft stopped"


def _truth(
    aircraft: SimAircraft, axes: str
) -> tuple[dict[str, complex | list[complex] | None], dict]:
    """The named modes of JSBSim's linear model at this trim (agent.sim.truth), and its check
    against JSBSim's own response there (truth.check: a doublet on each surface and a throttle
    step; validated where every test's worst TIC is within truth.CHECK_TIC). The benchmark's
    aircraft pass it (`benchmarks/truth_check.py`); another aircraft's truth may not, and the
    errors against it then say little: the report says which."""
    options = aircraft.options
    truth_model = linear_truth(options.aircraft, options.speed_kts, altitude_ft=options.altitude_ft)
    modes = truth_model.modes()
    tests = {c.test: c.worst for c in check(truth_model)}
    verdict = {
        "validated": all(tic <= CHECK_TIC for tic in tests.values()),
        "bound": CHECK_TIC,
        "worst_tic": tests,
    }

    def one(name: str) -> complex | None:
        return modes[name][0] if modes.get(name) else None

    truth: dict[str, complex | list[complex] | None] = {
        "Dutch roll": one("Dutch roll"),
        "roll": one("roll"),
        "spiral": one("spiral"),
    }
    if axes != "lateral":
        truth["phugoid"] = one("phugoid")
        truth["short period"] = list(modes.get("short period", []))
    return truth, verdict


def _report(
    options: SimOptions, aircraft: SimAircraft, agent: Agent, outcomes: list, ground: Ground
) -> dict:
    last = outcomes[-1]
    result = last.get("result")
    try:
        truth, truth_check = _truth(aircraft, preset(options.preset).axes)
    except PlantError as exc:  # the flight's results stand without a truth to judge them by
        truth, truth_check = {}, {"validated": False, "error": str(exc)}
    rows = []
    if result is not None:
        for mode in result.modes:
            lam = complex(mode.real, mode.imag)
            candidates = truth.get(mode.name or "")
            candidates = candidates if isinstance(candidates, list) else [candidates]
            candidates = [c for c in candidates if c is not None]
            ref = min(candidates, key=lambda c: abs(c - lam), default=None)
            rows.append(
                {
                    "name": mode.name,
                    "eigenvalue": [lam.real, lam.imag],
                    "frequency_rad_s": abs(lam),
                    "damping": mode.damping,
                    "emac": mode.emac,
                    "sigma_pct": (
                        None
                        if mode.frequency_std_rad_s is None or not abs(lam)
                        else 100 * mode.frequency_std_rad_s / abs(lam)
                    ),
                    "msv": mode.msv,
                    "truth": None if ref is None else [ref.real, ref.imag],
                    "error": None if ref is None else abs(lam - ref) / abs(ref),
                }
            )
    truth_modes = {
        k: (
            [[c.real, c.imag] for c in v]
            if isinstance(v, list)
            else None
            if v is None
            else [v.real, v.imag]
        )
        for k, v in truth.items()
    }
    return {
        "aircraft": options.plane.aircraft,
        "preset": options.preset,
        "runs": len(outcomes),
        "events": last["events"],
        "modes": rows,
        "truth_modes": truth_modes,
        "truth_check": truth_check,
        # The safety pilot's recoveries of a departure, in FBWA (agent.sim.pilot.departed).
        "recoveries": [{"at_s": round(t, 1), "why": why} for t, why in aircraft.recoveries],
        "tic_avg": None if result is None else result.tic_avg,
        "suggestion": None
        if result is None
        else {
            "update": result.suggest_update,
            "steps": result.reasons,
            "checks": result.checks,
            "tic_jn": result.tic_jn,
            "tic_nn": result.tic_nn,
            "tic_nj": result.tic_nj,
        },
        "decision": last.get("decision"),
        "failure": last.get("failure"),
        "history": [
            {
                "plan": o["plan"],
                "decision": o.get("decision"),
                "model_id": o["result"].model_id if "result" in o else None,
                "sizing": None
                if o.get("sizing") is None
                else o["sizing"].model_dump(mode="json", exclude={"v", "kind", "plan"}),
            }
            for o in outcomes
        ],
        # Which α and β the last identification used: the vanes', or synthesised (--no-vanes).
        "air_angles": _air_angles(agent),
        "recorder": dict(agent.recorder.counters),
        "sensor_gaps": {d.name: d.health().gaps for d in agent.drivers},
        "worker_identifications": len(agent.identification.results),
        # What the aircraft told the operator besides results (a surface that did not follow
        # its command, a full queue, a withheld live view…).
        "notices": [m.text for m in ground.inbox if isinstance(m, messages.Notice)],
    }


def _air_angles(agent) -> str | None:
    """ "vanes" or "synthesised" as the last onboard identification had α and β (None: none
    identified by the aircraft method)."""
    for record in reversed(agent.identification.results):
        if record.result is not None and record.result.aircraft is not None:
            return record.result.aircraft.wind.air_angles
    return None


def format_report(report: dict) -> str:
    lines = [f"{report['aircraft']} · preset {report['preset']} · {report['runs']} run(s)"]
    for k, run in enumerate(report["history"]):
        if run.get("sizing"):
            sized = messages.Sizing(plan=preset(report["preset"]), **run["sizing"])
            lines += [f"run {k + 1}: {line}" for line in sizing.message_lines(sized)]
    for recovery in report.get("recoveries", []):
        lines.append(
            f"the safety pilot recovered a departure in FBWA {recovery['at_s']:.0f} s into the "
            f"flight ({recovery['why']}); the runs after it excite closed loop"
        )
    if report["failure"]:
        lines.append(f"identification failed: {report['failure']}")
        return "\n".join([*lines, *(f"notice: {text}" for text in report["notices"])])
    # ERA's EMAC where the method has it; the whole-aircraft method's Cramér–Rao σ of ωn else.
    era = any(row["emac"] is not None for row in report["modes"])
    key, heading, form = ("emac", "EMAC %", ".0f") if era else ("sigma_pct", "σ(ωn) %", ".2f")
    warning = truth_warning(report.get("truth_check"))
    if warning:
        lines.append(warning)
    lines.append(f"{'mode':<14}{'identified':>22}{'JSBSim':>22}{'error':>8}{heading:>9}")
    for row in report["modes"]:
        lam = complex(*row["eigenvalue"])
        ref = "" if row["truth"] is None else f"{complex(*row['truth']):.3f}"
        err = "" if row["error"] is None else f"{100 * row['error']:.1f}%"
        value = "" if row.get(key) is None else f"{row[key]:{form}}"
        lines.append(f"{row['name'] or '-':<14}{lam:>22.3f}{ref:>22}{err:>8}{value:>9}")
    s = report["suggestion"]
    if report.get("air_angles") == "synthesised":
        lines.append("alpha, beta: synthesised from the INS and an estimated wind (no vanes)")
    lines.append(f"TIC_avg {report['tic_avg']:.3f}; update suggested: {s['update']}")
    lines += [f"  {step}" for step in s["steps"]]
    lines.append(f"operator: {report['decision']}")
    lines += [f"notice: {text}" for text in report["notices"]]
    return "\n".join(lines)


def truth_warning(verdict: dict | None) -> str | None:
    """What the report says where the truth failed its check (`_truth`); None where it passed."""
    if not verdict or verdict["validated"]:
        return None
    if "error" in verdict:
        why = verdict["error"]
        return f"no truth to judge the modes by: JSBSim's linear model was not built ({why})"
    failing = ", ".join(
        f"{test} {tic:.3f}" for test, tic in verdict["worst_tic"].items() if tic > verdict["bound"]
    )
    return (
        f"JSBSim's linear model here fails its check against JSBSim (worst TIC: {failing}; "
        f"bound {verdict['bound']}): the errors below are against a truth that does not "
        "reproduce the aircraft"
    )


def modes_within(report: dict, tolerance: float) -> bool:
    errors = [r["error"] for r in report["modes"] if r["error"] is not None]
    return bool(errors) and all(e <= tolerance for e in errors) and not np.isnan(errors).any()
