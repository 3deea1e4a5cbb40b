"""System identification on the sim's demo arm: what it finds, how well it predicts, and what
it is worth to the controller.

The true arm is ``config/arm.yaml`` with ``config/sysid_demo_arm.yaml`` layered over it (a
22 kg forearm with its centre of mass at 0.55 m instead of 15 kg at 0.4 m, and viscous and
Coulomb friction on both joints); the robot file the identification starts from, and the
"default" model below, is ``arm.yaml`` alone. In simulated time, in-process on ``ArmPlant``
with sensor noise, physics on 1 ms steps:

1. the identification run, exactly as the ``sysid`` node drives it (``Session``: stage 1
   with the file's model, a fit, stage 2 with the fitted one) at 50 Hz, and the fit of its
   log; its arm time. The base parameters, true against identified ±1σ.
2. prediction: windows of 0.5 s, every 0.1 s, of two fresh runs the model never saw -- a
   second identification-style run (other multi-sine phases and sensor noise) and the
   controller's benchmark suite on the true arm -- each predicted from the true state at
   its start with the voltages the arm really got; the error is the largest joint-angle
   error within the window. Also from the state the sensors give (Savitzky-Golay smoothed
   potentiometers, as a user would start a prediction): the true model's error then is
   the sensors'.
3. the controller (``ArmController`` with the planner, as in ``bench_controller``) running
   the benchmark suite on the true arm with the true, the identified and the default
   parameter file: move time, final error 1 s after arriving, overshoot, lowest point.

    python bench/bench_sysid.py                   # all three
    python bench/bench_sysid.py --file /tmp/arm_sysid/identified_params.yaml
                                                  # ... with a file from a run of the node
    python bench/bench_sysid.py --no-controller   # 1 and 2 only
    python bench/bench_sysid.py --seeds 12 [--write-docs]  # only: is the stated ±1σ honest?
"""

from dataclasses import replace
import math
from pathlib import Path
import sys
import time

BENCH = Path(__file__).resolve().parent
sys.path[:0] = [str(BENCH), str(BENCH.parent)]       # the suites beside, the package above

from bench_trajectory import _start_configuration, Move, SUITE  # noqa: E402
import docs_table  # noqa: E402
import in_process  # noqa: E402
import numpy as np  # noqa: E402
from scipy.signal import savgol_filter  # noqa: E402

from arm_control import config, parameters  # noqa: E402
from arm_control.control.controller import ArmController  # noqa: E402
from arm_control.model.dynamics import ArmDynamics, rk4  # noqa: E402
from arm_control.model.world import ForbiddenSpace  # noqa: E402
from arm_control.planning.planner import Planner  # noqa: E402
from arm_control.sysid.fit import fit_log  # noqa: E402
from arm_control.sysid.regressor import (BASE_PARAMETERS, base_parameters,  # noqa: E402
                                         realise, with_values)
from arm_control.sysid.settings import SysIdConfig  # noqa: E402
from arm_control.sysid.simulated import identification_run  # noqa: E402

CONFIG = BENCH.parent / 'config'
WINDOW_S = 0.5
STRIDE_S = 0.1
PHYSICS_S = 0.001


def layered(*paths, node='sim'):
    """The flat parameters of ``paths`` layered in order, as --params-file does."""
    params = {}
    for path in paths:
        params.update(parameters.read_parameter_file(path, node))
    return params


def arms(identified_file=None):
    default = config.ArmConfig.from_parameters(layered(CONFIG / 'arm.yaml'))
    truth = config.ArmConfig.from_parameters(
        layered(CONFIG / 'arm.yaml', CONFIG / 'sysid_demo_arm.yaml'))
    identified = None
    if identified_file:
        identified = config.ArmConfig.from_parameters(
            layered(CONFIG / 'arm.yaml', identified_file))
    return default, truth, identified


# --- prediction -------------------------------------------------------------------------

def predict_windows(arm, times_s, states, voltages, starts, window_s=WINDOW_S,
                    stride_s=STRIDE_S):
    """Largest joint error (deg) in each window, the model integrated by RK4 at 1 ms from
    ``starts[k]`` (a state) at sample k of ``times_s``, with the voltage applied then.

    ``voltages[i]`` is the voltage held over (times_s[i], times_s[i] + step)."""
    dynamics = ArmDynamics(arm)
    step = float(np.median(np.diff(times_s)))
    substeps = max(1, int(round(step / PHYSICS_S)))
    length = int(round(window_s / step))
    stride = max(1, int(round(stride_s / step)))
    errors = []
    for k in range(0, min(len(times_s), len(voltages) + 1) - length, stride):
        x = list(starts[k])
        worst = 0.0
        for i in range(k, k + length):
            for _ in range(substeps):
                x = rk4(dynamics.derivative, x, voltages[i], step / substeps)
            worst = max(worst, float(np.max(np.abs(np.array(x[:2]) - states[i + 1][:2]))))
        errors.append(math.degrees(worst))
    return np.array(errors)


def sensed_states(times_s, positions, window_s=0.3):
    """[θ, θ̇] from the potentiometers, Savitzky-Golay smoothed (cubic, zero-phase)."""
    step = float(np.median(np.diff(times_s)))
    window = int(round(window_s / step)) | 1
    q = savgol_filter(positions, window, 3, axis=0)
    qd = savgol_filter(positions, window, 3, deriv=1, delta=step, axis=0)
    return np.hstack([q, qd])


# --- the controller on the true arm -----------------------------------------------------

def run_suite(controller_arm, truth, controller_config, planner, moves):
    """Each move: the controller with ``controller_arm`` on the true arm, measured; and the
    trace (times, true states, applied voltages), 1 ms apart."""
    rows, traces = [], []
    forbidden = ForbiddenSpace(truth)
    for name, start_xy, goal_xy in moves:
        index = SUITE.index((name, start_xy, goal_xy))
        move = Move(name, start_xy, goal_xy, truth, controller_config, None, forbidden, None)
        start_q = _start_configuration(move)
        core = ArmController(controller_arm, controller_config)
        hand_off = in_process.PlanHandOff(core, planner)
        record = in_process.simulate(
            controller_arm, controller_config, in_process.TimedCore(core),
            lambda t: core.submit_goal(t, *goal_xy), start_q, index, hand_off, plant_arm=truth)
        last = core.last_step
        goal_q = last.goal_q if last and last.goal_q is not None else np.full(2, np.nan)
        rows.append((name, in_process.measure(truth, controller_config, record, goal_q, start_q)))
        traces.append(tuple(np.array(record[key]) for key in ('time', 'state', 'voltage')))
    return rows, traces


def fmt(value, spec='.2f'):
    return 'n/a' if value is None or not math.isfinite(value) else format(value, spec)


def coverage(truth, default, settings, seeds):
    """Identify the demo arm with ``seeds`` sensor-noise seeds: how far each estimate falls
    from the truth in its own σ, and how the estimates spread against the σ stated."""
    estimates, sigmas = [], []
    for seed in range(seeds):
        run = identification_run(truth, default, settings, seed=100 + seed)
        fit = fit_log(run.log, default, settings.smoothing_window_s,
                      settings.max_command_lag_s, settings.min_speed_rad_s)
        estimates.append(fit.parameters)
        sigmas.append(fit.standard_errors)
    estimates, sigmas = np.array(estimates), np.array(sigmas)
    z = (estimates - base_parameters(truth)) / sigmas
    lines = [f'{seeds} identification runs of the demo arm (sensor-noise seeds 100 to '
             f'{99 + seeds}):', '',
             '| base parameter | largest error / σ | mean error / σ | spread / mean σ |',
             '|---|---|---|---|']
    for k, (name, unit, _) in enumerate(BASE_PARAMETERS):
        lines.append(f'| {name} ({unit}) | {np.max(np.abs(z[:, k])):.1f} | '
                     f'{np.mean(z[:, k]):+.2f} | '
                     f'{np.std(estimates[:, k]) / np.mean(sigmas[:, k]):.2f} |')
    lines.append(f'\nWithin 2σ of the truth: {np.mean(np.abs(z) < 2):.1%}; within 1σ: '
                 f'{np.mean(np.abs(z) < 1):.1%}.')
    print('\n'.join(lines))
    return '\n'.join(lines)


def main(argv):
    file = argv[argv.index('--file') + 1] if '--file' in argv else None
    default, truth, identified = arms(file)
    settings = SysIdConfig.from_parameters(
        parameters.read_parameter_file(CONFIG / 'arm.yaml', 'sysid'))
    if '--seeds' in argv:
        table = coverage(truth, default, settings, int(argv[argv.index('--seeds') + 1]))
        if '--write-docs' in argv:
            docs_table.write('bench_sysid_seeds', 'System identification: is the stated σ '
                             'honest?', 'python bench/bench_sysid.py ' + ' '.join(argv), table)
        return
    # 1. identification
    began = time.process_time()
    run = identification_run(truth, default, settings, seed=0)
    run_cpu = time.process_time() - began
    began = time.process_time()
    fit = fit_log(run.log, default, settings.smoothing_window_s, settings.max_command_lag_s,
                  settings.min_speed_rad_s)
    fit_cpu = time.process_time() - began
    if identified is None:
        identified = with_values(default, realise(fit.parameters, default).values)
    print(f'Identification run on the demo arm: {run.arm_time_s:.1f} s of arm time '
          f'(simulated in {run_cpu:.1f} s CPU), fit in {fit_cpu:.1f} s CPU; command lag '
          f'{1000 * fit.lag_s:+.1f} ± {1000 * fit.lag_sigma_s:.1f} ms; residual RMS '
          f'{fit.residual_rms_v[0]:.3f} / {fit.residual_rms_v[1]:.3f} V.')
    print('Excitation: ' + '; '.join(run.session.notes))
    truth_forbidden = ForbiddenSpace(truth)
    entered = int(np.sum(~truth_forbidden.is_free(run.true_state[:, :2])))
    print(f'True samples of the run in forbidden space: {entered} of {len(run.true_state)}.')
    true_values, file_values = base_parameters(truth), base_parameters(default)
    print('\n| base parameter | true | identified ± 1σ | error / σ | default file |')
    print('|---|---|---|---|---|')
    for k, (name, unit, _) in enumerate(BASE_PARAMETERS):
        sigma = fit.standard_errors[k]
        print(f'| {name} ({unit}) | {true_values[k]:.3f} | {fit.parameters[k]:.3f} ± '
              f'{sigma:.3f} | {(fit.parameters[k] - true_values[k]) / sigma:+.1f} | '
              f'{file_values[k]:.3f} |')
    if file:
        print(f'\n(the rows below use {file})')

    # 2. prediction
    fresh = identification_run(truth, default, replace(settings, random_seed=1), seed=99)
    controller_config = config.load('controller')[1]
    planner = Planner(truth, config.load('planner')[1])
    moves = SUITE
    suite_rows, traces = run_suite(truth, truth, controller_config, planner, moves)
    tests = [('fresh excitation, 50 Hz', fresh.log.joint_time_s, fresh.true_state,
              fresh.log.voltage_v, fresh.log.position_rad)]
    tests.append(('controller suite, 1 ms', None, traces, None, None))
    print(f'\nPrediction error of {WINDOW_S:g} s windows (deg, the largest joint error in '
          'each window): p50 / p95 / max')
    print('| run | start | true model | identified | default file |')
    print('|---|---|---|---|---|')
    models = (('true', truth), ('identified', identified), ('default', default))
    for name, t, states, volts, positions in tests:
        for start in ('true state', 'sensed state'):
            if states is traces and start == 'sensed state':
                continue                    # the suite's trace holds no sensor readings
            cells = []
            for _, model in models:
                if states is traces:
                    # The trace's voltage i drove the step that ended at state i.
                    errors = np.concatenate([predict_windows(model, tt, ss, vv[1:], ss)
                                             for tt, ss, vv in traces])
                else:
                    starts = states if start == 'true state' else sensed_states(t, positions)
                    errors = predict_windows(model, t, states, volts, starts)
                p50, p95 = np.percentile(errors, [50, 95])
                cells.append(f'{p50:.3f} / {p95:.3f} / {np.max(errors):.3f}')
            print(f'| {name} | {start} | ' + ' | '.join(cells) + ' |')

    # 3. the controller
    if '--no-controller' in argv:
        return
    results = {'true': suite_rows}
    for name, model in models[1:]:
        results[name] = run_suite(model, truth, controller_config, planner, moves)[0]
    print('\nThe controller on the true arm with each parameter file: move time s, final '
          'error deg (1 s after arriving), overshoot deg, lowest point mm')
    print('| move | time true / identified / default | final error | overshoot | lowest |')
    print('|---|---|---|---|---|')
    for k, (name, _, _) in enumerate(moves):
        runs = [results[m][k][1] for m in ('true', 'identified', 'default')]
        print(f'| {name} | ' + ' | '.join(
            ' / '.join(fmt(getattr(r, field), spec) if field != 'lowest_m'
                       else fmt(1000 * r.lowest_m, '.0f') for r in runs)
            for field, spec in (('move_s', '.3f'), ('final_error_deg', '.2f'),
                                ('overshoot_deg', '.2f'), ('lowest_m', '.0f'))) + ' |')
    for model in ('true', 'identified', 'default'):
        runs = [r for _, r in results[model]]
        reached = [r for r in runs if r.reached]
        total = sum(r.move_s for r in reached)
        print(f'{model}: reached {len(reached)}/{len(runs)}, total move time {total:.2f} s, '
              f'worst final error {max((r.final_error_deg for r in runs), default=math.nan):.2f}'
              f' deg, worst overshoot {max((r.overshoot_deg for r in reached), default=0):.2f}'
              f' deg, floor contact {sum(r.lowest_m < 0 for r in runs)}')


if __name__ == '__main__':
    main(sys.argv[1:])
