"""The identification run in-process, on ``ArmPlant``: what the node does, in simulated time.

For tests and the benchmark: the plant is the true arm (with its sensors' noise), the
excitation is designed and tracked as the node does it (``Session``), and the log holds what
the node would record -- the potentiometers' readings, the commands sent and the bus voltage
(``battery_state``).
"""

from dataclasses import dataclass

import numpy as np

from arm_control.config import ArmConfig
from arm_control.model.plant import ArmPlant
from arm_control.sysid.log import Log
from arm_control.sysid.session import provisional_model, Session
from arm_control.sysid.settings import SysIdConfig


@dataclass(frozen=True)
class SimulatedRun:
    log: Log
    true_state: np.ndarray          # (N, 4) at each joint sample
    session: Session
    peak_current_a: np.ndarray      # per joint, one motor's, over every physics step

    @property
    def arm_time_s(self) -> float:
        return float(self.log.joint_time_s[-1] - self.log.joint_time_s[0])


class _Record:
    def __init__(self):
        self.joints, self.commands, self.states, self.battery = [], [], [], []

    def log(self) -> Log:
        times = np.array([c[0] for c in self.commands])
        return Log(joint_time_s=np.array([j[0] for j in self.joints]),
                   position_rad=np.array([j[1] for j in self.joints]),
                   velocity_rad_s=np.array([j[2] for j in self.joints]),
                   command_time_s=times, voltage_v=np.array([c[1] for c in self.commands]),
                   battery_time_s=np.array([b[0] for b in self.battery]),
                   battery_v=np.array([b[1] for b in self.battery]),
                   reference_time_s=times.copy(),
                   reference_rad=np.array([c[2] for c in self.commands]).reshape(-1, 2))


def identification_run(truth: ArmConfig, nominal: ArmConfig, settings: SysIdConfig,
                       seed: int = 0, start_rad=None, stalls=(),
                       command_timeout_s: float = 0.1) -> SimulatedRun:
    """Drive both stages on the true arm at ``loop_rate_hz``, the stage-1 fit taking no arm
    time; the plant's physics on 1 ms steps, each command held for one period (as the sim
    does with the node's).

    ``stalls``: (start s, duration s) during which the node sends nothing (starved of CPU):
    the plant keeps the last command for ``command_timeout_s``, then gets 0 V, as the sim
    does; the joint states of the stall are logged (they arrive late, with their stamps).
    """
    start = np.array(settings.centre_rad if start_rad is None else start_rad, float)
    plant = ArmPlant(truth, start, 0.001, seed)
    session = Session(nominal, settings, start)
    period_s = 1.0 / settings.loop_rate_hz
    steps = max(1, round(period_s / plant.physics_step_s))
    record, peak, last_command_s = _Record(), np.zeros(2), 0.0
    while not session.finished(plant.time_s):
        if session.stage_one_done(plant.time_s):
            session.begin_stage_two(*provisional_model(record.log(), nominal, settings))
            continue
        reading = plant.read()
        record.joints.append((plant.time_s, reading.potentiometer_rad, reading.velocity_rad_s))
        record.states.append(reading.true_state)
        record.battery.append((plant.time_s, reading.bus_voltage))    # as battery_state
        if not any(begin <= plant.time_s < begin + length for begin, length in stalls):
            voltage = session.command(plant.time_s, reading.potentiometer_rad,
                                      reading.velocity_rad_s, reading.bus_voltage)
            plant.set_voltage(voltage)
            last_command_s = plant.time_s
            # as the node logs its commands
            record.commands.append((plant.time_s, np.array(plant.command),
                                    session.reference[0]))
        for _ in range(steps):
            if plant.time_s - last_command_s >= command_timeout_s - 1e-9:
                plant.set_voltage((0.0, 0.0))
            plant.advance(plant.physics_step_s)
            peak = np.maximum(peak, np.abs(plant.power.motor_current_a))
    return SimulatedRun(record.log(), np.array(record.states), session, peak)
