from glob import glob

from setuptools import find_packages, setup

package_name = 'arm_control'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'bench']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/urdf', glob('urdf/*.urdf')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='arm_control maintainers',
    maintainer_email='arm-control@example.com',
    description='Simulation, planning and control of a two-joint FRC-style arm.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'sim = arm_control.nodes.sim:main',
            'controller = arm_control.nodes.controller_start:main',
            'planner = arm_control.nodes.planner:main',
            'tour = arm_control.nodes.tour:main',
            'viewer = arm_control.nodes.viewer:main',
            'markers = arm_control.nodes.markers:main',
            'recorder = arm_control.nodes.recorder:main',
            'plot_run = arm_control.visual.plots:main',
            'frc_bridge = arm_control.nodes.frc_bridge:main',
            'frc_robot_sim = arm_control.frc.robot_sim:main',
            'sysid = arm_control.nodes.sysid:main',
            'arm = arm_control.nodes.arm_cli:entry',
        ],
    },
)
