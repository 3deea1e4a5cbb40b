"""Start the arm: sim, controller and planner, all reading one parameter file.

    ros2 launch arm_control arm.launch.py
    ros2 launch arm_control arm.launch.py params_file:=/path/to/frc_robot.yaml viewer:=true
    ros2 launch arm_control arm.launch.py robot_state_publisher:=true markers:=true   # RViz

Arguments: ``params_file`` (default: the installed share/arm_control/config/arm.yaml);
``viewer``, ``markers``, ``recorder``, ``robot_state_publisher`` (each false by default).
robot_state_publisher gets the URDF of the arm that ``params_file`` describes (the same
generator that wrote urdf/arm.urdf), so its links match the simulated ones.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

PACKAGE = 'arm_control'
OPTIONAL_NODES = ('viewer', 'markers', 'recorder')


def _arm_node(executable, condition=None):
    return Node(package=PACKAGE, executable=executable, name=executable,
                parameters=[LaunchConfiguration('params_file')], output='screen',
                emulate_tty=True, condition=condition)


def _robot_state_publisher(context):
    """robot_state_publisher with the URDF generated from ``params_file``."""
    from arm_control.config import ArmConfig
    from arm_control.parameters import read_parameter_files
    from arm_control.visual.urdf import arm_urdf
    params_file = LaunchConfiguration('params_file').perform(context)
    arm = ArmConfig.from_parameters(read_parameter_files([params_file], 'robot_state_publisher'))
    return [Node(package='robot_state_publisher', executable='robot_state_publisher',
                 name='robot_state_publisher', output='screen',
                 parameters=[{'robot_description': arm_urdf(arm)}],
                 condition=IfCondition(LaunchConfiguration('robot_state_publisher')))]


def generate_launch_description():
    arguments = [
        DeclareLaunchArgument(
            'params_file',
            default_value=PathJoinSubstitution([FindPackageShare(PACKAGE), 'config',
                                                'arm.yaml']),
            description='ROS parameter file describing the arm, its world and every node'),
        DeclareLaunchArgument('viewer', default_value='false',
                              description='start the viewer (a window, or PNG when headless)'),
        DeclareLaunchArgument('markers', default_value='false',
                              description='publish arm_markers (MarkerArray) for RViz'),
        DeclareLaunchArgument('recorder', default_value='false',
                              description='record the run for plot_run'),
        DeclareLaunchArgument('robot_state_publisher', default_value='false',
                              description='publish TF of the arm from joint_states and the URDF'),
    ]
    nodes = [_arm_node(executable) for executable in ('sim', 'controller', 'planner')]
    nodes += [_arm_node(executable, IfCondition(LaunchConfiguration(executable)))
              for executable in OPTIONAL_NODES]
    return LaunchDescription(arguments + nodes + [OpaqueFunction(function=_robot_state_publisher)])
