"""The identification run in-process, on ``ArmPlant``: what the node does, in simulated time.

For tests and the benchmark: the plant is the true arm (with its sensors' noise), the
excitation is designed and tracked as the node does it (``Session``), and the log holds what
the node would record -- the potentiometers' readings and the commands sent.
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

    @property
    def arm_time_s(self) -> float:
        return float(self.log.joint_time_s[-1] - self.log.joint_time_s[0])


def _log(times, positions, velocities, voltages, references) -> Log:
    times = np.array(times)
    return Log(joint_time_s=times, position_rad=np.array(positions),
               velocity_rad_s=np.array(velocities), command_time_s=times.copy(),
               voltage_v=np.array(voltages), reference_time_s=times.copy(),
               reference_rad=np.array(references).reshape(-1, 2))


def identification_run(truth: ArmConfig, nominal: ArmConfig, settings: SysIdConfig,
                       seed: int = 0, start_rad=None) -> SimulatedRun:
    """Drive both stages on the true arm at ``loop_rate_hz``, the stage-1 fit taking no arm
    time; the plant's physics on 1 ms steps, each command held for one period (as the sim
    does with the node's)."""
    start = np.array(settings.centre_rad if start_rad is None else start_rad, float)
    plant = ArmPlant(truth, start, 0.001, seed)
    session = Session(nominal, settings, start)
    period_s = 1.0 / settings.loop_rate_hz
    times, positions, velocities, voltages, states, references = [], [], [], [], [], []
    while not session.finished(plant.time_s):
        if session.stage_one_done(plant.time_s):
            session.begin_stage_two(*provisional_model(
                _log(times, positions, velocities, voltages, references), nominal, settings))
            continue
        reading = plant.read()
        voltage = session.command(plant.time_s, reading.potentiometer_rad,
                                  reading.velocity_rad_s)
        plant.set_voltage(voltage)
        times.append(plant.time_s)
        positions.append(reading.potentiometer_rad)
        velocities.append(reading.velocity_rad_s)
        voltages.append(np.array(plant.command))          # as the node logs its commands
        states.append(reading.true_state)
        references.append(session.reference[0])
        plant.advance(period_s)
    return SimulatedRun(_log(times, positions, velocities, voltages, references),
                        np.array(states), session)
