"""What identification hands back: the parameter overlay, the report and the plot.

``identified_params.yaml`` names only the parameters identification sets (each link's mass,
centre of mass and inertia, and each joint's viscous and Coulomb friction), in the ROS
parameter-file format under ``/**``, each with its ±1σ in the line's comment, so it layers
over the robot file: ``--params-file arm.yaml --params-file identified_params.yaml``.
The uncertainty of a physical value is the base parameters' covariance carried through
``realise`` (its Jacobian, by central differences).
"""

from dataclasses import dataclass
import math
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
import numpy as np

from arm_control.config import ArmConfig
from arm_control.sysid.fit import fit_log, FitResult
from arm_control.sysid.log import Log
from arm_control.sysid.quality import identified_values, Quality
from arm_control.sysid.regressor import (BASE_PARAMETERS, base_parameters, Realisation,
                                         RealisationError, realise)
from arm_control.sysid.settings import SysIdConfig

# (parameter, unit) in the order written, per joint.
PHYSICAL = (('mass_kg', 'kg'), ('com_from_joint_m', 'm'), ('inertia_about_com_kgm2', 'kg m^2'),
            ('viscous_friction_nm_s_per_rad', 'N m s/rad'), ('coulomb_friction_nm', 'N m'))
JOINT_COLOURS = ('#1971c2', '#e8590c')          # shoulder, elbow, as in the run plots


def physical_uncertainty(parameters, covariance, nominal: ArmConfig) -> dict:
    """1σ of each realised value: J·Σ·Jᵀ with J = ∂realise/∂π by central differences."""
    parameters = np.asarray(parameters, float)
    names = list(realise(parameters, nominal).values)
    jacobian = np.zeros((len(names), len(parameters)))
    for k in range(len(parameters)):
        step = 1e-6 * max(abs(parameters[k]), 1e-3)
        try:
            up = realise(parameters + step * np.eye(len(parameters))[k], nominal).values
            down = realise(parameters - step * np.eye(len(parameters))[k], nominal).values
        except RealisationError:
            return {name: math.nan for name in names}
        jacobian[:, k] = [(up[n] - down[n]) / (2.0 * step) for n in names]
    spread = np.sqrt(np.maximum(np.diag(jacobian @ covariance @ jacobian.T), 0.0))
    return dict(zip(names, spread))


def _number(value: float, sigma: float = math.nan) -> str:
    """``value`` to the second significant digit of ``sigma`` (at least three digits);
    with no ``sigma`` given, two significant digits (for a σ itself)."""
    if not math.isfinite(value):
        return str(value)
    if math.isnan(sigma):
        return f'{value:.2g}'
    digits = 3
    if math.isfinite(sigma) and sigma > 0.0:
        digits = max(digits, int(math.floor(math.log10(abs(value) or 1.0)))
                     - int(math.floor(math.log10(sigma))) + 2)
    return f'{value:.{min(digits, 10)}g}'


def overlay_yaml(realisation: Realisation, fit: FitResult, nominal: ArmConfig,
                 source: str) -> str:
    """``identified_params.yaml``: only the identified parameters, ±1σ in the comments."""
    sigma = physical_uncertainty(fit.parameters, fit.covariance, nominal)
    lines = [
        f'# Identified by arm_control sysid from {source}',
        f'# ({fit.samples} samples over {fit.duration_s:.1f} s, command lag '
        f'{1000 * fit.lag_s:+.0f} ms). Layer it over the robot file:',
        '#   --params-file arm.yaml --params-file identified_params.yaml',
        '# Motion sees eight base parameters (identified, +/- 1 sigma):',
    ]
    for (name, unit, meaning), value, spread in zip(BASE_PARAMETERS, fit.parameters,
                                                    fit.standard_errors):
        lines.append(f'#   {name}: {_number(value, spread)} +/- {_number(spread)} {unit}'
                     f'  ({meaning})')
    lines += [
        '# Masses, centres of mass and inertias below realise them exactly, with each link',
        "# keeping the robot file's radius of gyration about its centre of mass (I/m):",
        "# motion cannot tell a link's mass from where its centre of mass is.",
    ]
    lines += [f'# Note: {note}' for note in realisation.notes]
    lines += ['', '/**:', '  ros__parameters:']
    for joint in ('shoulder', 'elbow'):
        if not any(name.startswith(joint + '.') for name in realisation.values):
            continue
        lines.append(f'    {joint}:')
        for field, unit in PHYSICAL:
            name = f'{joint}.{field}'
            if name not in realisation.values:
                continue
            value, spread = realisation.values[name], sigma.get(name, math.nan)
            text = f'      {field}: {value:.6g}'       # enough digits to give π back
            lines.append(f'{text:<46}# +/- {_number(spread)} {unit} (1 sigma)')
    return '\n'.join(lines) + '\n'


def report_markdown(fit: FitResult, realisation: Realisation | None, nominal: ArmConfig,
                    source: str, notes=(), truth: ArmConfig | None = None,
                    quality: Quality | None = None) -> str:
    """The fit in words and tables: parameters ±1σ beside the robot file's, the residuals."""
    file_values = base_parameters(nominal)
    true_values = base_parameters(truth) if truth is not None else None
    estimator = ('instrumental variables from the logged plan' if fit.instrumented else
                 'least squares: the log holds no plan (/sysid/reference), and in closed loop '
                 'the sensor noise pulls the inertias low')
    lines = [f'# System identification: {source}', '',
             f'{fit.samples} samples over {fit.duration_s:.1f} s; command-to-motion lag '
             f'{1000 * fit.lag_s:+.1f} ± {1000 * fit.lag_sigma_s:.1f} ms; condition number of '
             f'the (column-scaled) regressor {fit.condition_number:.1f}; {estimator}.', '',
             '## Base parameters', '',
             '| parameter | what | robot file | identified | ±1σ | σ/value | 2σ torque share '
             '| pinned down |' + (' true |' if truth is not None else ''),
             '|---|---|---|---|---|---|---|---|' + ('---|' if truth is not None else '')]
    for k, (name, unit, meaning) in enumerate(BASE_PARAMETERS):
        known = ('—' if quality is None else
                 f'{quality.relative_sigma[k]:.1%} | {quality.torque_share[k]:.2%} | '
                 + ('yes' if quality.identified[k] else '**no**'))
        row = (f'| `{name}` ({unit}) | {meaning} | {_number(file_values[k], 0.0)} | '
               f'{_number(fit.parameters[k], fit.standard_errors[k])} | '
               f'{_number(fit.standard_errors[k])} | {known} |')
        if true_values is not None:
            row += f' {_number(true_values[k], 0.0)} |'
        lines.append(row)
    lines += ['', '## Residuals', '',
              '| joint | residual RMS (V) | residual RMS (N m) | voltage spread (V) | '
              'explained |', '|---|---|---|---|---|']
    for j, name in enumerate(('shoulder', 'elbow')):
        explained = 1.0 - (fit.residual_rms_v[j] / fit.measured_rms_v[j]) ** 2
        lines.append(f'| {name} | {fit.residual_rms_v[j]:.3f} | {fit.residual_rms_nm[j]:.2f} '
                     f'| {fit.measured_rms_v[j]:.2f} | {100 * explained:.2f} % |')
    if realisation is not None:
        sigma = physical_uncertainty(fit.parameters, fit.covariance, nominal)
        lines += ['', '## Written to identified_params.yaml', '',
                  '| parameter | robot file | identified | ±1σ |', '|---|---|---|---|']
        for name, value in realisation.values.items():
            joint, field = name.split('.')
            before = getattr(getattr(nominal, joint), field)
            lines.append(f'| `{name}` | {_number(before, 0.0)} | '
                         f'{_number(value, sigma[name])} | {_number(sigma[name])} |')
        notes = list(notes) + list(realisation.notes)
    if notes:
        lines += ['', '## Notes', ''] + [f'- {note}' for note in notes]
    return '\n'.join(lines) + '\n'


def plot_fit(fit: FitResult, path, *, title: str = '', size_px=(1100, 760),
             dpi: float = 100.0) -> Figure:
    """Per joint: the (filtered) voltage the arm got, the identified model's prediction and
    the robot file's, against time; below, the identified model's residual."""
    figure = Figure(figsize=(size_px[0] / dpi, size_px[1] / dpi), dpi=dpi)
    FigureCanvasAgg(figure)
    axes = figure.subplots(3, 1, sharex=True, gridspec_kw={'height_ratios': (3, 3, 2)})
    # Lines break where the log has a gap (or the fit left samples out).
    steps = np.diff(fit.time_s)
    gap = np.concatenate([[False], steps > 1.5 * np.median(steps)]) if len(steps) else []

    def broken(values):
        return np.where(gap, np.nan, values)

    for j, (ax, name) in enumerate(zip(axes[:2], ('shoulder', 'elbow'))):
        ax.plot(fit.time_s, fit.measured_v[:, j], '.', color='0.35', markersize=2,
                label='measured (filtered command)')
        ax.plot(fit.time_s, broken(fit.predicted_v[:, j]), '-', color=JOINT_COLOURS[j],
                linewidth=1.0,
                label=f'identified model (RMS error {fit.residual_rms_v[j]:.3f} V)')
        nominal_rms = math.sqrt(float(np.mean((fit.nominal_v[:, j] - fit.measured_v[:, j])
                                              ** 2)))
        ax.plot(fit.time_s, broken(fit.nominal_v[:, j]), '--', color='0.6', linewidth=0.8,
                label=f'robot file (RMS error {nominal_rms:.3f} V)')
        ax.set_ylabel(f'{name} voltage (V)')
        ax.legend(loc='upper right', fontsize=8)
        ax.grid(alpha=0.3)
        axes[2].plot(fit.time_s, fit.measured_v[:, j] - fit.predicted_v[:, j], '.',
                     color=JOINT_COLOURS[j], markersize=2, label=name)
    axes[2].set_ylabel('residual (V)')
    axes[2].set_xlabel('time (s)')
    axes[2].legend(loc='upper right', fontsize=8)
    axes[2].grid(alpha=0.3)
    axes[0].set_title(title or 'measured against predicted voltage')
    figure.tight_layout()
    if path is not None:
        figure.savefig(Path(path))
    return figure


@dataclass(frozen=True)
class Identification:
    """What ``identify`` found and wrote."""

    fit: FitResult
    realisation: Realisation | None     # None when π cannot be written as an arm (see error)
    error: str | None
    parameter_file: Path | None
    report_file: Path
    plot_file: Path


def said(result: Identification) -> str:
    """The fit in one line for the node's log."""
    fit = result.fit
    line = (f'fitted {fit.samples} samples; residual RMS shoulder {fit.residual_rms_v[0]:.3f} V'
            f', elbow {fit.residual_rms_v[1]:.3f} V; command lag {1000 * fit.lag_s:+.1f} ms; '
            f'report {result.report_file}, plot {result.plot_file}')
    if not fit.instrumented:
        line += ('; the log holds no plan (/sysid/reference): fitted by least squares, whose '
                 'inertias the sensor noise pulls low in closed loop')
    return line


def identify(log: Log, nominal: ArmConfig, settings: SysIdConfig, directory, source: str,
             notes=()) -> Identification:
    """Fit ``log``, then write identified_params.yaml, report.md and fit.png to ``directory``.

    Raises ValueError when the log cannot be fitted (too short, no commands).
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    fit = fit_log(log, nominal, settings.smoothing_window_s, settings.max_command_lag_s,
                  settings.min_speed_rad_s)
    notes = list(notes) + list(log.notes)
    quality = None
    try:
        realisation, quality = identified_values(fit, nominal)
        error = None if realisation.values else 'the log identifies no parameter'
    except RealisationError as problem:
        realisation, error = None, str(problem)
    if error is not None:
        notes.append(f'no parameter file written: {error}')
        realisation = None
    parameter_file = None
    if realisation is not None:
        parameter_file = directory / 'identified_params.yaml'
        parameter_file.write_text(overlay_yaml(realisation, fit, nominal, source),
                                  encoding='utf-8')
    report_file = directory / 'report.md'
    report_file.write_text(report_markdown(fit, realisation, nominal, source, notes,
                                           quality=quality), encoding='utf-8')
    plot_file = directory / 'fit.png'
    plot_fit(fit, plot_file, title=f'sysid: {source}')
    return Identification(fit, realisation, error, parameter_file, report_file, plot_file)
