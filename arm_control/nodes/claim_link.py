"""The controller's claim to the arm on ROS: ``voltage_command_claim`` (std_msgs/Header,
transient local, beside ``voltage_command``), said every ``CLAIM_EVERY_S`` once it is ready,
and the claims of others heard (``control/commanders.py``: the earliest keeps the arm).

Listen before commanding: a controller that, when it becomes ready, sees other claimers in
the graph whose claims it has not heard yet sends nothing until it hears one or
``CLAIM_EVERY_S`` passes (a live claimer says its claim that often, and transient local
hands over the last at once). So a later controller yields before its first command rather
than after a few."""

import math
import os
import secrets
import socket
import threading
import time

from builtin_interfaces.msg import Time
from std_msgs.msg import Header

from arm_control.control.commanders import Claim, CLAIM_EVERY_S, CLAIM_STALE_S, Commanders
from arm_control.control.events import EventKind as Kind
from arm_control.control.state_machine import ArmState
from arm_control.nodes.common import LATCHED, listen, output

TOPIC = 'voltage_command_claim'
TOKEN_CHARS = 64            # a claim's token longer than this is not a controller's


class ClaimLink:
    """``ready()`` at the first reading; ``yields()`` before each command (any thread)."""

    def __init__(self, node):
        token = f'{socket.gethostname()[:30]}:{os.getpid()}:{secrets.token_hex(4)}'
        self.commanders = Commanders(token)
        self.yielding = False           # this controller sends nothing: another has the arm
        self.disabled_to_yield = False  # its core disabled on yielding: enabled on taking over
        self.lock = threading.Lock()
        self.listen_until_s = -math.inf  # wall s: silent until then, unless a claim is heard
        self.node = node
        self.publisher = output(node, Header, TOPIC, LATCHED)
        listen(node, Header, TOPIC, self.on_claim, LATCHED)
        node.create_timer(CLAIM_EVERY_S, self.say)

    def on_claim(self, msg: Header) -> None:
        since_s = msg.stamp.sec + 1e-9 * msg.stamp.nanosec
        if 0 < len(msg.frame_id) <= TOKEN_CHARS and math.isfinite(since_s):
            with self.lock:
                self.commanders.heard(Claim(since_s, msg.frame_id), time.time())

    def ready(self) -> None:
        """It could command from now: claim the arm (once), and say so at once."""
        if self.commanders.mine is None:
            now_s = time.time()
            with self.lock:
                self.commanders.ready(now_s)
                others = 0 if self.commanders.rivals else \
                    self.node.count_publishers(TOPIC) - 1              # its own is one
                if others > 0:
                    self.listen_until_s = now_s + CLAIM_EVERY_S
            if others > 0:
                self.node.get_logger().info(
                    f'{others} other claimer(s) of the arm on {TOPIC}: listening for their '
                    f'claims for up to {CLAIM_EVERY_S:g} s before commanding')
            self.say()

    def listening(self) -> bool:
        """Other claimers were in the graph at ready and none has been heard yet."""
        with self.lock:
            if self.commanders.rivals or time.time() >= self.listen_until_s:
                self.listen_until_s = -math.inf
                return False
            return True

    def say(self) -> None:
        mine = self.commanders.mine
        if mine is not None:
            sec = math.floor(mine.since_s)
            self.publisher.publish(Header(stamp=Time(
                sec=sec, nanosec=min(round(1e9 * (mine.since_s - sec)), 999_999_999)),
                frame_id=mine.token))

    def yields(self) -> bool:
        with self.lock:
            return self.commanders.yields(time.time())

    def owner(self):
        with self.lock:
            return self.commanders.owner(time.time())

    def change(self, node, now_s: float, yields: bool) -> None:
        """Under the node's lock: yield the arm to an earlier claim (the core disabled, where
        it can be, so that it neither moves nor judges an arm it does not command; nothing
        sent, not even on exit), or take it where it is once every earlier claim has gone."""
        core, self.yielding = node.core, yields
        mine, owner = self.commanders.mine, self.owner()
        if yields:
            self.disabled_to_yield = core.state != ArmState.DISABLED and \
                core.enable(now_s, False)[0] and core.state == ArmState.DISABLED
            node.last_command = node.commander.last_profile = None
            core.say(now_s, Kind.YIELDED, 'error', (
                f'another controller ({owner.token}) has had the arm since '
                f'{owner.since_s:.3f}, before this one ({mine.token if mine else "not ready"}): '
                'this one sends nothing and answers that it does not command, until it goes'),
                'voltage_command')
            return
        what = 'it was not disabled to yield: as it is'
        if self.disabled_to_yield and core.state == ArmState.DISABLED:
            what = core.enable(now_s, True)[1]
        self.disabled_to_yield = False
        core.say(now_s, Kind.TAKEN_OVER, 'warning', 'the controller that had the arm '
                 f'is gone (no claim heard for {CLAIM_STALE_S:g} s): {what}',
                 'voltage_command')
