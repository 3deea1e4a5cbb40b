"""The run plot shows what was recorded (bags and plot_run: test_bag.py)."""

import math
from pathlib import Path
import sys

from matplotlib import image
import numpy as np
import pytest

from arm_control.logs.recording import Recording, Sample
from arm_control.visual.plots import plot_run, state_spans, tracking_error
from arm_control.visual.scene import state_colour

ROOT = Path(__file__).resolve().parents[2]
STATES = ((0.0, 'waiting'), (0.5, 'planning'), (0.55, 'tracking'), (2.0, 'holding'))


def synthetic_run(lag_rad=0.1) -> list[Sample]:
    """A 3 s run at 50 Hz: the setpoint ramps, the arm lags it by ``lag_rad`` exactly."""
    samples = []
    for k in range(151):
        t = 100.0 + 0.02 * k
        setpoint = (0.5 + 0.3 * (t - 100.0), -1.0 + 0.2 * (t - 100.0))
        true = (setpoint[0] - lag_rad, setpoint[1] + lag_rad)
        state = next(name for start, name in reversed(STATES) if t - 100.0 >= start)
        samples.append(Sample(time_s=t, measured_rad=(true[0] + 0.001, true[1]), true_rad=true,
                              setpoint_rad=setpoint, voltage=(3.0, -2.0), state=state,
                              true_rad_s=(0.3, 0.2)))
    return samples


def test_states_are_kept_at_each_change_only():
    recording = Recording.from_samples(synthetic_run())
    states = recording.arrays('state')
    assert list(states['name']) == [name for _, name in STATES]
    assert states['time_s'] - 100.0 == pytest.approx([start for start, _ in STATES], abs=0.011)


def test_tracking_error_is_the_lag_between_setpoint_and_arm():
    recording = Recording.from_samples(synthetic_run(lag_rad=0.1))
    times, error = tracking_error(recording.arrays('setpoint'), recording.arrays('truth'))
    assert len(times) == 151
    assert error[:, 0] == pytest.approx(0.1) and error[:, 1] == pytest.approx(-0.1)


def test_tracking_error_interpolates_between_samples():
    setpoint = {'time_s': np.array([0.5, 1.5, 5.0]), 'position': np.zeros((3, 2))}
    actual = {'time_s': np.array([0.0, 1.0, 2.0]),
              'position': np.array([[0.0, 0.0], [1.0, -1.0], [3.0, -3.0]])}
    times, error = tracking_error(setpoint, actual)
    assert list(times) == [0.5, 1.5]                     # 5.0 is past the last sample
    assert error == pytest.approx(np.array([[-0.5, 0.5], [-2.0, 2.0]]))


def test_state_spans_run_to_the_next_change_and_the_last_to_the_end():
    assert state_spans([0.0, 1.0, 2.5], ['a', 'b', 'c'], 4.0) == [
        (0.0, 1.0, 'a'), (1.0, 2.5, 'b'), (2.5, 4.0, 'c')]
    assert state_spans([], [], 4.0) == []


def test_plot_shows_angles_error_voltage_and_states(tmp_path):
    recording = Recording.from_samples(synthetic_run(lag_rad=0.1))
    figure = plot_run(recording, tmp_path / 'run.png', title='synthetic')
    assert image.imread(tmp_path / 'run.png').shape[:2] == (760, 1000)
    angle_ax, error_ax, voltage_ax = figure.axes
    # the error panel's curves are the lag, in degrees, on a time axis from 0
    shoulder_error = error_ax.lines[0]
    assert shoulder_error.get_xdata()[0] == pytest.approx(0.0)
    assert shoulder_error.get_ydata() == pytest.approx(math.degrees(0.1))
    # setpoint drawn dashed beside the measured angle
    dashed = [line for line in angle_ax.lines if line.get_linestyle() == '--']
    assert len(dashed) == 2
    assert dashed[0].get_ydata()[-1] == pytest.approx(math.degrees(0.5 + 0.3 * 3.0))
    assert voltage_ax.lines[0].get_ydata() == pytest.approx(3.0)
    # one shaded span per state in each panel, in the state's colour, named over the top
    spans = voltage_ax.patches
    assert len(spans) == len(STATES)
    assert np.allclose([p.get_facecolor()[:3] for p in spans],
                       [[int(state_colour(n)[i:i + 2], 16) / 255 for i in (1, 3, 5)]
                        for _, n in STATES])
    labels = {t.get_text() for t in angle_ax.texts}
    assert {'waiting', 'tracking', 'holding'} <= labels      # 'planning' is too short to name


def test_plot_without_a_setpoint_says_so(tmp_path):
    samples = [Sample(time_s=0.02 * k, measured_rad=(0.1 * k, 0.0), voltage=(1.0, 0.0))
               for k in range(50)]
    figure = plot_run(Recording.from_samples(samples), tmp_path / 'run.png')
    assert 'no setpoint recorded' in [t.get_text() for t in figure.axes[1].texts]


def test_a_closed_loop_run_in_process_is_recorded_and_plotted(tmp_path):
    """The code path of the README's plot: controller, planner and plant in one process."""
    sys.path.insert(0, str(ROOT / 'scripts'))
    from readme_pictures import closed_loop_run, telling_frame
    run = closed_loop_run([], ['mid_score'], duration_s=6.0)
    (name, x, y, reached_s), = run.goals
    assert name == 'mid_score' and 0.0 < reached_s < 5.0
    recording = Recording.from_samples(run.samples)
    truth = recording.arrays('truth')
    assert truth['time_s'][-1] == pytest.approx(reached_s + 1.0, abs=0.03)
    states = list(recording.arrays('state')['name'])
    assert 'tracking' in states and states[-1] == 'holding'
    assert np.all(np.abs(recording.arrays('voltage')['value']) <= 12.0)
    figure = plot_run(recording, tmp_path / 'run.png')
    assert figure.axes[1].lines                  # a tracking error was drawn
    assert telling_frame(run).state == 'tracking'
