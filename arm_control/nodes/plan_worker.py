"""The controller's slow work in a process of its own: checking and timing plans.

Python runs one thread at a time in a process, so timing a plan -- milliseconds to tens of
milliseconds of numpy and Python -- in the controller's process would hold its control loop
back. The node starts one worker process at start-up (spawned, not forked: a fork would copy
the DDS threads' locks) and hands it each plan; the loop never waits for it. The worker dies
with the node: its end of the pipe closes when the node's process goes.
"""

import multiprocessing
import threading

from arm_control.config import ArmConfig
from arm_control.control.plans import PathPlan, PlanRequest, PlanTimer, TimedPlan


def _serve(arm, config, requests, results) -> None:
    """The worker: time each (request, plan) that comes in, send back the TimedPlan."""
    timer = PlanTimer(arm, config)
    results.send(None)                          # ready
    while True:
        try:
            item = requests.recv()
        except (EOFError, OSError):
            return
        if item is None:
            return
        if isinstance(item[0], ArmConfig):             # settings changed at run time
            timer = PlanTimer(*item)
            continue
        request, plan = item
        try:
            timed = timer.time_plan(request, plan)
        except Exception as error:              # never leave a goal hanging
            timed = TimedPlan(request, None, f'timing the plan failed: {error!r}')
        results.send(timed)


class PlanWorker:
    """The parent's side: ``submit`` a plan; ``on_timed(TimedPlan)`` is called from a thread
    of its own when it is timed."""

    def __init__(self, arm, config, on_timed):
        context = multiprocessing.get_context('spawn')
        child_requests, self._requests = context.Pipe(duplex=False)      # (reader, writer)
        self._results, child_results = context.Pipe(duplex=False)
        self.process = context.Process(target=_serve, daemon=True, name='plan worker',
                                       args=(arm, config, child_requests, child_results))
        self.process.start()
        child_requests.close()
        child_results.close()
        self.on_timed = on_timed
        self.ready = threading.Event()
        self._send_lock = threading.Lock()
        self._thread = threading.Thread(target=self._receive, daemon=True, name='plan results')
        self._thread.start()

    def submit(self, request: PlanRequest, plan: PathPlan) -> None:
        with self._send_lock:
            self._requests.send((request, plan))

    def retune(self, arm, config) -> None:
        """Time the plans that come after this with these settings."""
        with self._send_lock:
            self._requests.send((arm, config))

    def _receive(self) -> None:
        while True:
            try:
                timed = self._results.recv()
            except (EOFError, OSError):
                return
            if timed is None:
                self.ready.set()
            else:
                self.on_timed(timed)

    @property
    def alive(self) -> bool:
        return self.process.is_alive()

    def close(self) -> None:
        try:
            with self._send_lock:
                self._requests.send(None)
        except (OSError, ValueError):
            pass
        self.process.join(1.0)
        if self.process.is_alive():
            self.process.terminate()
