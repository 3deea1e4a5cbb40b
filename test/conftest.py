"""Shared fixtures: the default arm, its controller settings and planner, and isolated ROS
domains for process-level tests. The tests mirror the package: ``unit`` (pure modules),
``node`` (a node in process), ``process`` (installed nodes as processes over DDS),
``package`` (lint, docs, layers, the installed layout); what they share is in ``rigs``."""

import dataclasses
import os
from pathlib import Path
import sys

import pytest

from arm_control import config
from arm_control.planning.planner import Planner

sys.path.insert(0, str(Path(__file__).resolve().parent / 'rigs'))


@pytest.fixture(autouse=True)
def environment_kept():
    """Each test leaves this process's environment as it found it: one that starts rclpy the
    nodes' way sets Fast DDS variables in it (``use_udp_transport``), and the processes later
    tests start would inherit them."""
    saved = dict(os.environ)
    yield
    os.environ.clear()
    os.environ.update(saved)


@pytest.fixture(scope='session')
def arm() -> config.ArmConfig:
    return config.load('sim')[0]


@pytest.fixture(scope='module')
def controller_config():
    return config.load('controller')[1]


@pytest.fixture(scope='module')
def planner(arm):
    return Planner(arm, config.load('planner')[1])


@pytest.fixture
def controller(domain):
    """A controller node in process, constructed and not spun. At real-time priority it
    would raise this thread, pytest's, for every later test."""
    import rclpy
    from arm_control.nodes.controller import ControllerNode
    rclpy.init(args=['--ros-args', '-p', 'realtime_priority:=0'], domain_id=domain)
    node = None
    try:
        node = ControllerNode()
        yield node
    finally:
        if node is not None:
            node.loop.stop()
            node.plans.close()
            node.destroy_node()
        rclpy.try_shutdown()


@pytest.fixture(scope='module')
def frc():
    """The competition robot's arm and a planner on it at the file's resolution (1°)."""
    from planning_checks import FRC_FILE
    arm, planner_config = config.load('planner', FRC_FILE)
    return Planner(arm, planner_config)


def with_joint(arm, joint_name, **changes):
    """A copy of ``arm`` with fields of one joint changed."""
    joint = dataclasses.replace(getattr(arm, joint_name), **changes)
    return dataclasses.replace(arm, **{joint_name: joint})


@pytest.fixture
def domain():
    from ros_harness import ros_domain
    with ros_domain() as domain_id:
        yield domain_id


@pytest.fixture
def probe(domain):
    from ros_harness import Probe
    node = Probe(domain)
    yield node
    node.close()


@pytest.fixture
def launch(domain, tmp_path):
    """Start installed executables on the test's domain; all stopped at the end."""
    from ros_harness import NodeProcess
    started = []

    def start(name, *ros_args, environment=None):
        process = NodeProcess(name, domain, ros_args, tmp_path, environment)
        started.append(process)
        return process

    yield start
    for process in started:
        process.stop()


@pytest.fixture(scope='module')
def rig(request, tmp_path_factory):
    """sim, planner and controller as processes, shared by one module's tests, and a probe."""
    from arm_rig import ArmRig
    from ros_harness import Probe, ros_domain
    with ros_domain() as domain:
        probe = Probe(domain)
        rig = ArmRig(domain, probe, tmp_path_factory.mktemp(request.module.__name__))
        try:
            rig.start_all()
            rig.ready()
            yield rig
        finally:
            rig.close()
            probe.close()
