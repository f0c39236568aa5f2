"""Messages between two ends of the link: real digi-xbee on each side, emulated XBee modules
and an RF channel between them.

Bad input tried: 20 % of over-the-air attempts lost, a 12 s outage, a payload larger than the
radio takes, a well-checksummed frame that kills digi-xbee's reader thread, the ground's radio
unplugged for 3 s, and the aircraft's session restarted while the ground's numbering goes on.
"""

from __future__ import annotations

import asyncio
import json

import numpy as np
import pytest

from agent.clock import LoopClock
from agent.excitation.plan import preset
from agent.ident.document import ModeDocument
from agent.link import messages
from agent.link.session import RETRY_MAX_S
from agent.sim.radio import EmulatedXBee, RfChannel
from tests.link.pair import link_pair, wait_for

pytestmark = pytest.mark.usefixtures("no_leaked_tasks")


def full_result(model_id: str = "m1") -> messages.Result:
    """A full-model result: eight states, four inputs, eight outputs."""
    rng = np.random.default_rng(0)
    mode = ModeDocument(
        name="Dutch roll",
        eigenvalue=(-0.6, 2.2),
        frequency_rad_s=2.28,
        damping=0.26,
        time_constant_s=None,
        msv=0.3,
        mci=0.8,
        moi=0.7,
        emac=0.95,
        mpc=0.3,
        cmi=0.7,
        eigenvalue_std=(0.021, 0.048),
        frequency_std_rad_s=0.05,
        damping_std=0.012,
    )
    m = lambda r, c: rng.normal(size=(r, c)).tolist()  # noqa: E731
    return messages.Result(
        model_id=model_id,
        axes="full",
        dt=0.04,
        inputs=["throttle", "elevator", "aileron", "rudder"],
        outputs=["Vt", "alpha", "q", "theta", "beta", "p", "r", "phi"],
        modes=[mode] * 5,
        tic=[0.1] * 8,
        tic_avg=0.1,
        stable=True,
        suggest_update=True,
        reasons=["TIC 0.10 better than nominal 0.14"],
        A=m(8, 8),
        B=m(8, 4),
        C=m(8, 8),
        D=m(8, 4),
    )


@pytest.mark.parametrize("escaped", [False, True], ids=["AP=1", "AP=2"])
async def test_messages_round_trip_in_both_api_modes(tmp_path, escaped):
    async with link_pair(tmp_path, escaped=escaped) as pair:
        assert pair.air.radio.max_payload == 256  # NP read at start-up
        pair.ground.session.send_reliable(messages.Arm(plan=preset("full")))
        pair.ground.session.send_reliable(messages.Abort(reason="test"))
        result = full_result()
        pair.air.session.send_reliable(result)
        pair.air.session.send_status(messages.Status(time=1.0, airspeed=22.0, excitation="idle"))
        assert await wait_for(lambda: len(pair.air.inbox) == 2 and len(pair.ground.inbox) == 2)
    assert pair.air.inbox[0] == messages.Arm(plan=preset("full"))
    assert pair.air.inbox[1].reason == "test"
    got = {type(m): m for m in pair.ground.inbox}
    assert got[messages.Result] == result  # 8 × 8 float matrices survive exactly
    assert got[messages.Status].airspeed == 22.0
    assert pair.ground.codec.counters["messages"] >= 2


async def test_twenty_percent_loss_delivers_everything_once_in_order(tmp_path):
    channel = RfChannel(loss=0.2, retries=0, seed=4)  # every attempt: 20 % lost, no MAC retry
    async with link_pair(tmp_path, channel=channel) as pair:
        for k in range(30):
            pair.ground.session.send_reliable(messages.Abort(reason=f"up {k}"))
            pair.air.session.send_reliable(messages.Notice(text=f"down {k}"))
        done = await wait_for(lambda: len(pair.air.inbox) == 30 and len(pair.ground.inbox) == 30)
        await asyncio.sleep(0.5)  # nothing more may arrive (no duplicates)
        lost = pair.modules[0].counters["lost"] + pair.modules[1].counters["lost"]
    assert done
    assert [m.reason for m in pair.air.inbox] == [f"up {k}" for k in range(30)]
    assert [m.text for m in pair.ground.inbox] == [f"down {k}" for k in range(30)]
    assert lost > 5  # the channel did lose frames
    assert pair.air.session.counters["retransmissions"] > 0


async def test_the_live_view_goes_after_every_reliable_message(tmp_path):
    """Over the slow 10 kb/s air (the result takes 3.5 s of it), a result, an ack and live
    views handed over together: the live view waits until both are delivered and acknowledged,
    and only the newest goes (best effort, latest wins). No loss: a lost live view is not
    resent, by design."""
    channel = RfChannel(data_rate_bps=10_000.0, loss=0.0, retries=0, seed=5)
    async with link_pair(tmp_path, channel=channel) as pair:
        session = pair.air.session
        session.send_reliable(full_result("lat-1"))
        session.send_reliable(messages.Ack(ref=1, ok=True))
        for k in range(3):
            session.send_live(messages.Live(time=float(k), dt=0.1, tenths={"p": [k] * 10}))
        done = await wait_for(lambda: any(isinstance(m, messages.Live) for m in pair.ground.inbox))
    assert done
    kinds = [m.kind for m in pair.ground.inbox]
    assert kinds == ["result", "ack", "live"]
    assert pair.ground.inbox[-1].time == 2.0  # the newest


async def test_the_air_share_is_the_time_spent_sending(tmp_path):
    """On the long-range 10 kb/s air, two full results keep the aircraft's radio busy for at
    least their air time (about 7 s of the 10 s window); the live view's gate reads that
    share (agent/runtime/live.py)."""
    from agent.link.session import AIR_WINDOW_S
    from agent.sim.radio import AIR_OVERHEAD

    channel = RfChannel(data_rate_bps=10_000.0, loss=0.0, retries=0, seed=6)
    async with link_pair(tmp_path, channel=channel) as pair:
        session = pair.air.session
        idle = session.air_share()
        frames = pair.air.codec.encode(messages.to_dict(full_result()))
        for k in range(2):
            session.send_reliable(full_result(f"m{k}"))
        assert await wait_for(lambda: len(pair.ground.inbox) >= 2)
        busy = session.air_share()
    air_time = 2 * sum((len(f) + AIR_OVERHEAD) * 8 / 10_000.0 for f in frames)
    assert idle < busy / 5  # heartbeats only
    assert air_time / AIR_WINDOW_S <= busy < 1.0
    assert busy > 0.5  # the live view would be withheld here


async def test_results_queued_during_a_12_s_outage_are_delivered_after_it(tmp_path):
    async with link_pair(tmp_path, deadline_s=3.0) as pair:
        await asyncio.sleep(0.3)
        assert pair.ground.session.link_up
        pair.channel.outage = True
        for k in range(3):
            pair.air.session.send_reliable(full_result(f"during-{k}"))
        # Three times the retries' longest interval: the backoff reaches its cap and the
        # messages outlive retries at it.
        await asyncio.sleep(3 * RETRY_MAX_S)
        assert not pair.ground.session.link_up  # the ground saw the link go
        assert not pair.ground.inbox
        pair.channel.outage = False
        assert await wait_for(lambda: len(pair.ground.inbox) == 3)
        assert pair.ground.session.link_up
    assert [m.model_id for m in pair.ground.inbox] == [f"during-{k}" for k in range(3)]


async def test_a_payload_larger_than_the_radio_takes_is_refused_not_sent(tmp_path):
    async with link_pair(tmp_path) as pair:
        result = await pair.air.radio.send(pair.modules[1].address, bytes(300))
    assert result.reason == "payload too large"


# A frame digi-xbee's factory cannot build: 0x28 (Send Data Request) whose path length points
# past its end. Found by fuzzing (fuzz/, target digi-xbee): build_frame raises IndexError, and
# digi-xbee's reader thread ends and closes the port on it.
READER_KILLER = bytes([0x28]) + b"\xd6" * 8


async def test_a_frame_that_ends_digi_xbees_reader_costs_a_reopen_not_the_link(tmp_path):
    """Bad input tried: a well-checksummed frame from the ground's own module that makes
    digi-xbee's frame factory raise (its reader thread then dies and closes the port)."""
    from drivers.xbee import codec as api

    async with link_pair(tmp_path) as pair:
        radio = pair.ground.radio
        pair.modules[1].emit(api.ApiFrame(READER_KILLER))
        assert await wait_for(lambda: not radio.healthy()), "digi-xbee survived the frame"
        t0 = asyncio.get_running_loop().time()
        assert await wait_for(lambda: radio.counters["reopened"] == 1), radio.counters
        took = asyncio.get_running_loop().time() - t0
        pair.air.session.send_reliable(messages.Notice(text="after the reopen"))
        assert await wait_for(lambda: pair.ground.inbox)
    assert pair.ground.inbox[-1].text == "after the reopen"
    assert radio.counters["port_lost"] == 1
    assert took < 30  # digi-xbee's open retries its AT reads on a 4 s timeout: 1-9 s here


async def test_an_unplugged_radio_is_reopened_and_the_message_sent_meanwhile_arrives(tmp_path):
    """Bad input tried: the ground's USB radio pulled for 3 s while the aircraft sends."""
    async with link_pair(tmp_path) as pair:
        radio, module = pair.ground.radio, pair.modules[1]
        module.unplug()
        pair.air.session.send_reliable(messages.Notice(text="sent while unplugged"))
        await asyncio.sleep(3.0)
        assert not pair.ground.inbox
        assert radio.counters["reopen_failures"] >= 1  # it kept trying, and said so
        module.plug()
        assert await wait_for(lambda: radio.counters["reopened"] == 1)
        assert await wait_for(lambda: pair.ground.inbox)
    assert [m.text for m in pair.ground.inbox] == ["sent while unplugged"]
    assert radio.counters["port_lost"] == 1


async def test_a_restarted_receiver_takes_the_senders_next_message(tmp_path):
    """Bad input tried: the aircraft's session replaced by a new one (the agent restarted
    after a crash) while the ground's numbering goes on: it used to wait forever for message 1."""
    from agent.link.codec import AIRCRAFT, LinkCodec
    from agent.link.session import LinkSession
    from agent.link.store import CounterStore
    from tests.link.pair import GROUND_ADDR, KEY

    async with link_pair(tmp_path) as pair:
        pair.ground.session.send_reliable(messages.Notice(text="one"))
        assert await wait_for(lambda: len(pair.air.inbox) == 1)
        # The aircraft restarts: a new codec (its counter and replay state from disk would do
        # the same) and a new session on the same radio.
        old = pair.tasks[2]
        old.cancel()
        await asyncio.gather(old, return_exceptions=True)
        inbox: list = []
        codec = LinkCodec(KEY, AIRCRAFT, {GROUND_ADDR}, counter=CounterStore(tmp_path / "a2"))
        codec.max_payload = pair.air.radio.max_payload
        codec.address = pair.air.radio.address
        session = LinkSession(
            codec,
            pair.air.radio,
            GROUND_ADDR,
            LoopClock(),  # the pair's clock: the event loop's
            lambda m, _seq: inbox.append(m),
        )
        pair.air.session = session
        pair.air.on_frame = session.receive
        task = asyncio.create_task(session.run(), name="session-air-restarted")
        try:
            pair.ground.session.send_reliable(messages.Notice(text="two"))
            pair.ground.session.send_reliable(messages.Notice(text="three"))
            assert await wait_for(lambda: inbox and inbox[-1].text == "three"), inbox
        finally:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
    # "one" again only if its acknowledgement had not reached the ground before the restart.
    assert [m.text for m in inbox] in (["two", "three"], ["one", "two", "three"])
    assert session.counters["peer_epochs"] == 1


async def test_an_agent_whose_radio_does_not_answer_at_start_records_and_links_later(tmp_path):
    """Bad input tried: the aircraft's XBee unplugged when the agent starts (it used to stop
    the agent: `sysid agent` exited when the module did not answer at start-up, recording nothing).
    The agent flies without a link, counts and logs each failed open, and links up once the
    module is plugged in."""
    from agent.clock import LoopClock
    from agent.config import Autopilot, Config, Link, Recorder, Sensors
    from agent.link.codec import GROUND
    from agent.link.endpoint import build_endpoint
    from agent.runtime import Agent
    from tests.link.pair import AIR_ADDR, GROUND_ADDR, KEY

    clock, channel = LoopClock(), RfChannel()
    air = EmulatedXBee("air", AIR_ADDR, tmp_path, channel, clock)
    ground_module = EmulatedXBee("ground", GROUND_ADDR, tmp_path, channel, clock)
    air.join(ground_module)
    ground_module.join(air)
    modules = [asyncio.create_task(m.run(), name=f"xbee-{m.name}") for m in (air, ground_module)]
    await asyncio.sleep(0.05)
    air.unplug()
    (tmp_path / "link.key").write_text(KEY.hex())
    (tmp_path / "link.key").chmod(0o600)
    off = {"enabled": False}
    config = Config(
        recorder=Recorder(log_dir=str(tmp_path / "logs"), capacity_s=60.0),
        sensors=Sensors(vn200=off, airdata=off, surfaces=off),
        autopilot=Autopilot(url="udpout://127.0.0.1:9", connect_timeout_s=0.5),
        link=Link(
            port=str(air.path),
            peer=GROUND_ADDR.hex(),
            key_file="link.key",
            counter_file="air.counter",
            seen_file="air.seen",
        ),
    )
    agent = Agent(config, base=tmp_path, clock=clock)
    running = asyncio.create_task(agent.run(), name="agent")
    inbox: list = []
    ground_link = Link(
        port=str(ground_module.path),
        peer=AIR_ADDR.hex(),
        key_file="link.key",
        counter_file="ground.counter",
        seen_file="ground.seen",
    )
    radio, session = build_endpoint(
        ground_link, GROUND, tmp_path, clock, lambda m, _seq: inbox.append(m)
    )
    await radio.open()
    ground = [asyncio.create_task(session.run(), name="ground-session")]
    try:
        assert await wait_for(lambda: agent.radio is not None)
        assert await wait_for(lambda: agent.radio.counters["open_failures"] >= 2)
        frames = agent.recorder.ring.count
        await asyncio.sleep(0.5)
        assert not running.done()  # the agent flies on
        assert agent.recorder.ring.count > frames  # and records
        health = agent.health.record(wall_s=1.0, cpu_s=0.1)
        assert health["radio"]["open_failures"] >= 2  # the health log says why there is no link
        assert not session.link_up
        air.plug()
        assert await wait_for(lambda: session.link_up)  # the agent's frames arrive
        assert await wait_for(lambda: agent.session.link_up)  # and the ground's reach it
        assert agent.radio.counters["reopened"] == 0  # a first open, not a reopen
    finally:
        running.cancel()
        for task in ground:
            task.cancel()
        await asyncio.gather(running, *ground, return_exceptions=True)
        await radio.close()
        for task in modules:
            task.cancel()
        await asyncio.gather(*modules, return_exceptions=True)
    execution = next((tmp_path / "logs").glob("*_exec_*")).read_text()
    assert "cannot open the XBee" in execution or "did not answer" in execution


async def test_an_open_given_up_leaves_no_reader_on_the_port(tmp_path, monkeypatch):
    """Bad input tried: an open that outlasts its timeout (a busy machine: the module answers,
    late). The opening thread closes the device it opened itself, so no digi-xbee reader is
    left on the port beside the next attempt's (two readers split the frames between them;
    one left on a closed pty spins logging warnings), and closing the radio meanwhile waits
    for that open without holding the loop (it used to block in the executor's shutdown, and
    the emulated module, served by the same loop, could not answer)."""
    import threading

    import drivers.xbee.driver as xbee
    from agent.clock import LoopClock
    from tests.link.pair import AIR_ADDR

    clock = LoopClock()
    module = EmulatedXBee("air", AIR_ADDR, tmp_path, RfChannel(), clock)
    running = asyncio.create_task(module.run(), name="xbee-air")
    await asyncio.sleep(0.05)
    radio = xbee.XBeeRadio(str(module.path), 115200, clock, lambda *_: None)
    monkeypatch.setattr(xbee, "OPEN_TIMEOUT_S", 0.0)
    try:
        with pytest.raises(xbee.RadioError, match="did not answer"):
            await radio.open()
        ticks = [0]

        async def tick():
            while True:
                await asyncio.sleep(0)  # one turn of the loop
                ticks[0] += 1

        ticker = asyncio.create_task(tick(), name="ticker")
        await radio.close()  # returns once the abandoned open has finished
        ticker.cancel()
        await asyncio.gather(ticker, return_exceptions=True)
        assert ticks[0] > 0  # the loop ran while close waited for the open
        readers = [t for t in threading.enumerate() if type(t).__name__ == "PacketListener"]
        assert not [t for t in readers if t.is_alive()], readers
        assert not radio.is_open
    finally:
        running.cancel()
        await asyncio.gather(running, return_exceptions=True)


async def test_a_command_acted_on_is_refused_when_replayed_after_a_reboot(tmp_path):
    """Bad input tried: the ground's Revert recorded off the air and replayed to the aircraft
    right after it rebooted. The replay state is written (fsynced) before a command is acted
    on, so the restarted end refuses every recorded frame; it used to be saved about once a
    second, so a reboot within that second accepted the Revert again."""
    from agent.link.codec import AIRCRAFT, LinkCodec, key_fingerprint
    from agent.link.store import CounterStore, SeenStore
    from tests.link.pair import AIR_ADDR, GROUND_ADDR, KEY

    async with link_pair(tmp_path) as pair:
        heard: list[tuple[bytes, bytes]] = []
        deliver = pair.air.on_frame

        def record(source, payload, t):
            heard.append((source, payload))
            deliver(source, payload, t)

        pair.air.on_frame = record
        pair.ground.session.send_reliable(messages.Revert())
        assert await wait_for(lambda: any(isinstance(m, messages.Revert) for m in pair.air.inbox))
        # The reboot, at once: a new end from the files the old one left.
        rebooted = LinkCodec(
            KEY,
            AIRCRAFT,
            {GROUND_ADDR},
            counter=CounterStore(tmp_path / "r"),
            floors=SeenStore(tmp_path / "air.seen", key_fingerprint(KEY)).load(),
            address=AIR_ADDR,
        )
        replayed = [rebooted.decode(source, payload, 0.0) for source, payload in heard]
    assert heard
    assert replayed == [None] * len(heard)
    assert rebooted.counters["replayed"] + rebooted.counters["stale"] == len(heard)


def test_a_missing_or_damaged_replay_state_refuses_the_link(tmp_path):
    """Bad input tried: the seen file deleted while the counter file is there (the key was
    used: every recorded frame would be accepted again), and seen files of garbage, of
    Infinity, 1e400, 1.5, true or -7 as a counter, of a bad address, of a list, nested a
    hundred thousand deep, and a directory in its place (each used to stop the agent at
    start-up or be taken). build_endpoint refuses with the reason; the agent then
    flies and records without a link (the agent's `_build_link`)."""
    from agent.clock import LoopClock
    from agent.config import Link
    from agent.link.codec import AIRCRAFT, key_fingerprint
    from agent.link.endpoint import build_endpoint
    from tests.link.pair import GROUND_ADDR, KEY

    (tmp_path / "link.key").write_text(KEY.hex())

    (tmp_path / "link.key").chmod(0o600)
    cfg = Link(
        port=str(tmp_path / "nowhere"),
        peer=GROUND_ADDR.hex(),
        key_file="link.key",
        counter_file="air.counter",
        seen_file="air.seen",
    )
    build_endpoint(cfg, AIRCRAFT, tmp_path, LoopClock(), lambda *_: None)  # a first start
    # Its state starts saved, bound to the key.
    state = json.loads((tmp_path / "air.seen").read_text())
    assert state == {"key": key_fingerprint(KEY), "floors": {}}
    (tmp_path / "air.seen").unlink()
    with pytest.raises(ValueError, match=r"air\.seen is missing while .*air\.counter exists"):
        build_endpoint(cfg, AIRCRAFT, tmp_path, LoopClock(), lambda *_: None)
    peer = GROUND_ADDR.hex()
    for bad in (
        "{not json",
        f'{{"{peer}": Infinity}}',
        f'{{"{peer}": 1e400}}',
        f'{{"{peer}": 1.5}}',
        f'{{"{peer}": true}}',
        f'{{"{peer}": -7}}',
        '{"zz": 1}',
        "[1, 2]",
        json.dumps({"key": key_fingerprint(KEY), "floors": [1]}),
        "[" * 100_000,  # deep nesting: a RecursionError in json
    ):
        (tmp_path / "air.seen").write_text(bad)
        with pytest.raises(ValueError, match="the replay state is unreadable"):
            build_endpoint(cfg, AIRCRAFT, tmp_path, LoopClock(), lambda *_: None)
    (tmp_path / "air.seen").unlink()
    (tmp_path / "air.seen").mkdir()  # not a file at all
    with pytest.raises(ValueError, match="the replay state is unreadable"):
        build_endpoint(cfg, AIRCRAFT, tmp_path, LoopClock(), lambda *_: None)
    (tmp_path / "air.seen").rmdir()
    # The state of another key says nothing of this one's frames: it starts empty.
    (tmp_path / "air.seen").write_text(json.dumps({"key": "0" * 16, "floors": {peer: 99}}))
    _, session = build_endpoint(cfg, AIRCRAFT, tmp_path, LoopClock(), lambda *_: None)
    assert session.codec.floors() == {}  # nothing held: no floor for the peer
    assert not session.unsaved


async def test_a_queued_abort_survives_a_full_outbox(tmp_path):
    """Bad input tried: the aircraft's radio unplugged while the ground queues an Abort and
    then more reliable messages than the outbox holds (64). The outbox used to drop its
    oldest message, the Abort; it now drops the oldest that is not one."""
    from agent.link.session import OUTBOX

    async with link_pair(tmp_path) as pair:
        module = pair.modules[0]  # the aircraft's
        module.unplug()
        pair.ground.session.send_reliable(messages.Abort(reason="stop now"))
        for k in range(OUTBOX + 10):
            pair.ground.session.send_reliable(messages.Notice(text=f"n{k}"))
        assert pair.ground.session.counters["outbox_dropped"] > 0
        module.plug()
        assert await wait_for(lambda: any(isinstance(m, messages.Abort) for m in pair.air.inbox))
    assert [m.reason for m in pair.air.inbox if isinstance(m, messages.Abort)] == ["stop now"]


async def test_a_frame_of_an_older_session_reordered_behind_a_new_one_is_dropped(tmp_path):
    """Bad input tried: a reliable frame of the ground's previous session (its epoch) arriving
    after the restarted session's first frame. It used to switch the aircraft's session back
    to the old epoch and deliver the old session's message; the sender's frame counter never
    goes back across restarts, so the older epoch is recognised and dropped."""
    from agent.link.codec import GROUND, LinkCodec
    from agent.link.store import CounterStore
    from tests.link.pair import AIR_ADDR, GROUND_ADDR, KEY

    # The ground's codec under both of its sessions (a session restarted on the same codec):
    # consecutive frame counters, so the old frame is inside the replay window.
    ground = LinkCodec(
        KEY, GROUND, {AIR_ADDR}, counter=CounterStore(tmp_path / "gc"), address=GROUND_ADDR
    )

    def reliable(text: str, epoch: int) -> dict:
        return messages.to_dict(messages.Notice(text=text)) | {"e": epoch, "s": 1, "b": 1}

    (old,) = ground.encode(reliable("from the old session", 111))
    (new,) = ground.encode(reliable("from the new session", 222))
    async with link_pair(tmp_path) as pair:
        session, now = pair.air.session, LoopClock().now
        session.receive(GROUND_ADDR, new, now())
        session.receive(GROUND_ADDR, old, now())  # reordered behind it
        assert await wait_for(lambda: pair.air.inbox)
        await asyncio.sleep(0.2)  # anything else that would be delivered
    assert [m.text for m in pair.air.inbox] == ["from the new session"]
    assert session.counters["old_epoch"] == 1


async def test_a_radio_with_its_encryption_off_is_reported_or_refused(tmp_path):
    """Bad input tried: a module with AES encryption off (EE = 0, as shipped), whose settings
    any node on the network could change by Remote AT commands: the open reads EE, warns and
    counts it; with require_encryption the module is refused with the reason, and so is a
    module that does not answer EE at all (it used to be taken: fail open); with EE = 1 it
    opens quietly."""
    from agent.clock import LoopClock
    from drivers.xbee.driver import RadioError, XBeeRadio
    from tests.link.pair import AIR_ADDR

    clock = LoopClock()
    module = EmulatedXBee("air", AIR_ADDR, tmp_path, RfChannel(), clock)
    running = asyncio.create_task(module.run(), name="xbee-air")
    await asyncio.sleep(0.05)

    def radio(**options) -> XBeeRadio:
        return XBeeRadio(str(module.path), 115200, clock, lambda *_: None, **options)

    try:
        plain = radio()
        await plain.open()
        assert plain.encrypted is False
        assert plain.counters["unencrypted_opens"] == 1
        await plain.close()
        strict = radio(require_encryption=True)
        with pytest.raises(RadioError, match=r"encryption is off \(EE = 0\)"):
            await strict.open()
        await strict.close()
        module.encryption = None  # no EE command: whether it encrypts cannot be told
        silent = radio()
        await silent.open()
        assert silent.encrypted is None  # without require_encryption: opened
        await silent.close()
        strict = radio(require_encryption=True)
        with pytest.raises(RadioError, match=r"encryption cannot be read \(no answer to EE\)"):
            await strict.open()
        await strict.close()
        module.encryption = True
        secured = radio(require_encryption=True)
        await secured.open()
        assert secured.encrypted is True
        assert secured.counters["unencrypted_opens"] == 0
        await secured.close()
    finally:
        running.cancel()
        await asyncio.gather(running, return_exceptions=True)


@pytest.mark.parametrize(
    ("seen", "counter"),
    [
        (None, "65536"),  # the key was used; the seen file is gone
        ('{"0013a20040000002": Infinity}', "65536"),  # an OverflowError used to stop the agent
        ('{"0013a20040000002": 1e400}', "65536"),
        ("{}", "1e400"),
        ("{}", "-5"),  # a negative counter made every frame fail to pack
    ],
    ids=["seen-missing", "seen-infinity", "seen-1e400", "counter-1e400", "counter-negative"],
)
async def test_an_agent_whose_link_is_refused_flies_and_records(tmp_path, seen, counter):
    """Bad input tried: the agent started with its seen file deleted while its counter file
    is there, a seen file holding Infinity or 1e400 (JSON floats: int() of them raised
    OverflowError, which stopped the agent at start-up), a counter file of 1e400 or -5. The
    link is refused with the reason (counted), and the agent flies and records without it;
    nothing is written over the state it refused."""
    from agent.clock import LoopClock
    from agent.config import Autopilot, Config, Link, Recorder, Sensors
    from agent.runtime import Agent
    from tests import waiting
    from tests.link.pair import GROUND_ADDR, KEY

    (tmp_path / "link.key").write_text(KEY.hex())
    (tmp_path / "link.key").chmod(0o600)
    (tmp_path / "air.counter").write_text(counter)
    if seen is not None:
        (tmp_path / "air.seen").write_text(seen)
    off = {"enabled": False}
    config = Config(
        recorder=Recorder(log_dir=str(tmp_path / "logs"), capacity_s=60.0),
        sensors=Sensors(vn200=off, airdata=off, surfaces=off),
        autopilot=Autopilot(url="udpout://127.0.0.1:9", connect_timeout_s=0.5),
        link=Link(
            port=str(tmp_path / "nowhere"),
            peer=GROUND_ADDR.hex(),
            key_file="link.key",
            counter_file="air.counter",
            seen_file="air.seen",
        ),
    )
    agent = Agent(config, base=tmp_path, clock=LoopClock())
    running = asyncio.create_task(agent.run(), name="agent")
    try:
        await waiting.until(lambda: agent.counters["link_refused"] == 1, "the link's refusal")
        frames = agent.recorder.ring.count
        await waiting.until(lambda: agent.recorder.ring.count > frames, "recording")
        assert not running.done()  # the agent flies on
        assert agent.session is None
    finally:
        running.cancel()
        await asyncio.gather(running, return_exceptions=True)
    # Nothing written over the state it refused.
    assert (tmp_path / "air.counter").read_text() == counter
    if seen is None:
        assert not (tmp_path / "air.seen").exists()
    else:
        assert (tmp_path / "air.seen").read_text() == seen
    execution = next((tmp_path / "logs").glob("*_exec_*")).read_text()
    assert "link refused, flying without it" in execution
