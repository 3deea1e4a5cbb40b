"""A flood of goals from a process of its own: good ones and bad ones of every kind, at a
rate, kept by the publisher until the controller has them all."""

import subprocess
import sys
import time

from arm_rig import BAD_GOALS, point
from geometry_msgs.msg import PointStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy

# The flood's publisher keeps its goals until the controller has them (a user's script
# with COMMANDS' depth of 10 loses some to overwriting when the subscriber falls behind): a
# depth for a whole flood, since a loaded controller falls more than a second behind (with
# 1000, 321 of 10,000 goals were overwritten before they were sent).
FLOOD_QOS = QoSProfile(depth=20_000, reliability=ReliabilityPolicy.RELIABLE)


def flood_goals():
    """Goals for the flood, cycling: good ones (they fill the queue; high, front and back)
    and bad ones of every kind."""
    good = [dict(x=1.1, y=0.9), dict(x=0.9, y=1.5), dict(x=-0.6, y=1.5)]
    return good + [dict(goal) for goal, _ in BAD_GOALS]


def flood(domain: int, rate_hz: float, seconds: float) -> int:
    """Publish goals at ``rate_hz`` for ``seconds`` (in bursts every 10 ms); return the
    count sent."""
    import rclpy
    from rclpy.duration import Duration
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('flood', context=context)
    publisher = node.create_publisher(PointStamped, '/goal_point', FLOOD_QOS)
    deadline = time.monotonic() + 10.0
    while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    goals = [point(**goal) for goal in flood_goals()]
    sent = 0
    began = time.monotonic()
    while True:
        elapsed = time.monotonic() - began
        if elapsed >= seconds:
            break
        due = min(int(elapsed * rate_hz) + 1, int(seconds * rate_hz))
        while sent < due:
            publisher.publish(goals[sent % len(goals)])
            sent += 1
        time.sleep(0.01)
    # Alive until the controller has them all: a reliable writer that goes away takes the
    # goals not yet delivered with it.
    publisher.wait_for_all_acked(Duration(seconds=60.0))
    node.destroy_node()
    rclpy.try_shutdown(context=context)
    return sent


def start_flood(domain: int, rate_hz: float, seconds: float) -> subprocess.Popen:
    from ros_harness import ros_environment
    return subprocess.Popen([sys.executable, __file__, 'flood', str(domain), str(rate_hz),
                             str(seconds)], env=ros_environment(domain),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


if __name__ == '__main__':
    if sys.argv[1:2] == ['flood']:
        print(f'sent {flood(int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]))}')
