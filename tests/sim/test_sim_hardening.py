"""Fault injection on the simulated aircraft, beyond tests/sim/test_sim_faults.py.

Every test flies the whole chain — JSBSim aircraft, emulated ArduPlane on MAVLink, sensor
ptys, emulated radios, the real agent with its worker, the scripted ground — breaks one thing
during a flight, and checks three things: what the agent did, that the aircraft was returned to
trim and released where a run was active, and that every byte logged before the fault is still
readable (`assert_logs_whole`).

Bad input tried:
- a hostile transmitter during an excitation, forging its source address: frames with forged
  tags (an abort among them), frames recorded off the air and replayed, malformed frames, and
  frames from its own address — while the channel loses half of all attempts;
- the identification worker process killed (SIGKILL) while it identifies;
- the log disk filling up during an excitation (a real tmpfs), then space coming back;
- `kill -9` of the agent process in the middle of an excitation, then a restart;
- the INS unplugged for half a second and the surface box's stream corrupted (5 % of frames)
  during an excitation;
- the autopilot rebooting in the middle of an excitation.
"""

from __future__ import annotations

import asyncio
import errno
import json
import os
import re
import signal
from collections import Counter
from pathlib import Path

import msgpack
import numpy as np
import pytest

from agent.excitation.plan import preset
from agent.link import messages
from agent.link.codec import GROUND, HEADER, TAG, VERSION
from agent.logs import read_log
from agent.sim.ardupilot import RELEASE_LOW
from agent.sim.flight import AIR, GROUND_ADDR, SimFlight, SimOptions, simulated
from agent.sim.radio import EmulatedXBee
from drivers.autopilot.driver import RELEASE_REPEATS
from tests.sim.test_sim_faults import answer, received, start_run, until

pytestmark = [pytest.mark.usefixtures("no_leaked_tasks"), pytest.mark.timeout(240)]
INTRUDER = bytes.fromhex("0013A200DEADBEEF")


def assert_logs_whole(directory: Path) -> dict[str, int]:
    """Every log file ends with a whole line, and every line parses: CSV logs through the
    reader `sysid identify` uses, JSON-lines logs one object per line. Returns rows per file."""
    sizes = {}
    for path in sorted((directory / "logs").iterdir()):
        raw = path.read_bytes()
        if not raw:
            continue
        assert raw.endswith(b"\n"), f"{path.name} ends inside a line"
        if path.suffix == ".csv":
            header, rows = read_log(path)
            assert rows.shape[1] == len(header), path.name
            if len(rows) > 1:
                assert np.all(np.diff(rows[:, 0]) > 0), f"{path.name}: time not increasing"
            sizes[path.name] = len(rows)
        else:
            lines = raw.decode().splitlines()
            for line in lines:
                json.loads(line)
            sizes[path.name] = len(lines)
    return sizes


def fill(path: Path) -> int:
    """Write to `path` until the file system refuses; the error number it refused with."""
    with open(path, "wb", buffering=0) as handle:
        while True:
            try:
                handle.write(b"\0" * 65536)
            except OSError as exc:
                return exc.errno


def trim_of(started: messages.ExcitationEvent) -> dict[int, int]:
    return {
        {"aileron": 1, "elevator": 2, "throttle": 3, "rudder": 4}[name]: int(us)
        for name, us in re.findall(r"(\w+) (\d+) µs", started.detail)
    }


def assert_trimmed_then_released(
    sim: SimFlight, started: messages.ExcitationEvent, since: float
) -> None:
    """After `since`: an override holding the trim of the excited channels, then the release of
    exactly those channels, and the ArduPlane holding no override any more."""
    ap, trim = sim.aircraft.autopilot, trim_of(started)
    after = [
        values
        for t, kind, values, accepted in (e for e in ap.wire if e[1] == "override")
        if t >= since and accepted
    ]
    assert trim in after, f"no trim override after the fault: {after[:5]}"
    rest = after[after.index(trim) + 1 :]
    release = {ch: RELEASE_LOW for ch in trim}
    assert rest[-RELEASE_REPEATS:] == [release] * RELEASE_REPEATS
    assert ap.overrides == {}


async def finished_or_aborted(sim: SimFlight, seen: int):
    def ended():
        return received(sim, messages.ExcitationEvent, seen, event="finished") or received(
            sim, messages.ExcitationEvent, seen, event="aborted"
        )

    return (await until(ended, "the end of the excitation"))[0]


# -- the radio: a hostile transmitter and half the frames lost ------------------------------


async def test_a_hostile_transmitter_and_half_the_frames_lost_change_nothing(tmp_path):
    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:
        codec = sim.agent.session.codec
        # Frames sent before the agent's radio was open (it opens beside the drivers) reached
        # its module but never the agent: replayed within the 64-frame window they are first
        # receipts of authentic frames, rightly accepted. Only frames the agent has had are
        # replayed: those heard from here on, with the link up both ways.
        early = {payload for _, _, payload in sim.channel.heard}
        intruder = EmulatedXBee("intruder", INTRUDER, tmp_path / "ports", sim.channel, sim.clock)
        intruder.join(sim.air_module)
        sim.channel.loss = 0.5  # every over-the-air attempt, both ways, the intruder's too
        seen = await start_run(sim, "under-attack")
        started = received(sim, messages.ExcitationEvent, seen, event="started")[0]
        dropped_before = (
            sum(codec.counters.values()) - codec.counters["frames"] - codec.counters["messages"]
        )
        uplink = [
            p for s, d, p in sim.channel.heard if s == GROUND_ADDR and d == AIR and p not in early
        ]
        assert uplink, "the eavesdropper heard no uplink frame to replay"
        rng = np.random.default_rng(7)
        body = msgpack.packb(messages.to_dict(messages.Abort(reason="forged")))
        sent = 0
        for k in range(60):  # 6 s of attack during the excitation, one frame per 100 ms
            kind = k % 4
            if kind == 0:  # a forged abort: right header, made-up tag
                header = HEADER.pack(VERSION, GROUND, 2**40 + k, 7, 0, 1)
                frame, source = header + body + rng.bytes(TAG), GROUND_ADDR
            elif kind == 1:  # a frame recorded off the air, replayed
                frame, source = uplink[k % len(uplink)], GROUND_ADDR
            elif kind == 2:  # malformed: too short, another version, garbage
                garbage = rng.bytes(int(rng.integers(1, 200)))
                frame = [b"\x01\x00", b"\x02" + rng.bytes(40), garbage][k % 3]
                source = GROUND_ADDR
            else:  # from its own address
                frame, source = rng.bytes(60), INTRUDER
            await intruder.transmit_as(source, AIR, frame)
            sent += 1
            await asyncio.sleep(0.1)
        end = await finished_or_aborted(sim, seen)
        assert end.event == "finished", end.detail  # the forged abort did nothing
        result = await answer(sim, seen)
        assert isinstance(result, messages.Result), result
        delivered = intruder.counters["delivered"]
        dropped = (
            sum(codec.counters.values()) - codec.counters["frames"] - codec.counters["messages"]
        )
        counters = Counter(codec.counters)
        released = sim.clock.now()
        sim.aircraft.pilot.set_switch(False)
        await asyncio.sleep(0.5)
        ap = sim.aircraft.autopilot
        overrides = ap.overrides
    # Half the attempts lost, MAC retries bring most through: all of them on about one run in
    # fifty (each frame four tries, lost on 1/16: (15/16)^60 = 2 %), so no share is asserted.
    tried = sent - intruder.counters["too_large"]  # garbage over the payload limit: refused
    assert delivered + intruder.counters["lost"] == tried
    assert delivered > tried // 2
    # Every hostile frame that arrived was dropped and counted, none reached the agent.
    assert dropped - dropped_before == delivered, counters
    assert counters["bad_tag"] >= 1
    assert counters["replayed"] + counters["stale"] >= 1
    assert counters["wrong_source"] >= 1
    assert counters["malformed"] >= 1
    assert overrides == {}, f"overrides held after the run: {overrides} ({released})"
    assert_trimmed_then_released(sim, started, started.time)  # the run ended as it should
    assert_logs_whole(tmp_path)


# -- the worker process killed --------------------------------------------------------------


async def test_the_worker_killed_while_identifying_gives_a_failure_and_a_new_worker(tmp_path):
    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:
        agent = sim.agent
        await until(lambda: agent.identification.ready, "the worker warmed up")
        pid = agent.identification.worker_pid
        # Stopped before the window reaches it, killed once the window is in it: killed while
        # identifying for certain, however slow the machine (a worker killed after its answer
        # came back has cost nothing, and that is not what this test is about).
        os.kill(pid, signal.SIGSTOP)
        seen = await start_run(sim, "killed")

        def identifying() -> bool:
            stage = agent.identification.stage(sim.clock.now())
            return stage is not None and stage[0] == "identifying"

        await until(identifying, "the window in the worker")
        os.kill(pid, signal.SIGKILL)
        failure = await answer(sim, seen)
        assert isinstance(failure, messages.Failure), failure
        assert "worker process died" in failure.reason
        assert agent.counters["worker_restarts"] == 1
        sim.aircraft.pilot.set_switch(False)
        await asyncio.sleep(0.5)
        seen = await start_run(sim, "after")  # the agent flies on with a new worker
        result = await answer(sim, seen)
        assert isinstance(result, messages.Result), result
        assert agent.identification.worker_pid not in (None, pid)
    sizes = assert_logs_whole(tmp_path)
    results = next(n for n in sizes if "_results_" in n)
    lines = (tmp_path / "logs" / results).read_text().splitlines()
    assert "worker process died" in json.loads(lines[0])["failure"]
    assert "result" in json.loads(lines[1])


# -- the log disk full ----------------------------------------------------------------------


async def test_a_full_log_disk_is_reported_and_the_flight_and_identification_go_on(
    tmp_path, small_disk_at
):
    small_disk_at(tmp_path / "logs", "16m")
    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:
        agent = sim.agent
        await asyncio.sleep(1.0)
        before = assert_logs_whole(tmp_path)  # what was logged before the fault
        seen = await start_run(sim, "disk-full")
        filler = tmp_path / "logs" / "filler"
        assert fill(filler) == errno.ENOSPC  # from the kernel

        def notices(text: str) -> list:
            return [m for m in received(sim, messages.Notice, seen) if text in m.text]

        notice = await until(lambda: notices("logs not written"), "the disk notice")
        assert "No space left on device" in notice[0].text
        end = await finished_or_aborted(sim, seen)
        assert end.event == "finished", end.detail  # a full disk is no reason to abort
        result = await answer(sim, seen)  # identified from memory
        assert isinstance(result, messages.Result), result
        lost = agent.writer.lost_lines
        assert lost > 0
        filler.unlink()  # space again
        await until(lambda: notices("logs written again"), "writing resumed")
        await asyncio.sleep(1.5)
        sim.aircraft.pilot.set_switch(False)
    after = assert_logs_whole(tmp_path)  # every line whole, before and after the fault
    for name, rows in before.items():
        assert after[name] >= rows
    _, rows = read_log(next((tmp_path / "logs").glob("*_flight_*")))
    gaps = np.diff(rows[:, 0])
    assert gaps.max() > 1.0  # the lines the disk refused are missing, not invented
    assert np.isclose(np.median(gaps), 0.01)


# -- kill -9 of the agent -------------------------------------------------------------------


def _dead(pid: int) -> bool:
    """Gone, or a zombie waiting for init to reap it."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True
    return stat[stat.rindex(")") + 2] == "Z"


async def test_kill_9_mid_run_lets_the_pilot_back_and_loses_no_logged_byte(tmp_path):
    async with simulated(
        SimOptions(preset="lateral", directory=tmp_path), agent_process=True
    ) as sim:
        ap, agent = sim.aircraft.autopilot, sim.agent
        await start_run(sim, "kill-9")
        await asyncio.sleep(1.5)  # inside the aileron doublet: overrides held
        assert ap.overrides
        children = Path(f"/proc/{agent.pid}/task/{agent.pid}/children").read_text().split()
        worker = next(
            int(c) for c in children if b"spawn_main" in Path(f"/proc/{c}/cmdline").read_bytes()
        )
        killed = sim.clock.now()
        agent.kill(signal.SIGKILL)
        # Nothing of ours can act now: ArduPilot's RC_OVERRIDE_TIME hands every channel back
        # to the pilot.
        timeout = ap.params.rc_override_time_s
        await until(lambda: not ap.overrides, "the overrides lapsing")
        lapsed = sim.clock.now() - killed
        # The worker died with the agent (PR_SET_PDEATHSIG), not left running orphaned.
        await until(lambda: _dead(worker), "the worker to die")
        rc, pilot = ap.rc_inputs(sim.clock.now()), sim.aircraft.pilot(sim.clock.now())
        sim.aircraft.pilot.set_switch(False)
        logged = assert_logs_whole(tmp_path)  # read while the agent is dead
        # A restart: the same config, on the same directory.
        mark = len(sim.ground.inbox)
        agent.start()
        await until(lambda: received(sim, messages.Status, mark), "the restarted agent")
        await until(lambda: sim.ground.flight_mode() is not None, "the autopilot again")
        # The restarted agent takes the ground's next commands (its session starts counting
        # where the ground's stands). No second run: the interrupted doublet left the aircraft
        # out of the envelope for a while, which the envelope check rightly refuses.
        ack = await sim.ground.command(messages.IdentSettings(axes="lateral"))
        assert ack.ok, ack.reason
        ack = await sim.ground.command(messages.Arm(plan=preset("lateral", plan_id="again")))
        assert ack.ok, ack.reason
    assert lapsed <= timeout + 0.5
    assert rc == pilot
    assert any("_flight_" in n for n in logged)
    flights = sorted((tmp_path / "logs").glob("*_flight_*"))
    assert len(flights) == 2  # the restarted agent started a new log, numbered after the old
    assert flights[0].name < flights[1].name
    after = assert_logs_whole(tmp_path)
    for name, rows in logged.items():
        assert after[name] == rows  # nothing written before the kill was lost or changed


# -- sensors failing during an excitation ---------------------------------------------------


async def test_an_ins_dropout_and_a_corrupted_stream_during_an_excitation(tmp_path):
    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:
        agent = sim.agent
        surfaces = sim.aircraft.emitters["surfaces"]
        vn200 = next(d for d in agent.drivers if d.name == "vn200")
        box = next(d for d in agent.drivers if d.name == "surfaces")
        surfaces.corrupt = 0.05
        seen = await start_run(sim, "sensors")
        await asyncio.sleep(2.0)
        sim.aircraft.ports["vn200"].unplug()
        await asyncio.sleep(0.5)
        sim.aircraft.ports["vn200"].plug()
        await until(lambda: vn200.health().state == "open", "the INS back")
        end = await finished_or_aborted(sim, seen)
        outcome = await answer(sim, seen)
        surfaces.corrupt = 0.0
        corrupted, crc = surfaces.corrupted, box.health().crc_errors
        sim.aircraft.pilot.set_switch(False)
        await asyncio.sleep(0.5)
        overrides = sim.aircraft.autopilot.overrides
    assert corrupted > 10
    assert crc + box.health().rejected >= corrupted - 3  # each bad frame counted
    assert vn200.health().gaps >= 1
    assert overrides == {}
    # The run played to its end (the scheduler flies on the autopilot's attitude, not the
    # INS); the identification refused a window with a hole in the INS channels, and said so.
    # Single corrupted surface frames (10 ms each) are bridged by the recorder.
    assert end.event == "finished", end.detail
    assert isinstance(outcome, messages.Failure), outcome
    found = re.search(r"channel '(\w+)' has a ([\d.]+) s gap in the window", outcome.reason)
    assert found, outcome.reason
    assert found.group(1) in ("p", "r", "phi", "psi", "theta", "q")
    assert 0.4 < float(found.group(2)) < 1.5
    assert_logs_whole(tmp_path)


# -- the autopilot rebooting ----------------------------------------------------------------


async def test_an_autopilot_reboot_mid_run_aborts_to_trim_and_the_agent_reconnects(tmp_path):
    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:
        ap, agent = sim.aircraft.autopilot, sim.agent
        seen = await start_run(sim, "reboot")
        started = received(sim, messages.ExcitationEvent, seen, event="started")[0]
        await asyncio.sleep(1.5)
        rebooted = sim.clock.now()
        await ap.reboot(silent_s=2.0)
        end = await finished_or_aborted(sim, seen)
        assert end.event == "aborted"
        await until(lambda: agent.autopilot.connected, "the link to the rebooted autopilot")
        # The agent asked the rebooted ArduPlane for its streams again.
        await until(lambda: ap.intervals != ap.default_intervals, "the stream rates again")
        sim.aircraft.pilot.set_switch(False)
        await asyncio.sleep(0.5)
        ack = await sim.ground.command(messages.Arm(plan=preset("lateral", plan_id="again")))
        assert ack.ok, ack.reason  # and takes a new plan
        after = [
            values
            for t, kind, values, accepted in (e for e in ap.wire if e[1] == "override")
            if t >= rebooted and accepted
        ]
        overrides = ap.overrides
    assert ap.counters["reboots"] == 1
    assert "autopilot" in end.detail or "stale" in end.detail, end.detail
    # The reboot dropped the excitation's overrides; what the agent sent the rebooted ArduPlane
    # was at most the trim and the release of the excited channels, never another excitation.
    trim = trim_of(started)
    release = {ch: RELEASE_LOW for ch in trim}
    assert all(v in (trim, release) for v in after), after[:5]
    assert overrides == {}
    assert_logs_whole(tmp_path)


# -- shutdown in the middle of a run --------------------------------------------------------


async def test_an_agent_stopped_mid_run_trims_and_releases_before_its_link_closes(tmp_path):
    """The agent's task cancelled 1.5 s into a run (a shutdown): the autopilot link stays up
    until the scheduler's trim and release have gone out (it used to close first)."""
    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:
        seen = await start_run(sim, "shutdown")
        started = received(sim, messages.ExcitationEvent, seen, event="started")[0]
        await asyncio.sleep(1.5)
        assert sim.aircraft.autopilot.overrides
        agent_task = next(t for t in asyncio.all_tasks() if t.get_name() == "agent")
        agent_task.cancel()
        await asyncio.gather(agent_task, return_exceptions=True)
        held = sim.agent.autopilot.counters["closed_holding_override"]
        await asyncio.sleep(0.2)
        overrides = sim.aircraft.autopilot.overrides
    assert held == 0
    assert_trimmed_then_released(sim, started, started.time)
    assert overrides == {}
    assert_logs_whole(tmp_path)


# -- the disk holding the link's replay state fills up mid-run ------------------------------


async def test_an_abort_acts_at_once_while_the_link_state_cannot_be_written(
    tmp_path, small_disk_at
):
    """Bad input tried: the file system holding the aircraft's link state (a real 1 MiB
    tmpfs) filled up during an excitation, so every write of the seen file fails with ENOSPC
    from the kernel. The session used to hold every command until that write succeeded and
    restart on its error (6 restarts in 20 s): the ground's Abort never acted. Now the Abort
    acts the moment it arrives: no excitation command goes out after it (the scheduler's next
    command is the trim), then the release; a state-changing command is refused with the
    disk's reason, which the status carries; the agent records throughout, and the session
    never restarts."""
    disk = small_disk_at(tmp_path / "air", "1m")
    async with simulated(SimOptions(preset="lateral", directory=tmp_path)) as sim:
        agent = sim.agent
        sent: list[tuple[messages.Message, int]] = []  # every downlink message, as it is sent
        agent.downlink.subscribe(lambda m: sent.append((m, agent.scheduler.counters["commands"])))
        seen = await start_run(sim, "state-disk-full")
        started = received(sim, messages.ExcitationEvent, seen, event="started")[0]
        assert fill(disk / "filler") == errno.ENOSPC  # from the kernel
        refused = await sim.ground.command(messages.IdentSettings(axes="lateral"))
        assert not refused.ok
        assert "replay state cannot be saved" in refused.reason
        assert "No space left on device" in refused.reason
        await until(
            lambda: [m for m in received(sim, messages.Status, seen) if m.link_fault],
            "the status's link fault",
        )
        frames = agent.recorder.ring.count
        ack = await sim.ground.command(messages.Abort(reason="operator abort, disk full"))
        assert ack.ok, ack.reason
        end = await finished_or_aborted(sim, seen)
        assert end.event == "aborted"
        assert "disk full" in end.detail
        await until(lambda: agent.recorder.ring.count > frames + 100, "recording")
        failures = agent.session.counters["seen_write_failures"]
        restarts = agent.counters["link_restarts"]
        sim.aircraft.pilot.set_switch(False)
    # The Abort's acknowledgement is sent in the callback that received it; the scheduler's
    # command count then is its count at the end: not one excitation command after it.
    at_abort = next(n for m, n in sent if isinstance(m, messages.Ack) and m.ref == ack.ref)
    assert agent.scheduler.counters["commands"] == at_abort
    assert_trimmed_then_released(sim, started, started.time)
    assert failures >= 1
    assert restarts == 0
    assert_logs_whole(tmp_path)
