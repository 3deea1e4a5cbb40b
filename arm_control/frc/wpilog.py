"""A run logged as a .wpilog (WPILib's DataLog), the file AdvantageScope opens.

Every NT topic of the contract is logged under its own name, with its unit in the entry's
metadata; the ROS side's own view (the controller's voltage and setpoint, its state) and the
bridge's events sit under ``/ros`` and ``/bridge``. Timestamps are on NT's clock (µs), the
clock of the NT values themselves, so readings keep the time the robot took them.
"""

import json
from pathlib import Path
import time

from wpiutil import DataLogWriter
from wpiutil.log import BooleanLogEntry, DoubleArrayLogEntry, DoubleLogEntry, StringLogEntry

from arm_control.frc import contract

FLUSH_PERIOD_S = 0.25       # handed to the disk this often (in 4 KB blocks), and at close
ENTRY_TYPES = {'double[]': DoubleArrayLogEntry, 'double': DoubleLogEntry,
               'boolean': BooleanLogEntry, 'string': StringLogEntry}

CONTROLLER_VOLTAGE = contract.NtTopic('/ros/voltage_command', 'double[]', 'V', 'controller', '',
                                      'what the controller asked, before the link rules')
CONTROLLER_SETPOINT = contract.NtTopic('/ros/controller/setpoint_rad', 'double[]', 'rad',
                                       'controller', '', 'the trajectory setpoint')
CONTROLLER_SETPOINT_VELOCITY = contract.NtTopic(
    '/ros/controller/setpoint_velocity_rad_s', 'double[]', 'rad/s', 'controller', '', '')
BRIDGE_EVENTS = contract.NtTopic('/bridge/events', 'string', '', 'bridge', '',
                                 'the link found, lost, enabled, disabled')
LOGGED = contract.ROBOT_READINGS + contract.COMMANDS + (
    CONTROLLER_VOLTAGE, CONTROLLER_SETPOINT, CONTROLLER_SETPOINT_VELOCITY, BRIDGE_EVENTS)


def unused_path(path) -> Path:
    """``path``, or ``<stem>_1<suffix>``, ``_2``... if it exists: an old log is never lost."""
    path = Path(path).expanduser()
    candidate, n = path, 0
    while candidate.exists():
        n += 1
        candidate = path.with_name(f'{path.stem}_{n}{path.suffix}')
    return candidate


class RunLog:
    """A .wpilog with an entry for each topic of ``LOGGED``; ``path`` is where it went."""

    def __init__(self, path):
        self.path = unused_path(path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.log = DataLogWriter(str(self.path))
        except (OSError, RuntimeError) as error:
            raise OSError(f'cannot log to {self.path}: {error}') from error
        self.flushed_s = time.monotonic()
        self.entries = {topic.name: ENTRY_TYPES[topic.type](
            self.log, topic.name, json.dumps({'unit': topic.unit}) if topic.unit else '')
            for topic in LOGGED}

    def append(self, name: str, value, time_us: int = 0) -> None:
        """Log ``value`` under topic ``name`` at ``time_us`` on NT's clock (0: now)."""
        entry = self.entries[name]
        entry.append(list(value) if isinstance(entry, DoubleArrayLogEntry) else value, time_us)
        if time.monotonic() - self.flushed_s >= FLUSH_PERIOD_S:
            self.log.flush()
            self.flushed_s = time.monotonic()

    def close(self) -> None:
        self.log.stop()             # writes what is left
