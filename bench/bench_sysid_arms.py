"""System identification on arms unlike arm.yaml (bench/arms/*.yaml and the demo arm): what it
finds, what it refuses, and how well the file it writes predicts a fresh run.

For each arm, in simulated time (in-process on ``ArmPlant`` with sensor noise, as
``bench_sysid``): ``--runs`` identification runs exactly as the ``sysid`` node drives them,
each with its own multi-sine phases and sensor noise, each fitted, checked for what the data
identify and realised as the parameter file would be (unidentified parameters keep
arm.yaml's values). Then a fresh run the models never saw -- the controller's benchmark
suite on the true arm -- cut into 0.5 s windows (every ``STRIDE_S``), each predicted from
the true state at its start under the voltages the arm really got, by RK4 at 1 ms; the
error is the largest joint-angle error within the window.

It prints, per arm, each base parameter true against identified ±1σ (first run) and the
error in σ of every run, what was not written, and per run the window-prediction p95 of the
identified file beside the true and default (arm.yaml) ones.

    python bench/bench_sysid_arms.py [--runs 5] [--arms bench/arms/a.yaml ...] [--write-docs]
"""

import argparse
import dataclasses
import glob
from pathlib import Path
import sys

BENCH = Path(__file__).resolve().parent
sys.path[:0] = [str(BENCH), str(BENCH.parent)]

from bench_sysid import CONFIG, layered, predict_windows, run_suite  # noqa: E402
from bench_trajectory import SUITE  # noqa: E402
import docs_table  # noqa: E402
import numpy as np  # noqa: E402

from arm_control import config, parameters  # noqa: E402
from arm_control.planning.planner import Planner  # noqa: E402
from arm_control.sysid.fit import fit_log  # noqa: E402
from arm_control.sysid.quality import identified_values  # noqa: E402
from arm_control.sysid.regressor import (BASE_PARAMETERS, base_parameters,  # noqa: E402
                                         with_values)
from arm_control.sysid.settings import SysIdConfig  # noqa: E402
from arm_control.sysid.simulated import identification_run  # noqa: E402

STRIDE_S = 0.25
BAR_DEG = 0.2


def window_p95(model, traces):
    errors = np.concatenate([predict_windows(model, t, s, v[1:], s, stride_s=STRIDE_S)
                             for t, s, v in traces])
    return float(np.percentile(errors, 95))


def identify(truth, default, settings, run):
    """Run ``run`` of the bench (its multi-sine phases and sensor noise) on the true arm, as
    the node drives it, fitted and realised as the file would be: (identified arm, fit,
    quality, simulated run)."""
    simulated = identification_run(
        truth, default, dataclasses.replace(settings, random_seed=run), seed=200 + run)
    fit = fit_log(simulated.log, default, settings.smoothing_window_s,
                  settings.max_command_lag_s, settings.min_speed_rad_s)
    realisation, quality = identified_values(fit, default)
    return with_values(default, realisation.values), fit, quality, simulated


def one_arm(path, default, settings, runs, lines):
    truth = config.ArmConfig.from_parameters(layered(CONFIG / 'arm.yaml', path))
    controller_config = config.load('controller')[1]
    planner = Planner(truth, config.load('planner')[1])
    _, traces = run_suite(truth, truth, controller_config, planner, SUITE)
    true_p95, default_p95 = window_p95(truth, traces), window_p95(default, traces)
    fits, p95s, refused, times = [], [], [], []
    for run in range(runs):
        identified, fit, quality, simulated = identify(truth, default, settings, run)
        fits.append(fit)
        refused.append(quality.unidentified)
        times.append(simulated.arm_time_s)
        p95s.append(window_p95(identified, traces))
    true_values = base_parameters(truth)
    lines += [f'### {Path(path).name}', '',
              '| base parameter | true | identified ± 1σ (run 1) | error / σ, runs 1-'
              f'{runs} |', '|---|---|---|---|']
    for k, (name, unit, _) in enumerate(BASE_PARAMETERS):
        z = ' '.join(f'{(f.parameters[k] - true_values[k]) / f.standard_errors[k]:+.1f}'
                     for f in fits)
        lines.append(f'| {name} ({unit}) | {true_values[k]:.3f} | {fits[0].parameters[k]:.3f} '
                     f'± {fits[0].standard_errors[k]:.3f} | {z} |')
    lines += ['', '| run | arm time s | not written | p95 identified deg | p95 true deg | '
              'p95 default deg |', '|---|---|---|---|---|---|']
    for run in range(runs):
        lines.append(f'| {run + 1} | {times[run]:.1f} | {", ".join(refused[run]) or "-"} | '
                     f'{p95s[run]:.3f} | {true_p95:.3f} | {default_p95:.3f} |')
    z = np.array([(f.parameters - true_values) / f.standard_errors for f in fits])
    lines += ['', f'Within {BAR_DEG}° at p95 in {sum(p <= BAR_DEG for p in p95s)} of {runs} '
              f'runs; estimates within 2σ of the truth: {np.mean(np.abs(z) < 2):.0%}.', '']
    print('\n'.join(lines[-runs - 16:]), flush=True)
    return z


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=5)
    parser.add_argument('--arms', nargs='*', default=sorted(glob.glob(str(BENCH / 'arms' /
                                                                          '*.yaml')))
                        + [str(CONFIG / 'sysid_demo_arm.yaml')])
    parser.add_argument('--write-docs', action='store_true')
    args = parser.parse_args()
    default = config.ArmConfig.from_parameters(layered(CONFIG / 'arm.yaml'))
    settings = SysIdConfig.from_parameters(
        parameters.read_parameter_file(CONFIG / 'arm.yaml', 'sysid'))
    lines = [f'Each arm identified {args.runs} times (in-process, seeded), the written file '
             f'judged on 0.5 s windows of the controller suite on the true arm (every '
             f'{STRIDE_S:g} s, from the true state under the applied volts).', '']
    zs = [one_arm(path, default, settings, args.runs, lines) for path in args.arms]
    z = np.concatenate(zs)
    lines.append(f'Over every arm and run, {np.mean(np.abs(z) < 2):.1%} of the estimates lie '
                 f'within 2σ of the truth and {np.mean(np.abs(z) < 1):.1%} within 1σ '
                 '(honest σ: about 95 % and 68 %).')
    print(lines[-1])
    if args.write_docs:
        docs_table.write('sysid_arms', 'sysid on arms unlike arm.yaml',
                         'python bench/bench_sysid_arms.py ' + ' '.join(sys.argv[1:]),
                         '\n'.join(lines))


if __name__ == '__main__':
    main()
