"""The agent's own logic, without the hardware: ground commands answered with acks, and the
identification every update period set from the ground.

Bad input tried: a plan beyond the envelope, a decision on a model that does not exist, a
revert with no previous nominal, an operator start with the switch low, and an excitation
window whose surface data are missing for a second (identification fails with the reason, the
agent goes on).
"""

from __future__ import annotations

import asyncio
import signal
import time
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import numpy as np
import pytest

from agent.clock import VirtualClock
from agent.config import Config, Recorder
from agent.excitation.plan import Doublet, Plan, Segment, preset
from agent.link import messages
from agent.runtime import Agent, lag_histogram, lag_percentile
from agent.runtime.worker import new_worker, processes, stop_worker
from tests.waiting import until


def thread_worker() -> ThreadPoolExecutor:
    """The worker's jobs on a thread here: the same job functions, without a process spawn."""
    return ThreadPoolExecutor(1, thread_name_prefix="worker")


@pytest.fixture
def agent(tmp_path):
    config = Config(recorder=Recorder(log_dir=str(tmp_path / "logs"), capacity_s=60.0))
    a = Agent(config, base=tmp_path, clock=VirtualClock(100.0), worker=thread_worker)
    a.sent = []
    a.downlink.subscribe(a.sent.append)
    yield a
    a.close()


def acks_of(agent) -> dict[int, messages.Ack]:
    return {m.ref: m for m in agent.sent if isinstance(m, messages.Ack)}


async def command_task_answers(agent, count: int) -> dict[int, messages.Ack]:
    """Run the command task until `count` commands are acknowledged."""
    task = asyncio.create_task(agent.commands.run())
    try:
        await until(lambda: len(acks_of(agent)) >= count, f"{count} acknowledgements")
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
    return acks_of(agent)


async def test_ground_commands_are_acknowledged_with_the_reason(agent):
    big = Plan(
        id="big",
        axes="lateral",
        segments=(Segment(signals={"aileron": Doublet(pulse_s=1.0, amplitude=20.0)}),),
    )
    commands = [
        messages.Arm(plan=preset("lateral")),
        messages.Arm(plan=big),
        messages.Start(),
        messages.Decision(model_id="nope", accept=True),
        messages.Revert(),
        messages.IdentSettings(axes="full", update_period_s=20.0),
        # Bad input tried: an explicit p and order beyond markov_max / order_max.
        messages.IdentSettings(axes="lateral", markov=1000, order=500),
    ]
    for seq, command in enumerate(commands, start=1):
        agent.commands.receive(command, seq)  # queued for the command task, in order
    assert not agent.sent  # nothing answered before the command task runs
    acks = await command_task_answers(agent, len(commands))
    assert acks[1].ok
    assert not acks[2].ok
    assert "max_amplitude" in acks[2].reason
    assert not acks[3].ok
    assert "switch" in acks[3].reason
    assert not acks[4].ok
    assert "nope" in acks[4].reason
    assert not acks[5].ok
    assert "no previous" in acks[5].reason
    assert acks[6].ok
    assert not acks[7].ok
    assert "p 1000 is outside 1…" in acks[7].reason
    assert "order 500 is outside 1…" in acks[7].reason
    assert agent.identification.settings.axes == "full"  # the refused ones did not replace it


async def test_a_message_that_is_not_a_command_is_refused_by_name(agent):
    # Bad input tried: a status and a result sent up from the ground.
    agent.commands.receive(messages.Status(time=1.0), 1)
    agent.commands.receive(messages.Notice(text="hello"), 2)
    answered = await command_task_answers(agent, 2)
    assert not answered[1].ok
    assert answered[1].reason == "not a command: Status"
    assert answered[2].reason == "not a command: Notice"
    assert agent.counters["commands_unknown"] == 2


def test_an_agent_built_without_config_text_logs_the_hash_of_its_settings(tmp_path):
    # Input: the agent as `sysid sim` builds it in-process, Agent(config) with no file text;
    # its excitation logs carried sha256("") (e3b0c442...), naming no config.
    from agent.config import to_toml
    from agent.logs import config_hash
    from drivers.values import Window

    config = Config(recorder=Recorder(log_dir=str(tmp_path / "logs"), rate_hz=50.0))
    agent = Agent(config, base=tmp_path, worker=thread_worker)
    try:
        rows = np.zeros((2, len(agent.recorder.columns)))
        window = Window("lat1", "lateral", 1.0, 1.02, "finished", "")
        path = agent.logbook.excitation(window, rows)
    finally:
        agent.close()
    sha = [ln for ln in path.read_text().splitlines() if ln.startswith("# config sha256 ")]
    assert sha == [f"# config sha256 {config_hash(to_toml(config))}"]
    assert config_hash(to_toml(config)) != config_hash("")


def test_every_update_period_queues_the_latest_data(agent):
    n = len(agent.recorder.channels)
    for k in range(3001):  # 30 s of frames at 100 Hz, the newest at 130 s
        row = np.zeros(1 + 2 * n)
        row[0] = 100.0 + k * 0.01
        agent.recorder.ring.append(row)
    window, rows = agent.identification.periodic_window(20.0)
    assert window.end - window.start == pytest.approx(20.0)
    assert rows[0, 0] >= window.start
    assert rows[-1, 0] <= window.end
    assert len(rows) == pytest.approx(2000, abs=2)


async def test_an_unusable_window_gives_a_failure_result_and_the_agent_goes_on(agent):
    from agent.excitation.scheduler import Window

    n = len(agent.recorder.channels)
    rows = np.zeros((1500, 1 + 2 * n))
    rows[:, 0] = 100.0 + np.arange(1500) * 0.01
    aileron = 1 + agent.recorder.channels.index("aileron")
    rows[600:700, aileron] = np.nan  # the surface box was silent for 1 s mid-window
    await agent.identification.identify(Window("lat", "lateral", 100.0, 115.0, "finished"), rows)
    failures = [m for m in agent.sent if isinstance(m, messages.Failure)]
    assert len(failures) == 1
    assert "1.00 s gap" in failures[0].reason
    assert agent.counters["identification_failures"] == 1
    assert agent.identification.results[-1].failure == failures[0].reason


async def test_each_stage_is_expected_to_last_what_the_last_did_scaled_by_the_record(tmp_path):
    # The live view's progress bar for the identification: what the aircraft expects each
    # stage to take. On the real clock (the fixture's virtual one stands still in a job).
    from agent.excitation.scheduler import Window

    config = Config(recorder=Recorder(log_dir=str(tmp_path / "logs"), capacity_s=60.0))
    agent = Agent(config, base=tmp_path, worker=thread_worker)
    try:
        ident = agent.identification
        assert ident.expected("identifying", "lateral", 1500) is None  # nothing to go by yet
        n = len(agent.recorder.channels)
        rows = np.zeros((1500, 1 + 2 * n))
        rows[:, 0] = 100.0 + np.arange(1500) * 0.01
        await ident.identify(Window("lat", "lateral", 100.0, 115.0, "finished"), rows)
        took = ident.expected("identifying", "lateral", 1500)
        assert took is not None
        assert took > 0
        assert ident.expected("identifying", "lateral", 3000) == pytest.approx(2 * took)
        assert ident.expected("identifying", "longitudinal", 1500) is None  # other axes
        assert ident.expected("comparing with nominal", "lateral", 1500) is None  # no nominal
        assert ident.stage(agent.clock.now()) is None  # idle again
    finally:
        agent.close()


async def test_health_record_separates_the_lag_while_identifying(agent):
    # What the lag monitor collected over a period: 10 ms of lag once, while identifying.
    for lag, identifying in [(0.0001, False)] * 99 + [(0.010, True), (0.0002, True)]:
        agent.health.add_lag(lag, identifying)
    record = agent.health.record(wall_s=60.0, cpu_s=6.0)
    assert record["lag"]["n"] == 101
    assert record["lag"]["max_ms"] == pytest.approx(10.0)
    assert record["lag"]["p50_ms"] == pytest.approx(0.1)
    assert record["lag_identifying"]["n"] == 2
    assert record["lag_identifying"]["p50_ms"] == pytest.approx(5.1)
    assert record["cpu_percent"] == pytest.approx(10.0)
    assert record["rss_mb"] > 10
    assert record["threads"] >= 1
    # The bins count every sample: 0.1 ms falls in [0.1, 0.15), 10 ms in [10, 11).
    assert record["lag"]["hist"] == {"0.15": 99, "0.25": 1, "11": 1}
    assert record["lag_identifying"]["hist"] == {"0.25": 1, "11": 1}
    # The period starts afresh; an empty period is reported as such, not as zeros.
    empty = agent.health.record(wall_s=60.0, cpu_s=0.0)
    assert empty["lag"] == {"n": 0}
    assert empty["lag_identifying"] == {"n": 0}


async def test_an_abort_cancels_an_arm_still_waiting_its_turn(agent):
    agent.commands.receive(messages.Arm(plan=preset("full")), 1)  # rendering would take 0.1 s
    agent.commands.receive(messages.IdentSettings(axes="full"), 2)
    agent.commands.receive(messages.Abort(), 3)
    acks = await command_task_answers(agent, 3)
    assert not acks[1].ok
    assert "cancelled by an abort" in acks[1].reason
    assert acks[2].ok  # not a run: still carried out
    assert acks[3].ok
    assert agent.scheduler.status == "idle"


def a2_flight(tmp_path, refine: bool = False):
    """An agent (its worker on a thread) and the thesis's A.2 lateral record as a window of
    recorded rows."""
    import csv

    from agent.config import IdentificationConfig
    from agent.excitation.scheduler import Window

    root = Path(__file__).resolve().parents[1]
    with (root / "examples" / "a2_lateral.csv").open() as handle:
        table = list(csv.DictReader(handle))
    config = Config(
        recorder=Recorder(log_dir=str(tmp_path / "logs"), rate_hz=50.0),
        identification=IdentificationConfig(refine=refine),
    )
    agent = Agent(config, base=tmp_path, worker=thread_worker)
    channels = agent.recorder.channels
    rows = np.full((len(table), 1 + 2 * len(channels)), np.nan)
    rows[:, 0] = [float(r["time"]) for r in table]
    for name in ("aileron", "rudder", "beta", "p", "r", "phi"):
        rows[:, 1 + channels.index(name)] = [float(r[name]) for r in table]
    return agent, Window("run", "lateral", rows[0, 0], rows[-1, 0], "finished"), rows


async def test_a_new_nominal_that_predicts_worse_is_rolled_back(tmp_path):
    """Requirement 6.3.1: lat-2 is accepted but is wrong (its B negated); on the next
    excitation it predicts the data far worse than lat-1 did, so lat-1 is nominal again and
    the ground is told."""
    agent, window, rows = a2_flight(tmp_path)
    sent = []
    agent.downlink.subscribe(sent.append)

    def last_id() -> str:
        return [m for m in sent if isinstance(m, messages.Result)][-1].model_id

    try:
        await agent.identification.identify(window, rows)
        first = last_id()
        await agent.commands.handle(messages.Decision(model_id=first, accept=True), 1)
        await agent.identification.identify(window, rows)
        second = last_id()
        wrong = agent.models.candidates[second]
        wrong.result = wrong.result.model_copy(update={"B": (-np.asarray(wrong.result.B)).tolist()})
        await agent.commands.handle(messages.Decision(model_id=second, accept=True), 2)
        assert agent.models.nominal_id("lateral") == second
        await agent.identification.identify(window, rows)
    finally:
        agent.close()
    assert (first.rsplit("-", 1)[0], second.rsplit("-", 1)[0]) == ("lat-1", "lat-2")
    assert agent.models.nominal_id("lateral") == first
    notices = [m.text for m in sent if isinstance(m, messages.Notice)]
    assert any(
        t.startswith(f"self-check: nominal {second}") and t.endswith("reverted") for t in notices
    ), notices


def test_lag_percentiles_pool_the_health_records_histograms():
    # Two minutes of made-up lags (ms), one with a tail; the pooled percentile is the upper
    # edge of the bin the true percentile of all samples falls in.
    rng = np.random.default_rng(1)
    minutes = [rng.exponential(0.4, 5000), np.r_[rng.exponential(0.4, 5000), [3.3] * 80, [250]]]
    pooled = np.concatenate(minutes)
    hists = [lag_histogram(m) for m in minutes]
    assert sum(sum(h.values()) for h in hists) == pooled.size
    assert hists[1]["inf"] == 1  # 250 ms: beyond the last edge
    for q in (50, 99, 99.9):
        true = np.percentile(pooled, q, method="inverted_cdf")
        edge = lag_percentile(hists, q)
        assert true <= edge < true + 0.05 + 1e-9, (q, true, edge)
    assert lag_percentile(hists, 100) == float("inf")
    assert lag_percentile([hists[0]], 100) == pytest.approx(np.ceil(minutes[0].max() / 0.05) * 0.05)
    with pytest.raises(ValueError, match="no lag samples"):
        lag_percentile([{}], 99)


def _say_then_sleep(path: str) -> None:  # runs in the worker process
    Path(path).touch()
    time.sleep(3600)


async def test_stopping_a_worker_stuck_in_a_job_kills_it_instead_of_waiting_for_ever(tmp_path):
    # Bad input: the worker busy with a job that would take an hour (as a worker starved of
    # CPU, or one deep in a long identification, is) when the agent shuts down.
    loop = asyncio.get_running_loop()
    pool = new_worker()  # the real worker: spawned, with its initializer
    started = tmp_path / "started"
    stuck = loop.run_in_executor(pool, _say_then_sleep, str(started))
    while not started.exists():  # the worker has warmed up and is in the job
        await asyncio.sleep(0.05)
    (process,) = processes(pool)
    await stop_worker(pool)
    assert not process.is_alive()
    assert process.exitcode == -signal.SIGKILL  # killed, not finished
    with pytest.raises(BrokenProcessPool):  # the job is reported lost, not left pending
        await stuck


async def test_the_frequency_response_of_a_pair_is_sent_when_asked(tmp_path):
    """Bad input tried: a pair the model does not have, a model that does not exist."""
    from agent.ident.frf import model_response

    agent, window, rows = a2_flight(tmp_path, refine=True)
    agent.sent = []
    agent.downlink.subscribe(agent.sent.append)
    worker = asyncio.create_task(agent.identification.run())
    try:
        await agent.identification.identify(window, rows)
        (result,) = [m for m in agent.sent if isinstance(m, messages.Result)]
        model_id = result.model_id
        for seq, (model, i, o) in enumerate(
            [(model_id, "aileron", "p"), (model_id, "elevator", "q"), ("lat-9", "aileron", "p")],
            start=1,
        ):
            agent.commands.receive(messages.FrfRequest(model_id=model, input=i, output=o), seq)
        answered = await command_task_answers(agent, 3)
        await until(lambda: any(isinstance(m, messages.FrfReport) for m in agent.sent), "FRF")
    finally:
        worker.cancel()
        await asyncio.gather(worker, return_exceptions=True)
        agent.close()
    assert answered[1].ok
    assert "no pair elevator → q" in answered[2].reason
    assert "no model lat-9" in answered[3].reason
    (report,) = [m for m in agent.sent if isinstance(m, messages.FrfReport)]
    assert (report.model_id, report.input, report.output) == (model_id, "aileron", "p")
    assert 10 <= len(report.freq_hz) <= messages.FRF_POINTS
    assert np.all(np.diff(report.freq_hz) > 0)
    assert all(g is not None and 0 <= g <= 1 for g in report.coherence)
    # The measured response is the model's own data's: the identified model lies on it.
    result = agent.identification.results[-1].result
    model = model_response(result.A, result.B, result.C, result.D, result.dt, report.freq_hz)
    i, j = result.inputs.index("aileron"), result.outputs.index("p")
    model_db = 20 * np.log10(np.abs(model[:, j, i]))
    assert np.median(np.abs(model_db - np.array(report.mag_db))) < 1.0
    # What goes on air: the codec's own MessagePack, within the seven frames it was sized for.
    import msgpack

    assert len(msgpack.packb(messages.to_dict(report))) < 2000
