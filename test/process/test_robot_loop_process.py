"""Through ROS, on the robot's clock: the sim reads its sensors and applies the latest command
only at its loop's instants -- never before the command arrived, at the first instant after
-- and the controller sends profiles: a hold is still, a move arrives."""

import math
import time

from arm_rig import ArmRig, assert_never_forbidden, DEG
import numpy as np
import pytest
from ros_harness import stamp_s
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from arm_control import config
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.kinematics import TwoLinkKinematics

ARM, SIM = config.load('sim')
PERIOD_S = 1.0 / SIM.publish_rate_hz
PHASE_S = 0.013
KINEMATICS = TwoLinkKinematics(ARM.shoulder.length_m, ARM.elbow.length_m)


@pytest.fixture
def rig(domain, probe, tmp_path):
    rig = ArmRig(domain, probe, tmp_path, {'sim': (
        '-p', 'command_timing:=robot_loop', '-p', f'robot_loop_phase_s:={PHASE_S}')})
    rig.start_all()
    try:
        rig.ready()
        yield rig
    finally:
        rig.close()


def test_on_the_robot_loop_a_hold_is_still_and_a_move_arrives(rig):
    stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
              for _, m in rig.joint_states[-20:]]
    offsets = [(s - PHASE_S) / PERIOD_S - round((s - PHASE_S) / PERIOD_S) for s in stamps]
    assert max(abs(o) for o in offsets) < 1e-3          # at the loop's instants
    assert rig.voltages.last().layout.data_offset == 6  # a profile

    rig.spin_for(1.0)
    since = rig.truth[-1][0]
    rig.spin_for(2.0)
    held = [m for t, m in rig.truth if t > since]
    speeds = np.abs([m.velocity for m in held])
    positions = np.array([m.position for m in held])
    assert np.max(speeds) < 0.1, np.max(speeds, axis=0)
    assert np.max(np.ptp(positions, axis=0)) < math.radians(0.5)

    began = rig.truth[-1][0]
    rig.send(1.1, 0.9)
    assert rig.wait_said('goal_reached', 10.0, began), rig.event_log(began)
    reached_q, reached_s = rig.true_q(), time.monotonic()
    assert rig.wait_held(reached_q, 2.0 * DEG, timeout_s=3.0), drift(rig, reached_q, reached_s)
    tool = KINEMATICS.forward(rig.true_q())
    assert math.dist(tool, (1.1, 0.9)) < 0.03
    assert_never_forbidden(rig, began)


def drift(rig, q, since_s: float) -> str:
    """How far the true joints went from ``q`` after ``since_s``, and on how many states."""
    moved = [np.max(np.abs(np.array(m.position) - q)) for m in rig.truth.messages(since_s)]
    return (f'{len(moved)} true states after {q} rad; the farthest '
            f'{math.degrees(max(moved, default=math.nan)):.2f} deg from it, the last '
            f'{math.degrees(moved[-1]) if moved else math.nan:.2f} deg')


@pytest.mark.parametrize('phase_s', [0.004, 0.016])
def test_a_command_acts_at_the_first_loop_instant_after_it_arrives_never_before(
        launch, probe, phase_s):
    """Voltage pairs of alternating sign, sent at times spread over the period; a reading's
    effort is the torque of the volts applied since the instant before it, so the first
    reading of a command's volts, one period back, is the instant it was applied."""
    launch('sim', '-p', 'command_timing:=robot_loop', '-p', f'robot_loop_phase_s:={phase_s}',
           '-p', 'initial_position:=[1.5708, 0.0]')
    readings = probe.collect(JointState, '/joint_states')
    publisher = probe.node.create_publisher(Float64MultiArray, '/voltage_command', 10)
    assert probe.spin_until(lambda: readings and publisher.get_subscription_count() > 0, 20.0)
    rng = np.random.default_rng(0)
    sent = []
    for k in range(12):
        probe.spin_for(0.1 + rng.uniform(0.0, PERIOD_S))
        volts = 4.0 if k % 2 else -4.0
        sent.append((time.time(), volts))
        publisher.publish(Float64MultiArray(data=[volts, volts]))
    probe.spin_for(0.2)
    stamps = np.array([stamp_s(m) for m in readings])
    motor = ArmDynamics(ARM).motors[1]              # τ = a·V − b·ω: V from effort and speed
    volts_per_nm = 1.0 / (motor.torque_nm(1.0, 0.0) - motor.torque_nm(0.0, 0.0))
    applied = np.array([(m.effort[1] - motor.torque_nm(0.0, m.velocity[1])) * volts_per_nm
                        for m in readings])
    offsets = (stamps - phase_s) / PERIOD_S
    assert np.max(np.abs(offsets - np.round(offsets))) < 1e-3       # read at the instants
    for sent_s, volts in sent[1:]:
        first = np.flatnonzero((stamps > sent_s) & (np.abs(applied - volts) < 0.5))[0]
        applied_s = stamps[first] - PERIOD_S
        assert applied_s >= sent_s                               # never before it was sent
        assert applied_s < sent_s + PERIOD_S + 0.015             # the next instant (+ transit)
