"""robotpy is for the FRC side only: without wpimath, ntcore and wpiutil the sim, planner and
controller run on arm.yaml (whose motors are given by datasheet), and a joint that names a
motor of WPILib's catalogue stops the node saying what to install."""

import os
import subprocess
import sys
import textwrap

from geometry_msgs.msg import PoseStamped
from nav_msgs.srv import GetPlan
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from arm_control.nodes.common import LATCHED

ROBOTPY = ('wpimath', 'wpiutil', 'ntcore', 'wpilib', 'hal')
# Imported by Python at start (from PYTHONPATH): every robotpy module then fails to import,
# as on a machine where it was never installed.
BLOCKER = textwrap.dedent(f'''\
    import sys


    class NoRobotpy:
        def find_spec(self, name, path=None, target=None):
            if name.split('.')[0] in {ROBOTPY!r}:
                raise ModuleNotFoundError(f'No module named {{name!r}}', name=name)


    sys.meta_path.insert(0, NoRobotpy())
''')


def without_robotpy(tmp_path) -> dict:
    """Environment variables that hide robotpy from a process."""
    folder = tmp_path / 'no_robotpy'
    folder.mkdir(exist_ok=True)
    (folder / 'sitecustomize.py').write_text(BLOCKER)
    return {'PYTHONPATH': os.pathsep.join([str(folder), os.environ.get('PYTHONPATH', '')])}


def test_the_blocker_hides_robotpy(tmp_path):
    env = {**os.environ, **without_robotpy(tmp_path)}
    result = subprocess.run([sys.executable, '-c', 'import wpimath'], env=env,
                            capture_output=True, text=True)
    assert result.returncode != 0 and 'wpimath' in result.stderr


def test_sim_planner_and_controller_run_on_arm_yaml_without_robotpy(launch, probe, tmp_path):
    environment = without_robotpy(tmp_path)
    nodes = [launch(name, environment=environment) for name in ('sim', 'planner', 'controller')]
    states = probe.collect(JointState, 'joint_states')
    arm_states = probe.collect(String, 'arm_state', LATCHED)     # said once, at its change
    assert probe.spin_until(lambda: states and arm_states, 60.0), [n.output() for n in nodes]
    request = GetPlan.Request(start=PoseStamped(), goal=PoseStamped())
    request.start.pose.position.x, request.start.pose.position.y = 0.8, 1.0
    request.start.pose.orientation.w = 1.0
    request.goal.pose.position.x, request.goal.pose.position.y = 1.1, 0.9
    answer = probe.call(GetPlan, 'plan_path', request, timeout_s=60.0, idempotent=True)
    assert answer.plan.poses
    assert all(node.alive() for node in nodes), [n.output() for n in nodes if not n.alive()]


def test_a_catalogue_motor_without_robotpy_says_what_to_install(launch, tmp_path):
    sim = launch('sim', '-p', 'elbow.motor:=NEO', environment=without_robotpy(tmp_path))
    assert sim.process.wait(timeout=30) != 0
    output = sim.output()
    assert "'elbow.motor' = 'NEO'" in output
    assert 'pip install robotpy-wpimath' in output
