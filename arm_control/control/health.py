"""What the controller says about its health: a level, a sentence, and the numbers."""

import math

from arm_control.control.state_machine import ArmState as S

LEVELS = {S.ESTOPPED: 'error', S.ERROR: 'warn', S.NO_SENSORS: 'warn'}


def health(core, worst_period_s: float, problems=(), untrusted=()) -> tuple[str, str]:
    """('ok' | 'warn' | 'error', a sentence): the state and why, a loop that stalled (a
    period over three times its own), the planner away, and the node's ``problems``; an
    ``untrusted`` input (``TrustWatch.problems``' sentences) is an error."""
    level = 'error' if untrusted else LEVELS.get(core.state, 'ok')
    said = [f'{core.state}: {core.last_error}' if level != 'ok' else str(core.state)]
    if worst_period_s > 3 * core.period_s:
        said.append(f'control loop stalled for {worst_period_s:.3f} s')
    if core.planner_available is False:
        said.append('the planner (plan_path) is not available: goals will fail')
    said += list(problems) + list(untrusted)
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
        'tracking error (deg)': [round(math.degrees(e), 3)
                                 for e in core.tracking.tracking_error_rad],
        'e-stops': core.stops.estops,
        **{f'goals {k}': v for k, v in core.goals.counts.items()},
        **{f'last goal: {k} (ms)': f'{1000 * v:.1f}' for k, v in core.goals.latency.items()},
    }


def loop_values(stats: dict, ages_s, loop) -> dict:
    """The control loop's numbers (``loop_statistics``' ``stats``, the readings' ages, a
    ``ControlLoop``), as diagnostics' key-value pairs."""
    return {
        'loop period mean (s)': f'{stats["mean"]:.4f}',
        'loop period worst (s)': f'{stats["worst"]:.4f}',
        'compute per cycle median (ms)': f'{1000 * stats["compute median"]:.3f}',
        'compute per cycle worst (ms)': f'{1000 * stats["compute worst"]:.3f}',
        # On one clock (one host, or sim time): how late the readings come to the loop.
        'joint_states age worst (ms)': f'{1000 * max(ages_s, default=math.nan):.1f}',
        'loop scheduling': loop.priority_problem or (
            f'SCHED_FIFO {loop.realtime_priority}' if loop.realtime_priority else 'normal'),
        'clock jumps taken out': loop.guard.jumps,
        'ticks on a stopped clock': loop.clock_stops,
    }


def trust_values(trust) -> dict:
    """What a ``TrustWatch`` does not trust, as diagnostics' key-value pairs."""
    return {'untrusted': ', '.join(trust.problems) or 'none',
            'joint_states refused': trust.core.sensing.refused}
