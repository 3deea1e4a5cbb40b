"""A node given a bad parameter refuses to start and names it."""

import pytest


@pytest.mark.parametrize('ros_args, named', [
    (('-p', 'shoulder.mass_kg:=-3.0'), "'shoulder.mass_kg' = -3.0: must be >= 0"),
    (('-p', 'elbow.gear_ratio:=0.0'), "'elbow.gear_ratio' = 0.0: must be > 0"),
    (('-p', 'publish_rate_hz:=fast'), "'publish_rate_hz' = 'fast': expected a number"),
])
def test_sim_refuses_a_bad_parameter(launch, ros_args, named):
    sim = launch('sim', *ros_args)
    assert sim.process.wait(timeout=30) != 0
    assert named in sim.output()


def test_sim_refuses_a_broken_parameter_file(launch, tmp_path):
    broken = tmp_path / 'broken.yaml'
    broken.write_text('/**:\n  ros__parameters:\n    shoulder:\n      mass_kg: [1, 2\n')
    sim = launch('sim', '--params-file', str(broken))
    assert sim.process.wait(timeout=30) != 0
    assert 'broken.yaml' in sim.output() or 'parse' in sim.output().lower()


# Parameter files for the controller and the planner: a bad value, a missing one (a list
# that names a parameter the file does not give), one given no value at all.
NODE_FILES = [
    ('controller', '/controller:\n  ros__parameters:\n    loop_rate_hz: -50.0\n',
     "'loop_rate_hz' = -50.0: must be > 0"),
    ('controller', '/controller:\n  ros__parameters:\n    max_velocity_rad_s: [3.0]\n',
     "'max_velocity_rad_s' = [3.0]: expected 2 numbers"),
    ('controller', '/controller:\n  ros__parameters:\n    planner_timeout_s:\n',
     "parameter 'planner_timeout_s' has no value"),
    ('controller',
     '/**:\n  ros__parameters:\n    world:\n      forbidden_regions: [floor, wall]\n',
     "parameter 'world.regions.wall' is missing"),
    ('planner', '/planner:\n  ros__parameters:\n    world:\n      check_step_rad: fine\n',
     "'world.check_step_rad' = 'fine': expected a number"),
    ('planner', '/planner:\n  ros__parameters:\n    check_step_rad: 0.001\n',
     "'check_step_rad' is not a parameter of arm_control (did you mean "
     "'world.check_step_rad'?)"),
    ('planner', '/**:\n  ros__parameters:\n    presets:\n      names: [stow, shelf]\n',
     "parameter 'presets.shelf' is missing"),
    ('planner', '/planner:\n  ros__parameters:\n    grid_resolution_rad:\n',
     "parameter 'grid_resolution_rad' has no value"),
]


@pytest.mark.parametrize('node, text, named', NODE_FILES,
                         ids=[f'{n}-{w.split(chr(39))[1]}' for n, _, w in NODE_FILES])
def test_controller_and_planner_refuse_a_bad_parameter_file(launch, tmp_path, node, text,
                                                            named):
    path = tmp_path / 'params.yaml'
    path.write_text(text)
    process = launch(node, '--params-file', str(path))
    assert process.process.wait(timeout=30) == 2
    assert named in process.output()
