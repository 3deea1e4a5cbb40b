"""The installed layout `ros2 run` and `ros2 launch` rely on, checked directly."""

import os
from pathlib import Path
import subprocess
import xml.etree.ElementTree as ElementTree

from catkin_pkg.package import parse_package
import pytest
from ros_harness import install_prefix

SOURCE = Path(__file__).resolve().parents[2]
EXECUTABLES = ('sim', 'controller', 'planner')


@pytest.fixture(scope='module')
def prefix():
    return install_prefix()


def test_package_xml_parses_as_ament_python_format_3():
    package = parse_package(SOURCE / 'package.xml')
    assert package.name == 'arm_control'
    assert package.package_format == 3
    assert package.get_build_type() == 'ament_python'
    depends = {d.name for d in package.exec_depends}
    assert {'rclpy', 'sensor_msgs', 'std_msgs', 'std_srvs', 'geometry_msgs', 'nav_msgs',
            'diagnostic_msgs'} <= depends


def test_colcon_sees_a_ros_ament_python_package():
    listing = subprocess.run(['colcon', 'list', '--base-paths', str(SOURCE)],
                             capture_output=True, text=True, check=True).stdout
    assert 'arm_control' in listing and '(ros.ament_python)' in listing


@pytest.mark.parametrize('name', EXECUTABLES)
def test_executables_sit_where_ros2_run_looks(prefix, name):
    executable = prefix / 'lib' / 'arm_control' / name
    assert executable.is_file() and os.access(executable, os.X_OK)


def test_ament_index_marker_and_share_files(prefix):
    assert (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
            / 'arm_control').is_file()
    share = prefix / 'share' / 'arm_control'
    assert ElementTree.parse(share / 'package.xml').getroot().find('name').text == 'arm_control'
    installed = {p.name for p in (share / 'config').glob('*.yaml')}
    assert {p.name for p in (SOURCE / 'config').glob('*.yaml')} <= installed
    assert (share / 'launch' / 'arm.launch.py').is_file()


def test_installed_parameter_file_is_the_default(prefix):
    from arm_control.parameters import default_parameter_file
    assert default_parameter_file() == prefix / 'share' / 'arm_control' / 'config' / 'arm.yaml'
