"""Joint trajectories as a ROS client sends them, followed by the controller's core in closed
loop with the simulated arm (in-process, deterministic: seeded sensor noise, no ROS).

Each case is sent as ``~/follow_joint_trajectory`` hands it to the core: checked
(``TrajectoryGoals.prepare``: forbidden space, the motors' limits; an infeasible timing
retimed), then followed as the current goal (``GoalRunner.follow``). Per case: the duration
asked and followed, what was done to it, the worst and mean tracking error of the true arm
against the trajectory followed, the error at rest at the end, and the peak volts.

    python bench/joint_trajectories.py               # print the table
    python bench/joint_trajectories.py --write-docs  # and keep it in docs/benchmarks/

Needs the package's dependencies (no ROS graph). Not a test: it asserts nothing.
"""

from pathlib import Path
import sys

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / 'test' / 'rigs'), str(HERE)]

from docs_table import write  # noqa: E402
import numpy as np  # noqa: E402
from trajectory_checks import moveit_style, request  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.control.closed_loop import ClosedLoop  # noqa: E402
from arm_control.control.motions import Motion  # noqa: E402
from arm_control.control.state_machine import ArmState  # noqa: E402
from arm_control.parameters import read_parameter_files  # noqa: E402
from arm_control.plans.goals import Goal  # noqa: E402
from arm_control.plans.joint_trajectory import TrajectoryRefused  # noqa: E402
from arm_control.plans.trajectory_goals import FollowSettings, TrajectoryGoals  # noqa: E402

START = (1.5708, -1.5708)
# (case, end configuration (rad), seconds asked, points, with velocities and accelerations)
CASES = [
    ('MoveIt-style, forward and down', (0.9, -0.5), 3.0, 30, True),
    ('MoveIt-style, forward and down', (0.9, -0.5), 1.5, 30, True),
    ('MoveIt-style, forward and down', (0.9, -0.5), 0.6, 30, True),
    ('MoveIt-style, over the top to the back', (2.4, 0.9), 2.5, 40, True),
    ('MoveIt-style, over the top to the back', (2.4, 0.9), 1.0, 40, True),
    ('positions only, forward and down', (0.9, -0.5), 2.0, 8, False),
]


def run(arm, controller, goals, end, seconds, count, full):
    loop = ClosedLoop(arm, controller, seed=0)
    loop.run(0.5)
    core = loop.core
    rows = moveit_style(core.last_step.setpoint[0], end, seconds, count)
    if not full:
        rows = [row[:2] for row in rows]
    try:
        prepared = goals.prepare(request(('shoulder', 'elbow'), rows), loop.now,
                                 lambda t: core._reference(t))
    except TrajectoryRefused as error:
        return None, f'refused: {error.code.name}'
    motion = Motion(prepared.trajectory, prepared.begin_s)
    x, y = core.kinematics.forward(prepared.final_q)
    core.goals.follow(loop.now, Goal(x, y, 'bench', replan=False), motion)
    errors, volts = [], []
    loop.observers.append(lambda rig, reading, voltage: (
        errors.append(np.abs(rig.true_q - motion.sample(rig.now)[0])),
        volts.append(np.max(np.abs(voltage)))))
    loop.run(motion.end_s - loop.now + 3.0, until=loop.in_state(ArmState.HOLDING))
    errors = np.degrees(np.array(errors))
    final = np.degrees(np.abs(loop.true_q - prepared.final_q))
    done = 'retimed' if prepared.note else 'as asked'
    return (prepared.trajectory.duration_s, errors.max(axis=0), errors.mean(axis=0), final,
            max(volts), loop.core.state), done


def main():
    arm, controller = config.load('controller')
    settings = FollowSettings.from_parameters(read_parameter_files((), 'controller'))
    goals = TrajectoryGoals(arm, controller, settings)
    lines = ['| case | asked s | followed s | done | worst error deg (shoulder, elbow) | '
             'mean error deg | at rest deg | peak V | state after |',
             '|---|---|---|---|---|---|---|---|---|']
    for name, end, seconds, count, full in CASES:
        outcome, done = run(arm, controller, goals, end, seconds, count, full)
        if outcome is None:
            lines.append(f'| {name} ({count} points) | {seconds:.1f} | - | {done} | | | | | |')
            continue
        taken, worst, mean, final, peak, state = outcome
        lines.append(f'| {name} ({count} points) | {seconds:.1f} | {taken:.2f} | {done} | '
                     f'{worst[0]:.2f}, {worst[1]:.2f} | {mean[0]:.2f}, {mean[1]:.2f} | '
                     f'{final[0]:.2f}, {final[1]:.2f} | {peak:.1f} | {state} |')
    table = '\n'.join(lines)
    print(table)
    if '--write-docs' in sys.argv:
        print(write('joint_trajectories', 'Joint trajectories followed (in-process, closed loop)',
                    'python bench/joint_trajectories.py --write-docs', table))


if __name__ == '__main__':
    main()
