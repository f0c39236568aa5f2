"""The aircraft's end of the link for the console tests: a real LinkSession on the real
digi-xbee over an emulated XBee pair, scripted to answer commands as the agent does (an ack, or
a refusal with its reason), to send status, and to send results when told."""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from agent.clock import LoopClock
from agent.config import Link
from agent.ground.config import GroundConfig
from agent.ident.convert import discretize
from agent.ident.document import ModeDocument
from agent.ident.frf import model_response
from agent.ident.reference import LATERAL
from agent.link import messages
from agent.link.codec import AIRCRAFT, LinkCodec
from agent.link.session import LinkSession
from agent.link.store import CounterStore
from agent.sim.radio import EmulatedXBee, RfChannel
from drivers.xbee.driver import XBeeRadio

# A fixed key drawn at random (a patterned one, as bytes(range(32)) was, is refused).
KEY = bytes.fromhex("5f1e9c27d4a0b38e61c7f2094ad35be8c06f1a729e4d83b5f02c6e917ad4b358")
AIR = bytes.fromhex("0013A20040000001")
GROUND = bytes.fromhex("0013A20040000002")


def mode(name, real, imag=0.0, emac=95.0, std=None) -> ModeDocument:
    w = abs(complex(real, imag))
    return ModeDocument(
        name=name,
        eigenvalue=(real, imag),
        frequency_rad_s=w,
        damping=-real / w,
        time_constant_s=None if imag else -1 / real,
        msv=0.4,
        mci=0.8,
        moi=0.7,
        emac=emac,
        mpc=60.0,
        cmi=76.0,
        eigenvalue_std=None if std is None else std,
        frequency_std_rad_s=None if std is None else 0.1,
        damping_std=None if std is None else 0.03,
    )


def result(model_id: str, shift: float = 0.0, update: bool = True) -> messages.Result:
    modes = [
        mode("Dutch roll", -0.8 + shift, 3.1 + shift, std=(0.12, 0.25)),
        mode("roll", -9.5 + shift),
        mode("spiral", 0.004, emac=30.0),
    ]
    # The thesis's A.2 lateral model at 25 Hz: a real response for the frequency-response view.
    A, B = discretize(LATERAL.A, LATERAL.B, 0.04)
    return messages.Result(
        model_id=model_id,
        axes="lateral",
        dt=0.04,
        inputs=["aileron", "rudder"],
        outputs=["beta", "p", "r", "phi"],
        modes=modes,
        tic=[0.02, 0.03, 0.02, 0.04],
        tic_avg=0.0275,
        stable=False,
        suggest_update=update,
        reasons=[
            "1 stability: slowly divergent (doubles in 173 s)",
            "2 quality: named modes EMAC ≥ 50 %",
            "3 TIC_jj 0.028 < 0.3",
            "4–7 no nominal model yet",
        ],
        A=A.tolist(),
        B=B.tolist(),
        C=np.eye(4).tolist(),
        D=np.zeros((4, 2)).tolist(),
    )


def frequency_response(request: messages.FrfRequest) -> messages.FrfReport:
    """What the aircraft would measure for `result(model_id)`'s pair: its model's response at
    30 frequencies with a little error, the coherence low below 0.2 Hz (turbulence there)."""
    model = result(request.model_id)
    i, j = model.inputs.index(request.input), model.outputs.index(request.output)
    f = np.logspace(-1, np.log10(5.0), 30)
    h = model_response(model.A, model.B, model.C, model.D, model.dt, f)[:, j, i]
    h *= 1 + 0.05 * np.sin(7 * f)
    return messages.FrfReport(
        model_id=request.model_id,
        input=request.input,
        output=request.output,
        averaging="welch",
        segments=7,
        freq_hz=f.tolist(),
        mag_db=(20 * np.log10(np.abs(h))).tolist(),
        phase_deg=np.degrees(np.angle(h)).tolist(),
        coherence=np.where(f < 0.2, 0.4, 0.95).tolist(),
    )


def sized(plan) -> messages.Sizing:
    """The agent's own sizing of `plan` with no model yet (the build-up), as it sends it."""
    from agent import sizing
    from agent.config import Excitation
    from agent.excitation.plan import render
    from agent.runtime.sizer import sizing_message

    ex = Excitation()
    done = sizing.size(plan, render(plan, ex.rate_hz), None, ex.sizing, ex.surfaces, ex.envelope)
    return sizing_message(done, ex.surfaces)


def proposal(model_id: str, count: int) -> messages.Gains:
    """A gain proposal as the agent sends it (agent/runtime/gains.py): the roll axis a step
    toward its design, the pitch axis refused."""
    rows = [
        messages.GainRow(name="RLL2SRV_TCONST", current=0.5, designed=0.6, proposed=0.6),
        messages.GainRow(name="RLL_RATE_FF", current=0.345, designed=1.2, proposed=0.69),
        messages.GainRow(name="RLL_RATE_P", current=0.08, designed=0.12, proposed=0.12),
        messages.GainRow(name="SCALING_SPEED", current=15.0, designed=22.0, proposed=22.0),
    ]
    loops = [
        messages.LoopPrediction(axis="roll", gains="current", stable=False),
        messages.LoopPrediction(
            axis="roll",
            gains="proposed",
            crossover_rad_s=3.1,
            phase_margin_deg=58.0,
            gain_margin_db=None,
            delay_margin_s=0.33,
            rejection_rad_s=1.4,
            rise_s=0.9,
            overshoot_pct=1.2,
            rise_down_s=1.1,  # an aileron with more travel one way
            overshoot_down_pct=0.4,
            sound=True,
        ),
    ]
    return messages.Gains(
        proposal=f"{model_id}-g{count}",
        model_id=model_id,
        rows=rows,
        loops=loops,
        share={"roll": 0.55},
        refused=["pitch: the model has no elevator input"],
    )


@dataclass
class ScriptedAircraft:
    session: LinkSession | None = None
    inbox: list = field(default_factory=list)
    refuse: dict[str, str] = field(default_factory=dict)  # message kind → reason
    nominal: list[str] = field(default_factory=list)  # the nominal history, latest last
    excitation: str = "idle"
    airspeed: float = 22.0
    recorder: dict[str, float] = field(default_factory=lambda: {"frames": 1200.0})
    proposals: int = 0  # gain proposals sent
    settings: messages.IdentSettings | None = field(default_factory=messages.IdentSettings)
    """The settings in effect its status reports (None: an older agent, which does not)."""

    def on_message(self, message, seq) -> None:
        self.inbox.append(message)
        if seq is None:
            return
        reason = self.refuse.get(message.kind, "")
        if not reason:
            if isinstance(message, messages.Arm):
                self.excitation = "armed"
            elif isinstance(message, messages.Abort):
                self.excitation = "idle"
            elif isinstance(message, messages.IdentSettings) and self.settings is not None:
                self.settings = message
            elif isinstance(message, messages.Decision) and message.accept:
                self.nominal.append(message.model_id)
            elif isinstance(message, messages.Revert):
                if len(self.nominal) < 2:
                    reason = "no previous lateral nominal model to revert to"
                else:
                    self.nominal.append(self.nominal[-2])
        self.session.send_reliable(messages.Ack(ref=seq, ok=not reason, reason=reason))
        if isinstance(message, messages.FrfRequest) and not reason:
            self.session.send_reliable(frequency_response(message))
        if isinstance(message, messages.SizeRequest) and not reason:
            self.session.send_reliable(sized(message.plan))
        if isinstance(message, messages.GainsRequest) and not reason:
            self.proposals += 1
            model = message.model_id or (self.nominal[-1] if self.nominal else "lat-1")
            self.session.send_reliable(proposal(model, self.proposals))
        if isinstance(message, messages.GainsApply) and not reason:
            self.session.send_reliable(
                messages.GainsReport(
                    action="applied",
                    proposal=message.proposal,
                    values={"RLL_RATE_FF": 0.69, "RLL_RATE_P": 0.12},
                    reason="replacing RLL_RATE_FF 0.345, RLL_RATE_P 0.08",
                )
            )
        if isinstance(message, messages.GainsRevert) and not reason:
            self.session.send_reliable(
                messages.GainsReport(
                    action="reverted",
                    values={"RLL_RATE_FF": 0.345, "RLL_RATE_P": 0.08},
                    reason="operator's command",
                )
            )

    def status(self, t: float) -> messages.Status:
        return messages.Status(
            time=t,
            flight_mode="MANUAL",
            airspeed=self.airspeed,
            altitude=305.0,
            alpha=3.0,
            beta=-0.2,
            roll=0.02,
            pitch=0.05,
            yaw=1.2,
            excitation=self.excitation,
            loop_lag_ms=0.9,
            nominal={"lateral": self.nominal[-1]} if self.nominal else {},
            settings=self.settings,
            recorder=dict(self.recorder),
            sensors={
                "vn200": {
                    "state": "open",
                    "rate_hz": 100.0,
                    "gaps": 0.0,
                    "crc_errors": 0.0,
                    "age_s": 0.01,
                },
                "airdata": {
                    "state": "waiting",
                    "rate_hz": 0.0,
                    "gaps": 2.0,
                    "crc_errors": 1.0,
                    "age_s": 4.2,
                },
            },
        )


@dataclass
class Rig:
    channel: RfChannel
    aircraft: ScriptedAircraft
    config: GroundConfig
    base: Path
    status_task: asyncio.Task | None = None


@contextlib.asynccontextmanager
async def rig(tmp_path: Path, status_every: float = 0.2):
    clock = LoopClock()
    channel = RfChannel()
    air_module = EmulatedXBee("air", AIR, tmp_path, channel, clock)
    ground_module = EmulatedXBee("ground", GROUND, tmp_path, channel, clock)
    air_module.join(ground_module)
    ground_module.join(air_module)
    tasks = [
        asyncio.create_task(m.run(), name=f"xbee-{m.name}") for m in (air_module, ground_module)
    ]
    await asyncio.sleep(0.05)
    (tmp_path / "link.key").write_text(KEY.hex())
    (tmp_path / "link.key").chmod(0o600)
    aircraft = ScriptedAircraft()
    codec = LinkCodec(KEY, AIRCRAFT, {GROUND}, counter=CounterStore(tmp_path / "air.counter"))
    holder: list[LinkSession] = []
    radio = XBeeRadio(
        str(air_module.path), 115200, clock, lambda s, p, t: holder[0].receive(s, p, t)
    )
    await radio.open()
    codec.max_payload = radio.max_payload
    codec.address = radio.address
    aircraft.session = LinkSession(codec, radio, GROUND, clock, aircraft.on_message)
    holder.append(aircraft.session)
    tasks.append(asyncio.create_task(aircraft.session.run(), name="air-session"))

    async def status() -> None:
        while True:
            aircraft.session.send_status(aircraft.status(clock.now()))
            await asyncio.sleep(status_every)

    status_task = asyncio.create_task(status(), name="air-status")
    tasks.append(status_task)
    config = GroundConfig(
        link=Link(
            port=str(ground_module.path),
            peer=AIR.hex(),
            key_file="link.key",
            counter_file="ground.counter",
            seen_file="ground.seen",
        ),
        log_dir="ground-logs",
    )
    try:
        yield Rig(channel, aircraft, config, tmp_path, status_task)
    finally:
        for task in tasks[2:]:
            task.cancel()
        await asyncio.gather(*tasks[2:], return_exceptions=True)
        await radio.close()
        for task in tasks[:2]:
            task.cancel()
        await asyncio.gather(*tasks[:2], return_exceptions=True)
