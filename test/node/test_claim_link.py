"""A controller that becomes ready while other claimers of the arm are in the graph sends
nothing until it has heard a claim or one claim period has passed; alone, it commands at
once (nodes/claim_link.py)."""

import time

from std_msgs.msg import Header

from arm_control.control.commanders import CLAIM_EVERY_S
from arm_control.nodes import claim_link
from arm_control.nodes.claim_link import ClaimLink


class Graph:
    """The few calls ClaimLink makes of its node, with a graph of ``claimers`` publishers."""

    def __init__(self, claimers: int):
        self.claimers = claimers
        self.sent = []

    def create_publisher(self, *_, **__):
        graph = self

        class Publisher:
            def publish(self, msg):
                graph.sent.append(msg)
        return Publisher()

    def create_subscription(self, *_, **__):
        return None

    def create_timer(self, *_):
        return None

    def count_publishers(self, topic):
        assert topic == claim_link.TOPIC
        return self.claimers

    def get_logger(self):
        class Logger:
            def info(self, _):
                pass
        return Logger()


def claim(since_s: float, token: str) -> Header:
    msg = Header(frame_id=token)
    msg.stamp.sec, msg.stamp.nanosec = int(since_s), int(1e9 * (since_s % 1.0))
    return msg


def test_alone_it_commands_at_once():
    link = ClaimLink(Graph(claimers=1))         # its own publisher only
    link.ready()
    assert not link.listening()
    assert not link.yields()


def test_beside_a_claimer_not_yet_heard_it_listens_then_yields_to_an_earlier_claim():
    link = ClaimLink(Graph(claimers=2))
    link.ready()
    assert link.listening()
    link.on_claim(claim(time.time() - 10.0, 'earlier:1:ab'))
    assert not link.listening()
    assert link.yields()


def test_a_claimer_that_never_speaks_keeps_it_silent_one_claim_period_only(monkeypatch):
    now = [1000.0]
    monkeypatch.setattr(claim_link.time, 'time', lambda: now[0])
    link = ClaimLink(Graph(claimers=2))
    link.ready()
    now[0] += 0.9 * CLAIM_EVERY_S
    assert link.listening()
    now[0] += 0.2 * CLAIM_EVERY_S
    assert not link.listening()
    assert not link.yields()


def test_a_claim_heard_before_ready_needs_no_listening():
    link = ClaimLink(Graph(claimers=2))
    link.on_claim(claim(time.time() + 10.0, 'later:1:ab'))     # a later claim: it keeps the arm
    link.ready()
    assert not link.listening()
    assert not link.yields()
