"""What bench_frc_loop measures, from what its probe heard and its robot published: whole
readings, their transit and its legs, the bridge's and the controller's own figures, the
robot's stalls, and other users' real-time load on the machine."""

import os

import numpy as np

from arm_control.control.events import parse_event
from arm_control.frc.conversions import joint_effort_nm


def mixed_readings(copro, robot, since_s) -> tuple[int, int, float]:
    """(messages whose fields are not all those of the loop at their stamp, messages
    checked, the largest stamp error in ms): each message is matched to the loop nearest
    its stamp (the loops are a period apart)."""
    times = np.array(sorted(robot.published))
    mixed = checked = 0
    worst_us = 0.0
    for kind in ('joint_states', 'battery'):
        for t, message in copro.heard[kind]:
            if t < since_s or not len(times):
                continue
            stamp_us = message.header.stamp.sec * 1e6 + message.header.stamp.nanosec * 1e-3
            error_us = np.abs(times - stamp_us)
            worst_us = max(worst_us, np.min(error_us))
            # A late loop may be followed closely by the next: every loop within 3 ms.
            candidates = times[error_us <= max(3000.0, np.min(error_us))]
            checked += 1
            mixed += not any(whole(message, kind, robot.published[int(t)], robot.dynamics)
                             for t in candidates)
    return mixed, checked, 1e-3 * worst_us


def whole(message, kind, r, dynamics) -> bool:
    """Every field of ``message`` is reading ``r``'s."""
    if kind == 'joint_states':
        effort = joint_effort_nm(r.motor_current_a, dynamics)
        return tuple(message.position) == r.position_rad and \
            tuple(message.velocity) == r.velocity_rad_s and \
            np.allclose(message.effort, effort, rtol=1e-12, atol=1e-9)
    return message.voltage == np.float32(r.bus_voltage_v) and \
        message.current == np.float32(-r.supply_current_a)       # float32 fields


def bridge_reading_ages(copro, since_s) -> tuple[float, float]:
    """From the bridge's own /diagnostics (the robot's sensors' instant to the bridge taking
    the reading): the median of its per-second p50 (ms), and the share older than 10 ms."""
    p50, older, total = [], 0, 0
    for t, message in copro.heard['diagnostics']:
        for status in message.status if t >= since_s else ():
            values = {v.key: v.value for v in status.values}
            if 'reading age p50 (ms, last s)' in values:
                p50.append(float(values['reading age p50 (ms, last s)']))
                older += int(values['readings older than 10 ms (last s)'])
                total += int(values['readings (last s)'])
    return (np.median(p50) if p50 else np.nan), 100.0 * older / max(total, 1)


def controller_hearing(copro, since_s, until_s, drop_window) -> tuple[float, int]:
    """(the oldest ``joint_states`` the controller took, ms, from its /diagnostics' per-second
    worst; its ``sensors_lost`` events outside the drop), from ``since_s`` to ``until_s``."""
    worst = [float(v.value) for t, m in copro.heard['diagnostics'] if since_s <= t <= until_s
             for status in m.status for v in status.values
             if v.key == 'joint_states age worst (ms)']
    lost = [t for t, m in copro.heard['controller_events'] if since_s <= t and
            parse_event(m.data)[0] == 'sensors_lost' and
            not drop_window[0] <= t <= drop_window[1] + 0.3]
    return max(worst, default=np.nan), len(lost)


def robot_stalls(robot, since_s) -> list:
    """(from, to) wall seconds of every gap over 0.1 s between the robot's own loops."""
    times = np.array(sorted(us * 1e-6 for us in list(robot.published) if us * 1e-6 >= since_s))
    gaps = np.flatnonzero(np.diff(times) > 0.1)
    return [(times[i], times[i + 1]) for i in gaps]


def stamp_s(header) -> float:
    return header.stamp.sec + 1e-9 * header.stamp.nanosec


def transit_segments(copro, since_s) -> dict:
    """A reading's way to ``joint_states`` heard, in ms per message, in three legs: the
    sensors' instant to the bridge's publish (DDS's source time), DDS on to the probe's
    process (its received time), and that process's executor on to the callback."""
    rows = np.array([row for row in copro.joint_states if row[0] >= since_s]).reshape(-1, 4)
    heard, stamp, published, received = rows.T
    return {'total': 1e3 * (heard - stamp), 'bridge': 1e3 * (published - stamp),
            'dds': 1e3 * (received - published), 'probe': 1e3 * (heard - received)}


def others_realtime_ticks() -> dict:
    """{(pid, tid): (CPU clock ticks so far, real-time now)} of every thread of every process
    on the machine that is not this bench's: other users' real-time loops (SCHED_FIFO,
    SCHED_RR) compete with the bridge's and the robot's threads, which no priority below
    theirs escapes."""
    parents = {}
    for pid in filter(str.isdigit, os.listdir('/proc')):
        try:
            with open(f'/proc/{pid}/stat') as stat:
                parents[pid] = stat.read().rsplit(')', 1)[1].split()[1]
        except OSError:
            pass
    ours, grown = {str(os.getpid())}, True
    while grown:                                    # this process and its descendants
        grown = {pid for pid, parent in parents.items() if parent in ours} - ours
        ours |= grown
    ticks = {}
    for pid in set(parents) - ours:
        try:
            for tid in os.listdir(f'/proc/{pid}/task'):
                with open(f'/proc/{pid}/task/{tid}/stat') as stat:
                    fields = stat.read().rsplit(')', 1)[1].split()
                ticks[pid, tid] = (int(fields[11]) + int(fields[12]),   # utime, stime
                                   int(fields[38]) in (os.SCHED_FIFO, os.SCHED_RR))  # policy
        except (OSError, IndexError, ValueError):                       # gone meanwhile
            pass
    return ticks


def others_realtime_cores(before: dict, after: dict, seconds: float) -> float:
    """Cores other users' real-time threads kept busy between two ``others_realtime_ticks``
    (a thread that ended meanwhile is not counted: at least this much)."""
    used = sum(ticks - before.get(key, (0, False))[0]
               for key, (ticks, realtime) in after.items() if realtime)
    return used / os.sysconf('SC_CLK_TCK') / seconds


def percentiles(values_ms) -> str:
    values_ms = np.asarray(values_ms)
    if not len(values_ms):
        return '- / -'
    return f'{np.median(values_ms):.1f} / {np.percentile(values_ms, 99):.1f}'
