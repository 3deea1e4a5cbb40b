"""The controller's slow work in a process of its own: checking and timing plans.

Python runs one thread at a time in a process, so timing a plan -- milliseconds to tens of
milliseconds of numpy and Python -- in the controller's process would hold its control loop
back. The node starts one worker at start-up and hands it each plan; the loop never waits
for it. The worker is ``python -m arm_control.nodes.plan_worker`` with pickled objects over
its stdin and stdout: it imports only the timing code (multiprocessing's spawn would import
the node's whole module again, rclpy and all, and a fork would copy the DDS threads' locks).
It runs at normal priority, and dies with the node: its stdin closes when the node's
process goes.
"""

from multiprocessing.connection import Connection
import os
import subprocess
import sys
import threading

from arm_control.config import ArmConfig
from arm_control.control.plans import PathPlan, PlanRequest, PlanTimer, TimedPlan
from arm_control.control.trajectory.moving_start import toppra_solver


def _serve(requests: Connection, results: Connection) -> None:
    """The worker: (arm, config) first, then time each (request, plan) that comes in and
    send back the TimedPlan; new (arm, config) when the settings change at run time."""
    timer = None
    while True:
        try:
            item = requests.recv()
        except (EOFError, OSError):
            return
        if item is None:
            return
        if isinstance(item[0], ArmConfig):
            first = timer is None
            timer = PlanTimer(*item)
            if first:
                results.send(None)                      # ready
                # The moving-start solver's import (0.8 s) done meanwhile, not at the first
                # goal that preempts another.
                threading.Thread(target=toppra_solver, daemon=True).start()
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
        self.process = subprocess.Popen(
            [sys.executable, '-m', 'arm_control.nodes.plan_worker'],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        self._requests = Connection(os.dup(self.process.stdin.fileno()), readable=False)
        self._results = Connection(os.dup(self.process.stdout.fileno()), writable=False)
        self.process.stdin.close()
        self.process.stdout.close()
        self.on_timed = on_timed
        self.ready = threading.Event()
        self._send_lock = threading.Lock()
        self.retune(arm, config)
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
        return self.process.poll() is None

    def close(self) -> None:
        try:
            with self._send_lock:
                self._requests.send(None)
        except (OSError, ValueError):
            pass
        try:
            self.process.wait(1.0)
        except subprocess.TimeoutExpired:
            self.process.terminate()


def main() -> None:
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))    # whatever its parent had
    requests = Connection(os.dup(0), writable=False)
    results = Connection(os.dup(1), readable=False)
    os.dup2(2, 1)                   # a stray print goes to the log, not into the results
    _serve(requests, results)


if __name__ == '__main__':
    main()
