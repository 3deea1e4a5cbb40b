"""Plots of a run: joint angles with the setpoint, tracking error and voltage against time,
the state machine's states shaded behind. Matplotlib (Agg), no ROS.

    from arm_control.visual.plots import plot_run
    plot_run(Recording.from_samples(samples), 'run.png')     # an in-process run
    ros2 run arm_control plot_run arm_run -o run.png         # a bag the recorder wrote
"""

import argparse
import math
from pathlib import Path
import sys

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
import numpy as np

from arm_control.logs.bag import BagError, load_run
from arm_control.logs.recording import Recording
from arm_control.visual.scene import state_colour

JOINT_COLOURS = ('#1971c2', '#e8590c')          # shoulder, elbow
JOINT_LABELS = ('shoulder', 'elbow')
MIN_LABELLED_SPAN = 0.04                        # fraction of the run a state needs for a label


def state_spans(times_s, names, end_s: float) -> list[tuple[float, float, str]]:
    """(start, end, state) for each stretch of one state; the last runs to ``end_s``."""
    times_s = list(times_s)
    return [(start, times_s[i + 1] if i + 1 < len(times_s) else max(end_s, start), name)
            for i, (start, name) in enumerate(zip(times_s, names))]


def tracking_error(setpoint: dict, actual: dict) -> tuple[np.ndarray, np.ndarray]:
    """(times, setpoint − actual (N, 2)) at the setpoint's times within the actual's span;
    the actual angle is interpolated linearly between its samples."""
    times = setpoint['time_s']
    if len(times) == 0 or len(actual['time_s']) < 2:
        return np.zeros(0), np.zeros((0, 2))
    inside = (times >= actual['time_s'][0]) & (times <= actual['time_s'][-1])
    times = times[inside]
    error = np.column_stack([
        setpoint['position'][inside, k] - np.interp(times, actual['time_s'],
                                                    actual['position'][:, k])
        for k in range(2)])
    return times, error


def plot_run(recording: Recording, path=None, *, title: str = '', max_voltage: float = 12.0,
             size_px=(1000, 760), dpi: float = 100.0) -> Figure:
    """Three panels sharing the time axis; written to ``path`` (PNG) when given."""
    figure = Figure(figsize=(size_px[0] / dpi, size_px[1] / dpi), dpi=dpi)
    FigureCanvasAgg(figure)
    angle_ax, error_ax, voltage_ax = figure.subplots(3, 1, sharex=True,
                                                     gridspec_kw={'height_ratios': (3, 2, 2)})
    start = recording.start_time_s()
    measured, truth = recording.arrays('measured'), recording.arrays('truth')
    setpoint, voltage = recording.arrays('setpoint'), recording.arrays('voltage')
    states = recording.arrays('state')
    end = max([start] + [d['time_s'][-1] for d in (measured, truth, setpoint, voltage, states)
                         if len(d['time_s'])])

    # Angles: what the sensors read, the true angle when known, and the setpoint.
    for k in range(2):
        colour, label = JOINT_COLOURS[k], JOINT_LABELS[k]
        if len(measured['time_s']):
            angle_ax.plot(measured['time_s'] - start, np.degrees(measured['position'][:, k]),
                          color=colour, linewidth=1.0, label=f'{label} measured')
        if len(truth['time_s']):
            angle_ax.plot(truth['time_s'] - start, np.degrees(truth['position'][:, k]),
                          color=colour, linewidth=0.8, alpha=0.5, label=f'{label} true')
        if len(setpoint['time_s']):
            angle_ax.plot(setpoint['time_s'] - start, np.degrees(setpoint['position'][:, k]),
                          color=colour, linewidth=1.4, linestyle='--',
                          label=f'{label} setpoint')
    angle_ax.set_ylabel('angle (deg)')
    angle_ax.legend(loc='best', fontsize=7, ncol=2)

    # Tracking error: against the true angle where the sim gave it, else the sensors.
    actual, against = (truth, 'true') if len(truth['time_s']) >= 2 else (measured, 'measured')
    times, error = tracking_error(setpoint, actual)
    if len(times):
        for k in range(2):
            error_ax.plot(times - start, np.degrees(error[:, k]), color=JOINT_COLOURS[k],
                          linewidth=1.0, label=JOINT_LABELS[k])
        error_ax.axhline(0.0, color='#868e96', linewidth=0.6)
        error_ax.legend(loc='best', fontsize=7)
    else:
        error_ax.text(0.5, 0.5, 'no setpoint recorded', transform=error_ax.transAxes,
                      ha='center', va='center', color='#868e96')
    error_ax.set_ylabel(f'setpoint − {against}\n(deg)')

    if len(voltage['time_s']):
        for k in range(2):
            voltage_ax.step(voltage['time_s'] - start, voltage['value'][:, k], where='post',
                            color=JOINT_COLOURS[k], linewidth=1.0, label=JOINT_LABELS[k])
        voltage_ax.legend(loc='best', fontsize=7)
    for limit in (-max_voltage, max_voltage):
        voltage_ax.axhline(limit, color='#c92a2a', linewidth=0.8, linestyle=':')
    voltage_ax.set_ylim(-1.15 * max_voltage, 1.15 * max_voltage)
    voltage_ax.set_ylabel('voltage (V)')
    voltage_ax.set_xlabel('time (s)')

    # The states: shaded in their colours behind every panel, named over the top one.
    duration = max(end - start, 1e-9)
    for span_start, span_end, name in state_spans(states['time_s'], states['name'], end):
        colour = state_colour(name)
        for ax in (angle_ax, error_ax, voltage_ax):
            ax.axvspan(span_start - start, span_end - start, color=colour, alpha=0.10,
                       linewidth=0, zorder=0)
            ax.axvline(span_start - start, color=colour, linewidth=0.8, alpha=0.7, zorder=1)
        if (span_end - span_start) / duration >= MIN_LABELLED_SPAN:
            angle_ax.text((span_start + span_end) / 2 - start, 1.01, name, color=colour,
                          transform=angle_ax.get_xaxis_transform(), ha='center',
                          va='bottom', fontsize=7, fontweight='bold', clip_on=False)
    for ax in (angle_ax, error_ax, voltage_ax):
        ax.grid(True, color='#e9ecef', linewidth=0.6)
        ax.tick_params(labelsize=8)
    voltage_ax.set_xlim(0.0, duration)
    if title:
        figure.suptitle(title, fontsize=11)
    figure.subplots_adjust(left=0.09, right=0.98, top=0.92 if title else 0.95, bottom=0.07,
                           hspace=0.12)
    if path is not None:
        figure.savefig(path, format='png', dpi=dpi)
    return figure


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        description='Plot a run the recorder node recorded (a rosbag2 bag) to a PNG.')
    parser.add_argument('bag', type=Path, help='the bag directory, or its .mcap file')
    parser.add_argument('-o', '--output', type=Path, default=None,
                        help='the PNG to write (default: the bag with .png)')
    parser.add_argument('--namespace', default=None,
                        help="the arm's namespace, when the bag holds several (/arm1)")
    parser.add_argument('--title', default='')
    args = parser.parse_args(argv)
    try:
        recording, notes = load_run(args.bag, args.namespace)
    except BagError as error:
        print(f'plot_run: {error}', file=sys.stderr)
        return 1
    for note in notes:
        print(f'plot_run: {note}', file=sys.stderr)
    if not len(recording):
        print(f'plot_run: {args.bag} holds no joint_states, setpoint, voltage_command or '
              'arm_state of the arm', file=sys.stderr)
        return 1
    output = args.output or args.bag.with_suffix('.png')
    plot_run(recording, output, title=args.title or args.bag.name)
    print(f'{output}: {len(recording)} samples over '
          f'{_duration(recording):.1f} s')
    return 0


def _duration(recording: Recording) -> float:
    ends = [recording.arrays(s)['time_s'] for s in ('measured', 'truth', 'setpoint', 'voltage')]
    last = max((t[-1] for t in ends if len(t)), default=recording.start_time_s())
    return last - recording.start_time_s() if math.isfinite(last) else 0.0


if __name__ == '__main__':
    sys.exit(main())
