"""Start the arm: sim, controller and planner, all reading the same parameter files.

    ros2 launch arm_control arm.launch.py
    ros2 launch arm_control arm.launch.py params_file:=/path/to/frc_robot.yaml viewer:=true
    ros2 launch arm_control arm.launch.py robot_params_file:=/path/to/our_robot.yaml
    ros2 launch arm_control arm.launch.py namespace:=arm1        # a second arm: arm2
    ros2 launch arm_control arm.launch.py robot_state_publisher:=true markers:=true   # RViz
    ros2 launch arm_control arm.launch.py sim_speed:=5.0     # simulated time, 5x real time

Arguments: ``params_file`` (default: the installed share/arm_control/config/arm.yaml);
``robot_params_file`` (default none), an overlay given to every node after it, naming only
what differs; ``namespace`` (default none) for all the arm's nodes; ``sim_speed`` (default 0:
real time) runs the sim on simulated time that many times faster, every node following its
``/clock`` (``use_sim_time``); ``viewer``, ``markers``, ``recorder``,
``robot_state_publisher`` (each false by default).

The files are read and checked before anything starts: a missing or unreadable file, or a
bad parameter, stops the launch with an error naming the file and the parameter (exit code
1), and no node starts.
robot_state_publisher gets the URDF of the arm the files describe (the same generator that
wrote urdf/arm.urdf), so its links match the simulated ones.
"""

from pathlib import Path
import tempfile

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, GroupAction, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node, PushRosNamespace
from launch_ros.substitutions import FindPackageShare

PACKAGE = 'arm_control'
SYSTEM_NODES = ('sim', 'controller', 'planner')
OPTIONAL_NODES = ('viewer', 'markers', 'recorder')


def _bring_up(context):
    """Check the parameter files, then the nodes; or a logged reason and no node at all."""
    from arm_control.bringup import check_parameter_files, namespaced_parameter_files
    from arm_control.parameters import ParameterError
    from arm_control.visual.urdf import arm_urdf

    files = [LaunchConfiguration('params_file').perform(context)]
    overlay = LaunchConfiguration('robot_params_file').perform(context)
    if overlay:
        files.append(overlay)
    namespace = LaunchConfiguration('namespace').perform(context).strip('/')
    speed = LaunchConfiguration('sim_speed').perform(context)
    try:
        speed = float(speed)
        if not 0.0 <= speed <= 100.0:
            raise ValueError('not in [0, 100]')
    except ValueError as error:
        raise ValueError(f'arm_control: no node started: sim_speed = {speed!r}: expected a '
                         f'number from 0 (real time) to 100 ({error})') from error
    clock = [{'use_sim_time': True}] if speed > 0.0 else []
    try:
        arm = check_parameter_files(files)
        folder = Path(tempfile.mkdtemp(prefix='arm_control_')) if speed > 0.0 or namespace \
            else None
        if speed > 0.0:
            # In a file, in the sim's own section: neither a /** file (a dict here) nor -p
            # overrides the sim's section of arm.yaml, and the sim had run in real time.
            files.append(folder / 'sim_speed.yaml')
            files[-1].write_text(f'/sim:\n  ros__parameters:\n    sim_time_factor: {speed}\n')
        if namespace:
            files = namespaced_parameter_files(files, namespace, folder)
    except (ParameterError, OSError) as error:
        # ros2 launch logs it as an error and exits with 1, before any node has started.
        raise ParameterError(f'arm_control: no node started: {error}') from error

    def arm_node(executable, condition=None):
        own = [] if executable == 'sim' else clock
        return Node(package=PACKAGE, executable=executable, name=executable,
                    parameters=[str(path) for path in files] + own, output='screen',
                    emulate_tty=True, condition=condition)

    nodes = [arm_node(executable) for executable in SYSTEM_NODES]
    nodes += [arm_node(executable, IfCondition(LaunchConfiguration(executable)))
              for executable in OPTIONAL_NODES]
    nodes.append(Node(package='robot_state_publisher', executable='robot_state_publisher',
                      name='robot_state_publisher', output='screen',
                      parameters=[{'robot_description': arm_urdf(arm)}] + clock,
                      condition=IfCondition(LaunchConfiguration('robot_state_publisher'))))
    if namespace:
        return [GroupAction([PushRosNamespace(namespace)] + nodes)]
    return nodes


def generate_launch_description():
    arguments = [
        DeclareLaunchArgument(
            'params_file',
            default_value=PathJoinSubstitution([FindPackageShare(PACKAGE), 'config',
                                                'arm.yaml']),
            description='ROS parameter file describing the arm, its world and every node'),
        DeclareLaunchArgument(
            'robot_params_file', default_value='',
            description='a second parameter file, applied after params_file to every node: '
                        'only what this robot changes'),
        DeclareLaunchArgument('namespace', default_value='',
                              description="namespace of all the arm's nodes and topics"),
        DeclareLaunchArgument('sim_speed', default_value='0.0',
                              description='0: real time; > 0: simulated time (/clock from the '
                                          'sim), this many times faster, use_sim_time everywhere'),
        DeclareLaunchArgument('viewer', default_value='false',
                              description='start the viewer (a window, or PNG when headless)'),
        DeclareLaunchArgument('markers', default_value='false',
                              description='publish arm_markers (MarkerArray) for RViz'),
        DeclareLaunchArgument('recorder', default_value='false',
                              description='record the run as a rosbag2 bag (MCAP)'),
        DeclareLaunchArgument('robot_state_publisher', default_value='false',
                              description='publish TF of the arm from joint_states and the URDF'),
    ]
    return LaunchDescription(arguments + [OpaqueFunction(function=_bring_up)])
