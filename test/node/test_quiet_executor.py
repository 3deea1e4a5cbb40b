"""QuietExecutor: one wait per message for a plain subscription (rclpy's executor waits twice,
the second time woken by its own guard), while another thread's trigger still wakes it."""

import threading
import time

import pytest
import rclpy
import rclpy.executors
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import Int32

from arm_control.nodes.quiet_executor import QuietExecutor

MESSAGES = 20


class CountingWaits:
    """rclpy's extension module, counting the wait sets the executor builds (one per wait)."""

    def __init__(self, real):
        self.real, self.waits = real, 0

    def __getattr__(self, name):
        return getattr(self.real, name)

    def WaitSet(self, *args):     # noqa: N802 (the extension's name)
        self.waits += 1
        return self.real.WaitSet(*args)


@pytest.fixture
def context(domain):
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    yield context
    context.try_shutdown()


def waits_for_messages(context, executor_class, monkeypatch) -> tuple[int, int]:
    """(messages received, waits) for MESSAGES published 10 ms apart by another thread."""
    counting = CountingWaits(rclpy.executors._rclpy)
    monkeypatch.setattr(rclpy.executors, '_rclpy', counting)
    node = rclpy.create_node('quiet', context=context)
    received = []
    node.create_subscription(Int32, 'numbers', received.append, 100)
    publisher = node.create_publisher(Int32, 'numbers', 100)
    executor = executor_class(context=context)
    executor.add_node(node)

    def publish():
        time.sleep(0.2)
        for i in range(MESSAGES):
            publisher.publish(Int32(data=i))
            time.sleep(0.01)
    sender = threading.Thread(target=publish)
    sender.start()
    deadline = time.monotonic() + 10.0
    while len(received) < MESSAGES and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=1.0)
        if len(received) == 1 and counting.waits > 1:
            counting.waits = 1                  # from the first message on
    sender.join()
    executor.shutdown()
    node.destroy_node()
    return len(received), counting.waits


def test_the_quiet_executor_waits_once_per_message(context, monkeypatch):
    received, waits = waits_for_messages(context, QuietExecutor, monkeypatch)
    assert received == MESSAGES
    assert waits <= MESSAGES + 2, f'{waits} waits for {received} messages'


def test_rclpy_s_executor_waits_twice_per_message(context, monkeypatch):
    """The cost the quiet executor removes (if rclpy stops waking itself, drop it)."""
    received, waits = waits_for_messages(context, SingleThreadedExecutor, monkeypatch)
    assert received == MESSAGES
    assert waits >= 1.8 * MESSAGES


def test_another_thread_s_task_still_wakes_it(context):
    """A task created from another thread runs at once, not at the next message."""
    node = rclpy.create_node('quiet_wake', context=context)
    executor = QuietExecutor(context=context)
    executor.add_node(node)
    ran = []
    timer = threading.Timer(0.3, lambda: executor.create_task(lambda: ran.append(
        time.monotonic())))
    began = time.monotonic()
    timer.start()
    while not ran and time.monotonic() - began < 5.0:
        executor.spin_once(timeout_sec=5.0)
    timer.join()
    executor.shutdown()
    node.destroy_node()
    assert ran and ran[0] - began < 1.0
