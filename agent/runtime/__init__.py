"""`sysid agent`: the flight agent — one event loop and one TaskGroup owning the sensor
drivers, the autopilot link, the recorder, the excitation scheduler, the radio link session,
the identification and the health monitor (thesis chapter 5.1, algorithm 1).

One job per module: `agent` is the wiring (it builds the parts, connects them and supervises
each: a part that fails is logged, counted and restarted after a backoff, never taking the
others down); `identification` identifies windows in a worker process, so the loop never waits
on numerics, and keeps the results and the model store; `commands` carries out the ground's
commands, one handler per message type; `health` measures the loop's lag and the collector
and writes the health records; `status` sends the vehicle status down, and `live` the live
view during a run (progress and strip charts); `downlink` is the one way out to the ground;
`worker` starts and stops the worker process. On SIGINT/SIGTERM
(`serve`) a running excitation is aborted (trim, then release), logs are flushed and closed,
the worker is stopped.
"""

from agent.runtime.agent import Agent, serve
from agent.runtime.health import lag_histogram, lag_percentile

__all__ = ["Agent", "lag_histogram", "lag_percentile", "serve"]
