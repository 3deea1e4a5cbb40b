"""The identification run in-process, on ``ArmPlant``: what the node does, in simulated time.

For tests and the benchmark: the plant is the true arm (with its sensors' noise), the
excitation is designed and tracked with the robot file's arm, and the log holds exactly what
the node would record -- the potentiometers' readings and the commands sent.
"""

from dataclasses import dataclass

import numpy as np

from arm_control.config import ArmConfig
from arm_control.model.plant import ArmPlant
from arm_control.sysid.excitation import design_excitation, ExcitationRun
from arm_control.sysid.log import Log
from arm_control.sysid.settings import SysIdConfig


@dataclass(frozen=True)
class SimulatedRun:
    log: Log
    true_state: np.ndarray          # (N, 4) at each joint sample
    run: ExcitationRun
    notes: list


def identification_run(truth: ArmConfig, nominal: ArmConfig, settings: SysIdConfig,
                       seed: int = 0, start_rad=None) -> SimulatedRun:
    """Drive the excitation on the true arm at ``loop_rate_hz``; the plant's physics on 1 ms
    steps, each command held for one period (as the sim does with the node's)."""
    start = np.array(settings.centre_rad if start_rad is None else start_rad, float)
    excitation, notes = design_excitation(nominal, settings, start)
    plant = ArmPlant(truth, start, 0.001, seed)
    run = ExcitationRun(nominal, settings, excitation)
    period_s = 1.0 / settings.loop_rate_hz
    times, positions, velocities, voltages, states = [], [], [], [], []
    while not run.finished(plant.time_s):
        reading = plant.read()
        voltage = run.command(plant.time_s, reading.potentiometer_rad, reading.velocity_rad_s)
        plant.set_voltage(voltage)
        times.append(plant.time_s)
        positions.append(reading.potentiometer_rad)
        velocities.append(reading.velocity_rad_s)
        voltages.append(np.array(plant.voltage))
        states.append(reading.true_state)
        plant.advance(period_s)
    times = np.array(times)
    log = Log(joint_time_s=times, position_rad=np.array(positions),
              velocity_rad_s=np.array(velocities), command_time_s=times.copy(),
              voltage_v=np.array(voltages))
    return SimulatedRun(log, np.array(states), run, notes)
