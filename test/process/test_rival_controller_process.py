"""A second controller started beside the one that holds the arm (two voltage_command
publishers, two nodes named /controller): the later one yields -- it says so and sends
nothing -- while the first keeps holding the arm; both seeing each other, neither stops the
arm. Killed, the first leaves its last profile holding, and the one that yielded takes the
arm where it is once the claim has gone (control/commanders.py).

Where the arm went is read from the sim's true state, which the controllers never see."""

import time

from arm_rig import assert_never_forbidden, DEG
import numpy as np

from arm_control.control.commanders import CLAIM_STALE_S

RATE_HZ = 50.0                  # one controller's commands a second
WATCH_S = 3.0                   # watched with the two side by side, and after the hand-over
HELD_RAD = 0.5 * DEG            # the arm within this of where it was held, throughout
TAKEOVER_RAD = 3.0 * DEG        # ... and the second controller's hold within this of it
STARTED_S = 60.0                # a process started on a loaded machine is there by then
CLAIM_SLACK_S = 3.0             # DDS delivery and a loaded machine, on top of the stale time


def commands_a_second(rig, since_s: float, until_s: float) -> float:
    heard = [t for t, _ in rig.voltages if since_s <= t <= until_s]
    return len(heard) / (until_s - since_s)


def moved_from(rig, q, since_s: float) -> float:
    return max(float(np.max(np.abs(np.array(m.position) - q)))
               for m in rig.truth.messages(since_s))


def test_the_later_controller_yields_and_takes_the_arm_when_the_first_goes(rig):
    rig.reset_sim()
    assert rig.wait_still()
    held, began = rig.true_q(), time.monotonic()
    first = rig.processes['controller']
    log_dir = rig.log_dir / 'rival'
    log_dir.mkdir(exist_ok=True)
    second = rig._node_process('controller', rig.domain, (), log_dir)
    try:
        # Said once, maybe before the probe's subscription has matched the new node's
        # (events are volatile): its own log says it too.
        assert rig.spin_until(lambda: rig.said('yielded', began)
                              or 'yielded (voltage_command)' in second.output(), STARTED_S), \
            rig.event_log(began)
        yielded = time.monotonic()
        assert rig.spin_until(lambda: any(cause == 'voltage_command' for _, cause, _
                                          in rig.said('untrusted', began)), 10.0)
        rig.spin_for(WATCH_S)
        rate = commands_a_second(rig, yielded + 0.5, time.monotonic())
        side_by_side = moved_from(rig, held, began)
        assert len(rig.said('yielded', began)) <= 1, rig.event_log(began)     # one, not both
        assert second.output().count('yielded (voltage_command)') == 1
        assert 'yielded (voltage_command)' not in first.output()
        assert rate < 1.3 * RATE_HZ, f'{rate:.0f} commands a second: both command'
        assert side_by_side < HELD_RAD, np.degrees(side_by_side)

        rig.kill('controller')                  # the first, without a goodbye
        gone = time.monotonic()
        rig.processes['controller'], second = second, None      # the rig stops it at the end
        rig.retired.append(first)
        assert rig.wait_said('taken_over', CLAIM_STALE_S + CLAIM_SLACK_S, gone), \
            rig.event_log(gone)
        taken = time.monotonic()
        rig.spin_for(WATCH_S)
        after = commands_a_second(rig, taken + 0.5, time.monotonic())
        handed = moved_from(rig, held, gone)
        print(f'side by side: {rate:.0f} commands a second, the arm within '
              f'{np.degrees(side_by_side):.2f} deg; taken over '
              f'{rig.said_at("taken_over", gone) - gone:.2f} s after the first was killed, '
              f'{after:.0f} commands a second, the arm within {np.degrees(handed):.2f} deg')
        assert after > 0.7 * RATE_HZ
        assert handed < TAKEOVER_RAD
        assert_never_forbidden(rig, began)
    finally:
        if second is not None:
            second.stop()
