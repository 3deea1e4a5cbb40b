"""A robot's own log as an identification log: a .wpilog (WPILib's DataLog, which
AdvantageKit writes too), read with robotpy-wpiutil.

Three series are needed, each a double[] of [shoulder, elbow] or two doubles (named
``shoulder_entry|elbow_entry``): the joint positions (rad), their velocities (rad/s; may be
left out) and the voltage the motors got (V); the bus voltage (a double, V) when logged.
A name may take a slice of a double[], ``name[a:b]``. The defaults (``ENTRIES``) are slices
of this project's one reading per robot loop (``/arm/robot/reading``, its layout in
``arm_control.frc.contract``), whose applied voltage is what that loop applies from the
reading's instant on. An AdvantageKit log names its own entries, e.g.
``/RealOutputs/Arm/PositionRad``; there an applied voltage is logged at the end of the loop it
was applied over, so it is taken as held from one loop period before its time. A robot log
holds no plan: the fit is least squares (see ``fit``).
"""

import math
from pathlib import Path
import re

import numpy as np
from wpiutil.log import DataLogReader

from arm_control.sysid.log import Log

ENTRIES = ('/arm/robot/reading[2:4]', '/arm/robot/reading[4:6]',
           '/arm/robot/reading[12:14]', '/arm/robot/reading[10:11]')
SLICE = re.compile(r'^(?P<name>[^\[]+)\[(?P<start>\d+):(?P<stop>\d+)\]$')
KINDS = ('position', 'velocity', 'voltage', 'bus')


def _entry(name):
    """(entry name, slice of its double[] or None) of ``name`` or ``name[a:b]``."""
    sliced = SLICE.match(name)
    if sliced is None:
        return name, None
    return sliced['name'], slice(int(sliced['start']), int(sliced['stop']))


def _values(records, name):
    """[(time s, values)] of ``name``, sliced when it names a slice; finite values only (a
    reading may leave a sensor it has not as NaN)."""
    entry, part = _entry(name)
    rows = [(t, v if part is None else v[part]) for t, v in records.get(entry, [])
            if part is None or len(v) >= part.stop]
    return [(t, v) for t, v in rows if all(math.isfinite(x) for x in v)]


def _series(records, names):
    """(times s, values (N, 2)) of a double[] entry, or of two double entries 'a|b' joined
    at the first one's times."""
    parts = names.split('|')
    if len(parts) == 1:
        rows = [(t, v) for t, v in _values(records, parts[0]) if len(v) == 2]
        return (np.array([t for t, _ in rows]),
                np.array([v for _, v in rows], float).reshape(-1, 2))
    (t0, v0), (t1, v1) = (_scalar(records, name) for name in parts)
    if len(t0) < 2 or len(t1) < 2:
        return np.zeros(0), np.zeros((0, 2))
    return t0, np.column_stack([v0, np.interp(t0, t1, v1)])


def _scalar(records, name):
    rows = [(t, v[0]) for t, v in _values(records, name) if len(v) == 1]
    return np.array([t for t, _ in rows]), np.array([v for _, v in rows], float)


def read_wpilog(path, entries=ENTRIES) -> Log:
    """The identification log in a .wpilog; ``entries`` names (position, velocity, applied
    voltage, bus voltage), '' for one not logged (velocity and bus may be missing)."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f'{path}: no such file')
    reader = DataLogReader(str(path))
    if not reader.isValid():
        raise ValueError(f'{path} is not a .wpilog (DataLog) file')
    wanted = {_entry(name)[0] for names in entries for name in names.split('|') if name}
    ids, records = {}, {}
    for record in reader:
        if record.isStart():
            start = record.getStartData()
            if start.name in wanted:
                ids[start.entry] = (start.name, start.type)
        elif not record.isControl() and record.getEntry() in ids:
            name, kind = ids[record.getEntry()]
            value = (list(record.getDoubleArray()) if kind == 'double[]' else
                     [record.getDouble()] if kind == 'double' else None)
            if value is not None:
                records.setdefault(name, []).append((record.getTimestamp() * 1e-6, value))
    found = dict(zip(KINDS, entries))
    joint_t, position = _series(records, found['position'])
    volt_t, voltage = _series(records, found['voltage'])
    if len(joint_t) < 2 or len(volt_t) < 2:
        raise ValueError(f'{path}: {len(joint_t)} positions ({found["position"]}) and '
                         f'{len(volt_t)} applied voltages ({found["voltage"]}); a fit needs '
                         'both as [shoulder, elbow]')
    velocity = np.full_like(position, np.nan)
    if found['velocity']:
        speed_t, speed = _series(records, found['velocity'])
        if len(speed_t) > 1:
            velocity = np.column_stack([np.interp(joint_t, speed_t, speed[:, j])
                                        for j in range(2)])
    # One reading per loop carries what the loop applies from its instant on; a separate
    # entry, what was applied over the loop that ended at its time.
    whole = _entry(found['voltage'])[0] == _entry(found['position'])[0]
    held_from_s = volt_t if whole else volt_t - float(np.median(np.diff(volt_t)))
    bus_t, bus = (_scalar(records, found['bus']) if found['bus']
                  else (np.zeros(0), np.zeros(0)))
    order = np.argsort(joint_t)
    return Log(joint_time_s=joint_t[order], position_rad=position[order],
               velocity_rad_s=velocity[order], command_time_s=held_from_s,
               voltage_v=voltage, battery_time_s=bus_t, battery_v=bus,
               notes=[f'read from the .wpilog entries {", ".join(e for e in entries if e)}; '
                      'applied voltages taken as held from ' +
                      ('their times' if whole else 'one loop before their times')])


def read_recording(path, entries=ENTRIES) -> Log:
    """A .wpilog by ``read_wpilog``, anything else as a bag by ``log.read_log``."""
    from arm_control.sysid.log import read_log
    return read_wpilog(path, entries) if str(path).endswith('.wpilog') else read_log(path)
