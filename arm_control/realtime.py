"""Real-time scheduling for the threads that keep a beat, where the system allows it.

Under CPU load a 50 Hz loop at normal priority waits in the run queue behind busy processes,
for a good part of its period; at ``SCHED_FIFO`` it runs when it is due. Robot software runs
its loops this way: ros2_control's controller manager (FIFO 50) and WPILib's Notifier. It needs
CAP_SYS_NICE or an rtprio limit (``/etc/security/limits.conf``: ``@realtime - rtprio 98``);
without either, the node says so and runs at normal priority.
"""

from contextlib import contextmanager
import os
from typing import Optional

# Fast DDS names its threads 'dds.<role>...': 'dds.udp.<port>' receives, 'dds.ev.<n>' times.
DDS_THREAD_PREFIX = 'dds.'
HOW_TO_ALLOW = ('allow it with an rtprio limit (limits.conf: "<user> - rtprio 98") or '
                'CAP_SYS_NICE; running at normal priority, so CPU load can delay the beat')


def _set_fifo(thread_id: int, priority: int) -> None:
    os.sched_setscheduler(thread_id, os.SCHED_FIFO, os.sched_param(priority))


def raise_this_thread(priority: int) -> Optional[str]:
    """SCHED_FIFO at ``priority`` (1-98; 0: leave it) for the calling thread. None, or why
    it could not be done."""
    return raise_thread(0, priority)        # 0: the calling thread, not the process


def raise_thread(thread_id: int, priority: int) -> Optional[str]:
    """SCHED_FIFO at ``priority`` (0: leave it) for the thread ``thread_id`` of this process
    (``threading.Thread.native_id``). None, or why it could not be done."""
    if priority <= 0:
        return None
    try:
        _set_fifo(thread_id, priority)
    except OSError as error:
        return f'real-time priority {priority} refused ({error.strerror}): {HOW_TO_ALLOW}'
    return None


def lower_this_thread() -> None:
    """The calling thread back to normal scheduling."""
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


@contextmanager
def raised(priority: int):
    """The calling thread at SCHED_FIFO ``priority`` for the block, then back to normal; yields
    None, or why it could not be raised. For short work a user waits for (a plan, its quick
    timing): beside two busy processes on two cores, normal priority gets about half a core,
    and the wait doubles."""
    problem = raise_this_thread(priority)
    try:
        yield problem
    finally:
        if priority > 0 and problem is None:
            lower_this_thread()


def raise_process(priority: int) -> Optional[str]:
    """SCHED_FIFO at ``priority`` for every thread the process has now (the DDS threads that
    receive and send included); threads they start later inherit it."""
    if priority <= 0:
        return None
    try:
        for thread_id in os.listdir('/proc/self/task'):
            try:
                _set_fifo(int(thread_id), priority)
            except ProcessLookupError:      # a thread that ended meanwhile
                pass
    except OSError as error:
        return f'real-time priority {priority} refused ({error.strerror}): {HOW_TO_ALLOW}'
    return None


def dds_threads(task_dir: str = '/proc/self/task') -> list[int]:
    """The ids of this process's DDS threads (by their names), as they are now."""
    found = []
    for thread_id in os.listdir(task_dir):
        try:
            with open(os.path.join(task_dir, thread_id, 'comm')) as comm:
                if comm.read().startswith(DDS_THREAD_PREFIX):
                    found.append(int(thread_id))
        except OSError:                     # a thread that ended meanwhile
            pass
    return found


def raise_dds_threads(priority: int, task_dir: str = '/proc/self/task') -> Optional[str]:
    """SCHED_FIFO at ``priority`` for the DDS threads the process has now, Python's own left
    as they are: a message is received by a DDS thread before an executor takes it, and at
    normal priority that thread waits in the run queue behind every busy process first.
    None, or why it could not be done."""
    if priority <= 0:
        return None
    try:
        for thread_id in dds_threads(task_dir):
            try:
                _set_fifo(thread_id, priority)
            except ProcessLookupError:      # a thread that ended meanwhile
                pass
    except OSError as error:
        return f'real-time priority {priority} refused ({error.strerror}): {HOW_TO_ALLOW}'
    return None
