"""What the controller says about its health: a level, a sentence, and the numbers."""

import math

from arm_control.control.state_machine import ArmState as S

LEVELS = {S.ESTOPPED: 'error', S.ERROR: 'warn', S.NO_SENSORS: 'warn'}


def health(core, worst_period_s: float, problems=()) -> tuple[str, str]:
    """('ok' | 'warn' | 'error', a sentence): the state and why, a loop that stalled (a
    period over three times its own), the planner away, and the node's ``problems``."""
    level = LEVELS.get(core.state, 'ok')
    said = [f'{core.state}: {core.last_error}' if level != 'ok' else str(core.state)]
    if worst_period_s > 3 * core.period_s:
        said.append(f'control loop stalled for {worst_period_s:.3f} s')
    if core.planner_available is False:
        said.append('the planner (plan_path) is not available: goals will fail')
    said += list(problems)
    return ('warn' if len(said) > 1 and level == 'ok' else level), '; '.join(said)


def diagnostics(core, now_s: float) -> dict:
    """The core's numbers, as diagnostics' key-value pairs."""
    queue = core.goals.queue
    return {
        'state': str(core.state),
        'queued goals': len(queue.waiting),
        'current goal': queue.current.label if queue.current else '',
        'joint states age (s)': f'{core.sensing.age_s(now_s):.3f}',
        'bus voltage (V)': f'{core.sensing.bus_voltage:.2f}',
        'last error': core.last_error,
        'voltage (V)': [round(float(v), 3) for v in core.voltage],
        'tracking error (deg)': [round(math.degrees(e), 3) for e in core.tracking_error_rad],
        'e-stops': core.estops,
        **{f'goals {k}': v for k, v in core.goals.counts.items()},
        **{f'last goal: {k} (ms)': f'{1000 * v:.1f}' for k, v in core.goals.latency_s.items()},
    }
