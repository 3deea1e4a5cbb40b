"""The controller's slow work in a process of its own: checking and timing plans.

Python runs one thread at a time in a process, so timing a plan -- milliseconds to tens of
milliseconds of numpy and Python -- in the controller's process would hold its control loop
back. The node starts one worker at start-up and hands it each plan; the loop never waits
for it. The worker is ``python -m arm_control.nodes.plan_worker`` with pickled objects over
its stdin and stdout: it imports only the timing code (multiprocessing's spawn would import
the node's whole module again, rclpy and all, and a fork would copy the DDS threads' locks).
It runs at normal priority, and dies with the node: its stdin closes when the node's
process goes.

A plan from rest is answered twice, quick then refined (``plans/worker.py``). The
worker says it is ready once its timing kernels are loaded (before its settings come: the
``controller`` executable starts it first, ``controller_start``); then, only while no
request waits, it warms up in slices (``WarmUp``), so that later goals find the caches warm
while the first one is never kept waiting for all of it.

Each path answered from rest then goes to the keeper, a second process at nice
``KEEPER_NICE``, which times it finely from rest; the worker keeps what comes back
(``KeptTrajectories``), and the next goal from rest along the same path is answered with it
at once, with nothing to refine. The node hands the keeper the planner's paths between
presets too, once the arm has had no goal for a while (``PlanLink``), so a robot's
preset-to-preset goals find theirs kept from the first. The keeper starts with the first
path it is given, not with the worker, whose first goal may come at once. It takes only the
CPU the others leave, and only while the arm holds: the node stops it (SIGSTOP) while a goal
is planned or followed, or the driver moves the arm. A goal never waits for it.
"""

from collections import deque
from multiprocessing.connection import Connection, wait
import os
import signal
import subprocess
import sys
import threading

from arm_control.nodes.worker_spawn import spawn, take_started
from arm_control.plans.messages import (Done, KeeperJob, KeeperResult, KeeperSettings,
                                        Keeping, KeepPath, Kept, PathPlan, PlanRequest,
                                        Ready, Settings, TimedPlan, TimePlan)
from arm_control.plans.worker import Keeper, KEEPER_QUEUE, Worker
from arm_control.realtime import lower_this_thread, raise_this_thread
from arm_control.timing.bus import compile_kernels


# The keeper's niceness: below the worker, the planner and everything else at normal
# priority, so it takes only the CPU the others leave.
KEEPER_NICE = 10


def _serve(requests: Connection, results: Connection) -> None:
    """The worker (``plans.worker.Worker``) between its pipes: it waits for the next item at
    ``planning_priority`` and keeps it for a goal's quick timing and its refinement only
    (``answer``): at normal priority, beside busy processes, a goal's request waited in the
    run queue before it was even read; the rest (settings, keeping, warm-up) runs at normal.
    The warm-up goes a slice at a time, only while nothing waits."""
    compile_kernels()               # loaded from numba's cache (or compiled) while it waits
    incoming = _Incoming(requests)
    keeping = _Keeping()
    worker = Worker(results.send, keeping)
    try:
        while True:
            if worker.warming and not incoming.waiting and not requests.poll():
                worker.warm()
                continue
            listening = worker.priority > 0 and raise_this_thread(worker.priority) is None
            keeper = keeping.keeper
            if not incoming.waiting and keeper is not None \
                    and requests not in wait([requests, keeper.results]):
                if listening:
                    lower_this_thread()
                done = keeping.take()
                if done is not None:
                    worker.take(done)
                continue
            item = incoming.next()
            if listening and not isinstance(item, TimePlan):    # answer() lowers after
                lower_this_thread()
            if item is None:
                return
            worker.take(item, incoming.newer)
    except (EOFError, OSError):     # the node is gone
        return
    finally:
        keeping.close()


class _Keeping:
    """The keeper as the worker sees it: started with the first path it is given (not with the
    worker, whose first goal may come at once), told each new setting (a ``generation``:
    what it times with older ones is dropped), let work or stopped."""

    def __init__(self):
        self.keeper = None
        self.gone = False                   # could not start, or ended: nothing more kept
        self.generation, self.settings, self.working = 0, None, True

    def retune(self, settings: Settings) -> None:
        self.generation, self.settings = self.generation + 1, settings
        if self.keeper is not None:
            self.keeper.settings(self.generation, settings)

    def allow(self, working: bool) -> None:
        self.working = working
        if self.keeper is not None:
            self.keeper.allow(working)

    def send(self, request: PlanRequest, plan, pinned: bool) -> None:
        if self.keeper is None and not self.gone:
            self.keeper = _Keeper.start()
            self.gone = self.keeper is None
            if self.keeper is not None:
                self.keeper.settings(self.generation, self.settings)
                self.keeper.allow(self.working)
        if self.keeper is not None:
            self.keeper.send(KeeperJob(self.generation, request, plan, pinned))

    def take(self) -> KeeperResult | None:
        """What the keeper timed with these settings, or None (older settings; or it has
        ended)."""
        try:
            done = self.keeper.results.recv()
        except (EOFError, OSError):
            print('plan worker: the keeper process ended; fine trajectories are no longer kept',
                  file=sys.stderr, flush=True)
            self.close()
            self.gone = True
            return None
        return done if done.generation == self.generation else None

    def close(self) -> None:
        if self.keeper is not None:
            self.keeper.close()
            self.keeper = None


class _Incoming:
    """The worker's items, read ahead when asked whether a newer request waits: a path sent
    for the keeper alone, or word on when it may work, does not count as one."""

    def __init__(self, connection: Connection):
        self.connection = connection
        self.read = deque()

    @property
    def waiting(self) -> bool:
        return bool(self.read)

    def next(self):
        return self.read.popleft() if self.read else self.connection.recv()

    def newer(self) -> bool:
        while self.connection.poll():
            self.read.append(self.connection.recv())
        return any(not isinstance(item, (KeepPath, Keeping)) for item in self.read)


class _Keeper:
    """The worker's side of the keeper: paths go to it through a thread of their own, at most
    ``KEEPER_QUEUE`` waiting (the oldest dropped), so the worker never waits on the keeper,
    however slowly it reads."""

    def __init__(self):
        self.child = _Child('--keeper', nice=KEEPER_NICE)
        self.results = self.child.results
        self._outbox = deque(maxlen=KEEPER_QUEUE)
        self._changed = threading.Condition()
        self._open = True
        threading.Thread(target=self._send, daemon=True, name='to the keeper').start()

    @classmethod
    def start(cls):
        """The keeper, or None when it cannot be started (goals are answered all the same)."""
        try:
            return cls()
        except OSError as error:
            print(f'plan worker: no keeper ({error}); fine trajectories will not be kept',
                  file=sys.stderr, flush=True)
            return None

    def send(self, item) -> None:
        with self._changed:
            self._outbox.append(item)
            self._changed.notify()

    def settings(self, generation: int, settings: Settings) -> None:
        """New settings: the paths still waiting were for the old ones."""
        with self._changed:
            self._outbox.clear()
            self._outbox.append(KeeperSettings(generation, settings))
            self._changed.notify()

    def _send(self) -> None:
        while True:
            with self._changed:
                self._changed.wait_for(lambda: self._outbox or not self._open)
                if not self._open:
                    return
                item = self._outbox.popleft()
            try:
                self.child.requests.send(item)
            except (OSError, ValueError):
                return

    def allow(self, working: bool) -> None:
        """Let it work, or stop it where it is (SIGSTOP: no CPU at all until SIGCONT)."""
        try:
            os.kill(self.child.process.pid, signal.SIGCONT if working else signal.SIGSTOP)
        except ProcessLookupError:
            pass

    def close(self) -> None:
        """Its work is disposable: stopped at once."""
        with self._changed:
            self._open = False
            self._changed.notify()
        self.child.process.kill()
        self.child.process.wait()


def _keep(requests: Connection, results: Connection) -> None:
    """The keeper (``plans.worker.Keeper``) between its pipes: the latest job first, each
    ``KeeperResult`` sent back."""
    keeper = Keeper()
    while True:
        try:
            while not keeper.waiting or requests.poll():
                item = requests.recv()
                if item is None:
                    return
                keeper.take(item)
        except (EOFError, OSError):
            return
        result = keeper.work()
        if result is not None:
            try:
                results.send(result)
            except OSError:                 # the worker is gone
                return


class _Child:
    """``python -m arm_control.nodes.plan_worker`` (with ``args``, at ``nice``), pickles over
    its stdin (``requests``) and stdout (``results``)."""

    def __init__(self, *args, nice: int = 0):
        self.process = (None if args else take_started()) or spawn(*args, nice=nice)
        self.requests = Connection(os.dup(self.process.stdin.fileno()), readable=False)
        self.results = Connection(os.dup(self.process.stdout.fileno()), writable=False)
        self.process.stdin.close()
        self.process.stdout.close()

    def close(self) -> None:
        try:
            self.requests.send(None)
        except (OSError, ValueError):
            pass
        try:
            self.process.wait(1.0)
        except subprocess.TimeoutExpired:
            self.process.terminate()            # the worker's ``finally`` still runs
            self.process.wait()


class PlanWorker:
    """The parent's side: ``submit`` a plan; ``on_timed(TimedPlan)`` is called from a thread
    of its own when it is timed; ``busy`` while a plan submitted is not done with. ``keep``
    hands a path to the keeper alone; ``kept``: how many trajectories are kept."""

    def __init__(self, arm, config, on_timed):
        self._child = _Child()
        self.process = self._child.process
        self.on_timed = on_timed
        self.ready = threading.Event()
        self.kept = 0
        self._send_lock = threading.Lock()
        self._open = 0                       # plans submitted, not yet done with
        self.retune(arm, config)
        self._thread = threading.Thread(target=self._receive, daemon=True, name='plan results')
        self._thread.start()

    def submit(self, request: PlanRequest, plan: PathPlan) -> None:
        with self._send_lock:
            self._open += 1
            self._child.requests.send(TimePlan(request, plan))

    def allow_keeping(self, working: bool) -> None:
        """Let the keeper work (the arm holds, or has no goal), or stop it until then (a goal
        is being planned or followed): it never takes CPU from a moving arm."""
        self._send_for_keeper(Keeping(bool(working)))

    def keep(self, request: PlanRequest, plan: PathPlan) -> None:
        """Have ``plan`` kept from rest before it is asked for (a path between presets, kept
        for good)."""
        self._send_for_keeper(KeepPath(request, plan))

    def _send_for_keeper(self, item) -> None:
        """Nothing when the worker is gone: keeping is optional."""
        try:
            with self._send_lock:
                self._child.requests.send(item)
        except (OSError, ValueError):
            pass

    @property
    def busy(self) -> bool:
        return self._open > 0

    def retune(self, arm, config) -> None:
        """Time the plans that come after this with these settings."""
        with self._send_lock:
            self._child.requests.send(Settings(arm, config))

    def _receive(self) -> None:
        while True:
            try:
                message = self._child.results.recv()
            except (EOFError, OSError):
                return
            match message:
                case Ready():
                    self.ready.set()
                case Done():
                    with self._send_lock:
                        self._open -= 1
                case Kept(count):
                    self.kept = count
                case TimedPlan():
                    self.on_timed(message)

    @property
    def results_thread_id(self) -> int:
        """The thread that hands each timed plan to ``on_timed`` (its ``native_id``)."""
        return self._thread.native_id

    @property
    def alive(self) -> bool:
        return self.process.poll() is None

    def close(self) -> None:
        with self._send_lock:
            self._child.close()


def main() -> None:
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))    # whatever its parent had
    # A Ctrl-C reaches the whole process group; the controller ends the worker itself (or
    # its pipe closes when the controller dies), so the worker does not die mid-answer.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))    # the keeper stopped on the way
    requests = Connection(os.dup(0), writable=False)
    results = Connection(os.dup(1), readable=False)
    os.dup2(2, 1)                   # a stray print goes to the log, not into the results
    (_keep if '--keeper' in sys.argv[1:] else _serve)(requests, results)


if __name__ == '__main__':
    main()
