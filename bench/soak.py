"""Soak: minutes of random goals with random faults, through the installed processes.

sim, planner and controller run as separate processes on their own ROS domain (as the
process tests run them); a probe in this process sends random goals -- good ones (random
free configurations, and the presets) and bad ones of every kind -- and injects faults at
random: the sim paused (SIGSTOP, joint states stop), the planner paused (slow) or restarted
(down), an e-stop by service (reset a moment later). Seeded: the same seed makes the same
choices (the machine's timing still differs run to run).

Reported at the end:

- goals: sent, reached, rejected or failed with their reasons (numbers blanked), dropped
  (cleared by an e-stop or the controller's queue full);
- contact with forbidden space on ``/sim/ground_truth``, split by what the motors were told
  when the arm entered it (the last ``voltage_command`` heard): while commanding (must be
  zero); while at 0 V (no joint states, or an e-stop cut to 0 V: nothing holds a 45 kg arm
  up then; it falls as a real one would), or within a second after (the controller has it
  again, still braking that fall) -- reported, not excused;
- memory (RSS) of each node, minute by minute;
- control-loop period: ``voltage_command`` as the probe hears it (median, p99, worst), and
  the controller's own worst period per second from its diagnostics.

    python bench/soak.py                     # ten minutes
    python bench/soak.py --minutes 2 --seed 3

Needs the package built and sourced (``ros_harness`` finds it on AMENT_PREFIX_PATH).
Not a test: it takes minutes and asserts nothing, it prints a table.
"""

import argparse
from collections import Counter
from pathlib import Path
import random
import re
import signal
import sys
import tempfile
import time

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / 'test' / 'rigs'), str(HERE.parent)]

from arm_rig import ArmRig, BAD_GOALS, diagnostic_values  # noqa: E402
import numpy as np  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.control.events import EventKind, parse_event  # noqa: E402
from arm_control.model.kinematics import TwoLinkKinematics  # noqa: E402
from arm_control.model.world import ForbiddenSpace  # noqa: E402
from arm_control.plans.goals import GoalValidator  # noqa: E402

ARM, CONTROLLER = config.load('controller')
_, SIM = config.load('sim')
KINEMATICS = TwoLinkKinematics(ARM.shoulder.length_m, ARM.elbow.length_m)
FORBIDDEN = ForbiddenSpace(ARM)
VALIDATOR = GoalValidator(ARM)
# Contact that begins this soon after a 0 V period is that fall carrying on (the controller
# has the arm again, but it is still falling).
FALL_CARRIES_ON_S = 1.0
# What happens each turn, with its weight.
ACTIONS = {'good goal': 50, 'preset goal': 10, 'bad goal': 12, 'sim pause': 8,
           'planner pause': 5, 'planner restart': 4, 'estop': 5}
MAX_QUEUED = 3                     # good goals are sent only while fewer wait


def random_free_goal(rng: random.Random):
    """The tool point of a random free configuration inside the joints' travel, whose every
    free elbow branch (the controller picks one) keeps the elbow and the tool 10 cm or more
    above the floor: the default world has no clearance, so a goal held on the floor line
    would touch it within the sensors' noise."""
    upper_m = ARM.shoulder.length_m
    while True:
        q = np.array([rng.uniform(j.min_angle_rad, j.max_angle_rad) for j in ARM.joints])
        x, y = KINEMATICS.forward(q)
        branches = VALIDATOR.free_configurations(x, y)
        if FORBIDDEN.is_free(q) and branches and all(
                min(y, upper_m * np.sin(b[0])) > 0.1 for b in branches):
            return float(x), float(y)


def reason_of(sentence: str) -> str:
    """An event's sentence with numbers blanked, so that alike ones count together."""
    sentence = re.sub(r'^(goal rejected|E-STOP): ', '', sentence)
    return re.sub(r'[-+]?\d[\d.e+-]*', '#', sentence)[:90]


class Soak:

    def __init__(self, rig: ArmRig, rng: random.Random):
        self.rig = rig
        self.rng = rng
        self.sent = Counter()
        self.faults = Counter()
        self.memory = []                 # (elapsed s, {node: MB})
        self.log = []                    # (time, what was done)
        self.began = time.monotonic()

    def queued(self) -> int:
        message = self.rig.queue.last()
        return len(message.poses) if message is not None else 0

    def step(self) -> None:
        action = self.rng.choices(list(ACTIONS), weights=list(ACTIONS.values()))[0]
        rig, rng = self.rig, self.rng
        self.log.append((time.monotonic(), f'{action} begins'))
        if action in ('good goal', 'preset goal'):
            if self.queued() >= MAX_QUEUED or rig.state == 'estopped':
                self.wait(rng.uniform(0.5, 1.5))
                return
            if action == 'good goal':
                goal = random_free_goal(rng)
            else:
                goal = rng.choice(ARM.presets)[1:]
            rig.send(*goal)
            self.sent['good'] += 1
        elif action == 'bad goal':
            goal, _ = rng.choice(BAD_GOALS)
            rig.send(**goal)
            self.sent['bad'] += 1
        elif action == 'sim pause':
            rig.pause('sim')
            self.wait(rng.uniform(0.1, 1.0))
            rig.resume('sim')
        elif action == 'planner pause':
            rig.pause('planner')
            self.wait(rng.uniform(0.3, 2.0))
            rig.resume('planner')
        elif action == 'planner restart':
            rig.processes['planner'].stop()
            self.wait(rng.uniform(0.0, 1.0))
            rig.start('planner')
        elif action == 'estop':
            rig.call(Trigger, '/controller/estop')
            self.wait(rng.uniform(0.2, 1.0))
            rig.call(Trigger, '/controller/reset')
        self.faults[action] += 1
        self.log.append((time.monotonic(), action))
        self.wait(rng.uniform(0.3, 2.5))

    def wait(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.rig.spin_for(min(0.5, max(end - time.monotonic(), 0.0)))
            elapsed = time.monotonic() - self.began
            if not self.memory or elapsed - self.memory[-1][0] >= 5.0:
                self.memory.append((elapsed, {name: self.rig.rss_mb(name)
                                              for name in self.rig.NODES}))


def contact_runs(rig: ArmRig):
    """Runs of true samples in forbidden space: (start time, samples, deepest m, what the
    motors were told when it began: 'commanding (<state>)', 'at 0 V (<state>)' -- the last
    command heard was 0 V, or none came for the sim's ``command_timeout_s`` -- or 'after
    0 V' when a 0 V period ended within FALL_CARRIES_ON_S before it)."""
    times = np.array([t for t, _ in rig.truth])
    q = np.array([m.position for _, m in rig.truth])
    free = np.asarray(FORBIDDEN.is_free(q))
    lowest = np.asarray(FORBIDDEN.lowest_point_m(q))
    state_times = [t for t, _ in rig.states]
    command_times = np.array([t for t, _ in rig.voltages])
    zero = np.array([not any(m.data) for _, m in rig.voltages])
    zero_times = command_times[zero]

    def at_zero_volts(t):
        index = np.searchsorted(command_times, t, side='right') - 1
        return index < 0 or zero[index] or t - command_times[index] > SIM.command_timeout_s

    runs, start = [], None
    for index, ok in enumerate(free):
        if not ok and start is None:
            start = index
        if (ok or index == len(free) - 1) and start is not None:
            end = index if ok else index + 1
            began = times[start]
            where = np.searchsorted(state_times, began, side='right') - 1
            state = rig.states[where][1].data if where >= 0 else ''
            earlier = zero_times[zero_times <= began]
            if at_zero_volts(began):
                label = f'at 0 V ({state})'
            elif len(earlier) and began - earlier[-1] <= FALL_CARRIES_ON_S:
                label = 'after 0 V'
            else:
                label = f'commanding ({state})'
            runs.append((began, end - start, float(np.min(lowest[start:end])), label))
            start = None
    return runs


def report(soak: Soak, rig: ArmRig, minutes: float) -> None:
    events = [parse_event(text) for text in rig.events_heard()]
    kinds = Counter(kind for kind, _, _ in events)
    refused = Counter(reason_of(sentence) for kind, _, sentence in events
                      if kind in (EventKind.GOAL_REJECTED, EventKind.GOAL_FAILED))
    estops = Counter(cause or reason_of(sentence) for kind, cause, sentence in events
                     if kind in (EventKind.ESTOP, EventKind.CONTROL_FAILED))
    print(f'\n## Soak: {minutes:g} min, {soak.sent["good"]} good goals and {soak.sent["bad"]} '
          f'bad ones sent\n')
    print('| faults injected | count |\n|---|---|')
    for name, count in sorted(soak.faults.items()):
        if 'goal' not in name:
            print(f'| {name} | {count} |')
    print('\n| goals | count |\n|---|---|')
    print(f'| sent (good + bad) | {soak.sent["good"] + soak.sent["bad"]} |')
    print(f'| reached | {kinds[EventKind.GOAL_REACHED]} |')
    print(f'| rejected or failed, with the reason | {sum(refused.values())} |')
    for reason, count in refused.most_common():
        print(f'| &nbsp;&nbsp;{reason} | {count} |')
    print(f'| rejections beyond the burst, counted in one event | '
          f'{kinds[EventKind.GOALS_REJECTED]} |')
    print(f'| dropped (cancelled) | {kinds[EventKind.CANCELLED]} |')
    print(f'| e-stops (by reason) | {sum(estops.values())} |')
    for reason, count in estops.most_common():
        print(f'| &nbsp;&nbsp;{reason} | {count} |')

    runs = contact_runs(rig)
    at_zero = [r for r in runs if r[3].startswith('at 0 V')]
    after_zero = [r for r in runs if r[3] == 'after 0 V']
    commanding = [r for r in runs if r[3].startswith('commanding')]
    print('\n| contact with forbidden space (/sim/ground_truth) | entries | samples | '
          'deepest |\n|---|---|---|---|')
    for label, group in (('entered while the controller commanded (must be 0)', commanding),
                         ('entered while at 0 V (no joint states, power cut: it falls)',
                          at_zero),
                         (f'entered within {FALL_CARRIES_ON_S:g} s after 0 V (that fall, '
                          'still braking)', after_zero)):
        deepest = f'{-1000 * min(r[2] for r in group):.0f} mm' if group else '-'
        print(f'| {label} | {len(group)} | {sum(r[1] for r in group)} | {deepest} |')
    print(f'| true samples in all | | {len(rig.truth)} | |')
    for began_at, samples, deepest_m, state in runs:
        before = [m.data for t, m in rig.events if t <= began_at][-3:]
        done = [(round(t - soak.began, 1), what) for t, what in soak.log
                if began_at - 3.0 <= t <= began_at]
        print(f'contact at {began_at - soak.began:.1f} s, {state}: '
              f'{samples} samples, {1000 * -deepest_m:.0f} mm deep; events before: {before}; '
              f'done in the 3 s before: {done}')

    print('\n| minute | sim RSS (MB) | planner RSS (MB) | controller RSS (MB) |\n'
          '|---|---|---|---|')
    last_minute = -1
    for elapsed, sizes in soak.memory:
        minute = int(elapsed // 60)
        if minute != last_minute or (elapsed, sizes) == soak.memory[-1]:
            last_minute = minute
            print(f'| {elapsed / 60:.1f} | {sizes["sim"]:.1f} | {sizes["planner"]:.1f} | '
                  f'{sizes["controller"]:.1f} |')

    heard = np.diff([t for t, _ in rig.voltages])
    own = [float(d['loop period worst (s)']) for d in rig.controller_diagnostics()
           if d.get('loop period worst (s)', 'nan') != 'nan']
    print('\n| control-loop period | median | p99 | worst | samples |\n|---|---|---|---|---|')
    print(f'| voltage_command as heard by the probe | {1000 * np.median(heard):.1f} ms | '
          f'{1000 * np.percentile(heard, 99):.1f} ms | {1000 * heard.max():.1f} ms | '
          f'{len(heard)} |')
    if own:
        print('| the controller’s worst period per second (its diagnostics) | '
              f'{1000 * np.median(own):.1f} ms | {1000 * np.percentile(own, 99):.1f} ms | '
              f'{1000 * max(own):.1f} ms | {len(own)} |')
    stalls = sorted(((float(d['loop period worst (s)']), t) for t, message in rig.diagnostics
                     for d in [diagnostic_values(message, '/controller')]
                     if d.get('loop period worst (s)', 'nan') != 'nan'), reverse=True)[:3]
    for worst, heard_at in stalls:
        before = [(t, what) for t, what in soak.log if t <= heard_at][-2:]
        around = ', '.join(f'{what} at {t - soak.began:.1f} s' for t, what in before)
        print(f'stall {1000 * worst:.0f} ms in the second before {heard_at - soak.began:.1f} s;'
              f' just before: {around}')
    print(f'\nnominal period {1000 / CONTROLLER.loop_rate_hz:.1f} ms; node logs in '
          f'{rig.log_dir}')


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=10.0)
    parser.add_argument('--seed', type=int, default=1)
    args = parser.parse_args()
    from ros_harness import Probe, ros_domain
    rng = random.Random(args.seed)
    # Stopped from outside (timeout, kill): still stop the nodes, or they outlive the
    # domain's lock and disturb whoever takes the domain next.
    signal.signal(signal.SIGTERM, _interrupt)
    with ros_domain() as domain:
        probe = Probe(domain, 'soak')
        rig = ArmRig(domain, probe, Path(tempfile.mkdtemp(prefix='arm_soak_')))
        try:
            rig.start_all()
            rig.ready()
            soak = Soak(rig, rng)
            end = time.monotonic() + 60.0 * args.minutes
            while time.monotonic() < end:
                soak.step()
            rig.call(Trigger, '/controller/cancel')
            soak.wait(2.0)
            report(soak, rig, args.minutes)
            alive = {name: process.alive() for name, process in rig.processes.items()}
            print(f'processes alive at the end: {alive}')
        finally:
            rig.close()
            probe.close()


if __name__ == '__main__':
    main()
