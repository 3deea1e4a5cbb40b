"""The URDF matches the parameter file; the launch file names what the package installs.

``launch`` and ``launch_ros`` are not installable on these machines, so the launch file is
run against stand-ins that record what it builds: which executables of which packages,
with which parameters and conditions.
"""

import ast
import importlib.util
import math
from pathlib import Path, PurePath
import sys
import tempfile
import types
from xml.etree import ElementTree

from conftest import with_joint
import numpy as np
import pytest
import yaml

from arm_control import config, parameters
from arm_control.bringup import node_parameters
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.visual.urdf import arm_urdf, joint_limits

ROOT = Path(__file__).resolve().parents[2]
URDF = ROOT / 'urdf' / 'arm.urdf'
LAUNCH = ROOT / 'launch' / 'arm.launch.py'


@pytest.fixture(scope='module')
def robot():
    return ElementTree.parse(URDF).getroot()


def numbers(text):
    return [float(v) for v in text.split()]


def test_urdf_joints_are_named_as_in_joint_states_and_turn_about_z(robot):
    revolute = {j.get('name'): j for j in robot.findall('joint') if j.get('type') == 'revolute'}
    assert set(revolute) == set(config.JOINT_NAMES)
    for joint in revolute.values():
        assert numbers(joint.find('axis').get('xyz')) == [0.0, 0.0, 1.0]
    assert revolute['shoulder'].find('parent').get('link') == 'base'
    assert revolute['shoulder'].find('child').get('link') == 'upper_arm'
    assert revolute['elbow'].find('parent').get('link') == 'upper_arm'
    assert revolute['elbow'].find('child').get('link') == 'forearm'


def test_urdf_limits_lengths_and_masses_equal_the_parameter_file(robot, arm):
    joints = {j.get('name'): j for j in robot.findall('joint')}
    links = {link.get('name'): link for link in robot.findall('link')}
    for joint, link_name in ((arm.shoulder, 'upper_arm'), (arm.elbow, 'forearm')):
        limit = joints[joint.name].find('limit')
        assert float(limit.get('lower')) == pytest.approx(joint.min_angle_rad, abs=1e-6)
        assert float(limit.get('upper')) == pytest.approx(joint.max_angle_rad, abs=1e-6)
        # stall torque at the joint n·G·τ_stall; free speed 5330 rpm through the gearbox
        assert float(limit.get('effort')) == pytest.approx(
            joint.motor_count * joint.gear_ratio * 2.42, rel=1e-5)
        assert float(limit.get('velocity')) == pytest.approx(
            5330 * 2 * math.pi / 60 / joint.gear_ratio, rel=1e-5)
        inertial = links[link_name].find('inertial')
        assert float(inertial.find('mass').get('value')) == pytest.approx(joint.mass_kg)
        assert numbers(inertial.find('origin').get('xyz'))[0] == pytest.approx(
            joint.com_from_joint_m)
        assert float(inertial.find('inertia').get('izz')) == pytest.approx(
            joint.inertia_about_com_kgm2)
        box = links[link_name].find('visual/geometry/box')
        assert numbers(box.get('size'))[0] == pytest.approx(joint.length_m)
    assert numbers(joints['elbow'].find('origin').get('xyz')) == pytest.approx(
        [arm.shoulder.length_m, 0, 0])
    assert numbers(joints['tool_mount'].find('origin').get('xyz')) == pytest.approx(
        [arm.elbow.length_m, 0, 0])


def test_urdf_is_a_tree_rooted_at_arm_base(robot):
    links = {link.get('name') for link in robot.findall('link')}
    assert links == {'arm_base', 'base', 'upper_arm', 'forearm', 'tool'}
    children = [j.find('child').get('link') for j in robot.findall('joint')]
    assert sorted(children) == sorted(links - {'arm_base'})       # one parent each
    assert all(j.find('parent').get('link') in links for j in robot.findall('joint'))


def test_urdf_forward_kinematics_equals_the_model(robot, arm):
    """Chain the URDF's joints (translate, then turn about z) to the tool frame."""
    joints = {j.find('child').get('link'): j for j in robot.findall('joint')}
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    rng = np.random.default_rng(11)
    for _ in range(20):
        q = dict(zip(config.JOINT_NAMES, rng.uniform(-math.pi, math.pi, 2)))
        chain, link = [], 'tool'
        while link in joints:
            chain.append(joints[link])
            link = joints[link].find('parent').get('link')
        position, heading = np.zeros(2), 0.0
        for joint in reversed(chain):
            x, y, _ = numbers(joint.find('origin').get('xyz'))
            position = position + [x * math.cos(heading) - y * math.sin(heading),
                                   x * math.sin(heading) + y * math.cos(heading)]
            heading += q.get(joint.get('name'), 0.0) if joint.get('type') == 'revolute' else 0
        assert position == pytest.approx(kinematics.forward((q['shoulder'], q['elbow'])))


def test_checked_in_urdf_is_what_the_generator_makes_from_arm_yaml(arm):
    assert URDF.read_text() == arm_urdf(arm), \
        'urdf/arm.urdf is stale: python -m arm_control.visual.urdf config/arm.yaml > urdf/arm.urdf'


def test_joint_limits_of_the_default_shoulder(arm):
    limits = joint_limits(arm, arm.shoulder)
    assert limits['effort'] == pytest.approx(771.0, abs=0.1)       # 2 × 159.3 × 2.42 N·m
    assert limits['velocity'] == pytest.approx(3.504, abs=1e-3)    # 558.2 rad/s / 159.3


# -- the launch file ---------------------------------------------------------------------

def setup_call():
    """The keyword arguments of setup() in setup.py."""
    tree = ast.parse((ROOT / 'setup.py').read_text())
    call = next(node for node in ast.walk(tree)
                if isinstance(node, ast.Call) and getattr(node.func, 'id', '') == 'setup')
    return {k.arg: k.value for k in call.keywords}


def console_scripts() -> dict[str, str]:
    entry_points = ast.literal_eval(setup_call()['entry_points'])
    return dict(line.replace(' ', '').split('=') for line in entry_points['console_scripts'])


def data_file_globs() -> dict[str, str]:
    """{install folder: glob pattern} for each (folder, glob(...)) of data_files."""
    out = {}
    for entry in setup_call()['data_files'].elts:
        folder, files = entry.elts
        if isinstance(files, ast.Call) and getattr(files.func, 'id', '') == 'glob':
            folder_name = eval(ast.unparse(folder), {'package_name': 'arm_control'})
            out[folder_name] = files.args[0].value
    return out


class Recorded:
    """A stand-in for a launch class: keeps what it was built with."""

    built: list = []            # every stand-in made since the fixture started

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs
        Recorded.built.append(self)


class LaunchConfiguration(Recorded):
    def perform(self, context):
        return context[self.args[0]]


LAUNCH_API = {
    'launch': ['LaunchDescription'],
    'launch.actions': ['DeclareLaunchArgument', 'OpaqueFunction', 'IncludeLaunchDescription',
                       'GroupAction', 'SetEnvironmentVariable', 'LogInfo', 'Shutdown'],
    'launch.conditions': ['IfCondition', 'UnlessCondition'],
    'launch.substitutions': ['LaunchConfiguration', 'PathJoinSubstitution', 'TextSubstitution',
                             'PythonExpression', 'EnvironmentVariable'],
    'launch_ros.actions': ['Node', 'PushRosNamespace'],
    'launch_ros.substitutions': ['FindPackageShare'],
}
ARM_YAML = str(ROOT / 'config' / 'arm.yaml')


@pytest.fixture
def launch_description(monkeypatch):
    for module_name, names in LAUNCH_API.items():
        module = types.ModuleType(module_name)
        for name in names:
            setattr(module, name, LaunchConfiguration if name == 'LaunchConfiguration'
                    else type(name, (Recorded,), {}))
        monkeypatch.setitem(sys.modules, module_name, module)
    monkeypatch.setitem(sys.modules, 'launch_ros', types.ModuleType('launch_ros'))
    spec = importlib.util.spec_from_file_location('arm_launch', LAUNCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.generate_launch_description()


def bring_up(launch_description, **arguments):
    """What the launch starts for these arguments (the rest at their defaults)."""
    (opaque,) = [e for e in launch_description.args[0]
                 if type(e).__name__ == 'OpaqueFunction']
    context = {'params_file': ARM_YAML, 'robot_params_file': '', 'namespace': '',
               'sim_speed': '0.0', **arguments}
    Recorded.built.clear()
    return opaque.kwargs['function'](context)


def nodes_of(actions):
    return [a for a in actions if type(a).__name__ == 'Node']


def test_launch_file_imports_only_the_real_launch_api():
    tree = ast.parse(LAUNCH.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0 \
                and node.module.split('.')[0] in ('launch', 'launch_ros'):
            assert node.module in LAUNCH_API, node.module
            for alias in node.names:
                assert alias.name in LAUNCH_API[node.module], (node.module, alias.name)


def test_launch_starts_sim_controller_planner_from_the_parameter_files(launch_description):
    entities = launch_description.args[0]
    declared = {e.args[0]: e.kwargs for e in entities
                if type(e).__name__ == 'DeclareLaunchArgument'}
    assert declared['robot_params_file']['default_value'] == ''
    assert declared['namespace']['default_value'] == ''
    scripts = console_scripts()
    nodes = [n for n in nodes_of(bring_up(launch_description))
             if n.kwargs['package'] == 'arm_control']
    for node in nodes:
        assert node.kwargs['executable'] in scripts, node.kwargs['executable']
        assert node.kwargs['parameters'] == [ARM_YAML]
    always = {n.kwargs['executable'] for n in nodes if n.kwargs.get('condition') is None}
    assert always == {'sim', 'controller', 'planner'}
    for node in nodes:
        condition = node.kwargs.get('condition')
        if condition is not None:
            (flag,) = condition.args
            assert flag.args[0] in declared and declared[flag.args[0]]['default_value'] == 'false'

    default = declared['params_file']['default_value']
    package, folder, name = default.args[0]
    assert package.args == ('arm_control',) and (folder, name) == ('config', 'arm.yaml')
    installed = data_file_globs()['share/arm_control/config']
    assert all(PurePath(f'config/{name}').match(installed)
               for name in ('arm.yaml', 'frc_robot.yaml', 'fastdds_localhost_udp.xml'))


def test_the_robot_file_comes_after_the_arm_file_for_every_node(launch_description, tmp_path):
    robot = tmp_path / 'robot.yaml'
    robot.write_text('/controller:\n  ros__parameters:\n    shoulder_pid: [60.0, 10.0, 4.0]\n')
    nodes = [n for n in nodes_of(bring_up(launch_description, robot_params_file=str(robot)))
             if n.kwargs['package'] == 'arm_control']
    assert len(nodes) == 6
    assert all(n.kwargs['parameters'] == [ARM_YAML, str(robot)] for n in nodes)


def test_robot_state_publisher_gets_the_urdf_of_the_files(launch_description, arm, tmp_path):
    (publisher,) = [n for n in nodes_of(bring_up(launch_description))
                    if n.kwargs['package'] == 'robot_state_publisher']
    assert publisher.kwargs['executable'] == 'robot_state_publisher'
    (parameters,) = publisher.kwargs['parameters']
    assert parameters['robot_description'] == arm_urdf(arm)
    (flag,) = publisher.kwargs['condition'].args
    assert flag.args == ('robot_state_publisher',)
    # a robot file that lengthens the forearm lengthens the URDF's
    robot = tmp_path / 'robot.yaml'
    robot.write_text('/**:\n  ros__parameters:\n    elbow:\n      length_m: 0.9\n')
    (publisher,) = [n for n in nodes_of(bring_up(launch_description,
                                                 robot_params_file=str(robot)))
                    if n.kwargs['package'] == 'robot_state_publisher']
    assert publisher.kwargs['parameters'][0]['robot_description'] == arm_urdf(
        with_joint(arm, 'elbow', length_m=0.9))


@pytest.mark.parametrize('robot_file, words', [
    ('/**:\n  ros__parameters:\n    shoulder:\n      mass_kg: -30.0\n',
     "parameter 'shoulder.mass_kg' = -30.0"),
    ('/planner:\n  ros__parameters:\n    grid_resolution_rad: fine\n',
     "parameter 'grid_resolution_rad' = 'fine'"),
    ('/recorder:\n  ros__parameters:\n    flush_period_s: -1.0\n',
     "parameter 'flush_period_s' = -1.0"),
    ('/**:\n  ros__parameters: [unclosed\n', 'cannot read parameter file'),
])
def test_a_bad_parameter_file_starts_no_node(launch_description, tmp_path, robot_file, words):
    robot = tmp_path / 'robot.yaml'
    robot.write_text(robot_file)
    with pytest.raises(parameters.ParameterError) as refused:
        bring_up(launch_description, robot_params_file=str(robot))
    assert words in str(refused.value) and str(robot) in str(refused.value)
    assert 'no node started' in str(refused.value)
    assert not [a for a in Recorded.built if type(a).__name__ == 'Node']


def test_a_missing_parameter_file_starts_no_node(launch_description, tmp_path):
    with pytest.raises(parameters.ParameterError,
                       match='cannot read parameter file .*absent.yaml'):
        bring_up(launch_description, params_file=str(tmp_path / 'absent.yaml'))
    assert not [a for a in Recorded.built if type(a).__name__ == 'Node']


def test_a_namespace_moves_every_node_and_its_parameter_sections(
        launch_description, tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, 'tempdir', str(tmp_path))     # where the copies go
    robot = tmp_path / 'robot.yaml'
    robot.write_text('/controller:\n  ros__parameters:\n    shoulder_pid: [60.0, 10.0, 4.0]\n')
    (group,) = bring_up(launch_description, namespace='arm1', robot_params_file=str(robot))
    assert type(group).__name__ == 'GroupAction'
    push, *nodes = group.args[0]
    assert type(push).__name__ == 'PushRosNamespace' and push.args == ('arm1',)
    arm_nodes = [n for n in nodes if n.kwargs['package'] == 'arm_control']
    assert len(arm_nodes) == 6
    files = arm_nodes[0].kwargs['parameters']
    assert all(n.kwargs['parameters'] == files for n in arm_nodes) and len(files) == 2
    assert all(Path(f).is_relative_to(tmp_path) for f in files)
    # the node in /arm1 gets from the copies what /controller got from the originals
    for node_name in ('controller', 'sim', 'planner'):
        moved, _ = node_parameters(files, f'arm1/{node_name}')
        original, _ = node_parameters([ARM_YAML, robot], node_name)
        assert moved == original
    assert node_parameters(files, 'arm1/controller')[0]['shoulder_pid'] == [60.0, 10.0, 4.0]


def test_a_sim_speed_reaches_the_sim_in_its_own_section(launch_description, tmp_path,
                                                        monkeypatch):
    """rcl takes a node's own section (/sim) over a /** one, and over -p, whatever the order:
    the speed given as a /** override left the sim in real time under ros2 launch. It comes
    in a last file's /sim section (/arm1/sim in a namespace); the other nodes follow /clock."""
    monkeypatch.setattr(tempfile, 'tempdir', str(tmp_path))
    for namespace in ('', 'arm1'):
        actions = bring_up(launch_description, sim_speed='4.0', namespace=namespace)
        nodes = actions[0].args[0][1:] if namespace else nodes_of(actions)
        by_name = {n.kwargs['executable']: n for n in nodes
                   if n.kwargs['package'] == 'arm_control'}
        section = f'/{namespace}/sim' if namespace else '/sim'
        files = by_name['sim'].kwargs['parameters']
        last = yaml.safe_load(Path(files[-1]).read_text())
        assert last == {section: {'ros__parameters': {'sim_time_factor': 4.0}}}
        assert node_parameters(files, section.strip('/'))[0]['sim_time_factor'] == 4.0
        for name in ('controller', 'planner'):
            assert {'use_sim_time': True} in by_name[name].kwargs['parameters']


def test_launch_and_urdf_files_are_installed_under_share(launch_description):
    globs = data_file_globs()
    assert LAUNCH.match(globs['share/arm_control/launch'])
    assert URDF.match(globs['share/arm_control/urdf'])
