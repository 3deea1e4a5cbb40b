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
