"""rclpy's single-threaded executor without the wake it gives itself after each message.

rclpy's handler triggers the executor's guard condition as it takes a message and again when
the callback ends ("the entity can be waited on again", for executors with several threads).
In one thread the spinning thread gathers the wait set again right after the callback
anyway, so the next wait returns at once, on the guard alone, and every entity of the node is
gathered twice per message (the controller: 50 joint states a second). ``QuietExecutor``
builds the handler of a plain subscription callback with a guard that ignores its own
thread: the wake after it is the next message's, timer's or service's. A trigger from
another thread (a task created, a future done, ``wake``) still wakes it; coroutine
callbacks, timers, services, clients and waitables keep rclpy's handler as it is.
"""

import inspect
import threading

from rclpy.executors import SingleThreadedExecutor
from rclpy.subscription import Subscription


class _OtherThreadsGuard:
    """The executor's guard condition, triggered only from threads other than ``owner``."""

    def __init__(self, guard, owner: int):
        self.guard, self.owner = guard, owner

    def trigger(self) -> None:
        if threading.get_ident() != self.owner:
            self.guard.trigger()


class QuietExecutor(SingleThreadedExecutor):
    """A single-threaded executor that gathers once per message (the module's rule)."""

    def _make_handler(self, entity, node, take_from_wait_list):
        if not isinstance(entity, Subscription) or \
                inspect.iscoroutinefunction(entity.callback):
            return super()._make_handler(entity, node, take_from_wait_list)
        # The handler captures the guard as it is built; a thread that reads it meanwhile
        # (create_task, wake) gets one that still triggers for it.
        guard = self._guard
        self._guard = _OtherThreadsGuard(guard, threading.get_ident())
        try:
            return super()._make_handler(entity, node, take_from_wait_list)
        finally:
            self._guard = guard
