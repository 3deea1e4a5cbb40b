"""The controller core and the simulated arm in one process, in simulated time.

Each control period the core reads the plant's sensors, returns a voltage, and the plant
integrates it over the period: the closed loop the nodes run over ROS, with no ROS, for
tests, benchmarks and the README's pictures. Only the bookkeeping reads the true state.
"""

from typing import Callable, Optional

import numpy as np

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.control.controller import ArmController
from arm_control.control.events import EventKind
from arm_control.control.state_machine import ArmState
from arm_control.model.plant import ArmPlant
from arm_control.model.world import ForbiddenSpace
from arm_control.plans.port import plan_in_process


class ClosedLoop:
    """The plant and the core, stepped together at the control rate.

    ``planner``: the core plans with it in-process (``plans.port.InProcessPlanning``: anything
    with ``plan(start_q, goal_xy)``, e.g. ``planning.planner.Planner``). ``observers`` are
    called after every step with (loop, reading, voltage). ``command_delay_s``: each command
    acts this long after its tick, as through ROS; the core is told so (its step is for
    when the command acts) unless ``told_delay`` is False. ``reading_age_s``: the sensors
    were read this long before the tick (a reading's transit); the core is told when (the
    reading's stamp) unless ``told_age`` is False (it then takes the reading as new).
    """

    def __init__(self, arm: ArmConfig, controller_config: ControllerConfig, planner=None,
                 start=(1.5708, -1.5708), seed: Optional[int] = 0,
                 physics_step_s: float = 0.001, command_delay_s: float = 0.0,
                 told_delay: bool = True, reading_age_s: float = 0.0, told_age: bool = True):
        self.arm = arm
        self.plant = ArmPlant(arm, start, physics_step_s, seed)
        self.core = plan_in_process(ArmController(arm, controller_config), planner)
        self.period_s = controller_config.period_s
        self.command_delay_s, self.told_delay = command_delay_s, told_delay
        self.reading_age_s, self.told_age = reading_age_s, told_age
        self.forbidden = ForbiddenSpace(arm)
        self.sensors_on = True
        self.lowest_m = 0.0          # the lowest point of either link so far (y, m)
        self.voltages = []
        self.arrivals = []           # (goal q, true q, true q̇) at each arrival
        self.observers: list[Callable] = []

    @property
    def now(self) -> float:
        return self.plant.time_s

    @property
    def true_q(self) -> np.ndarray:
        return np.array(self.plant.state[:2])

    def step(self, reading=None):
        """One control period; ``reading`` replaces the plant's own (None: read it, unless
        ``sensors_on`` is off)."""
        read_s = self.now
        if reading is None and self.sensors_on:
            reading = self.plant.read()
        self.plant.advance(self.reading_age_s)
        acts_s = self.now + (self.command_delay_s if self.told_delay else 0.0)
        step = self.core.step(acts_s, reading, read_s if self.told_age else self.now)
        voltage = step.volts
        if any(event.kind == EventKind.GOAL_REACHED for event in step.events):
            self.arrivals.append((step.goal_q.copy(), self.true_q,
                                  np.array(self.plant.state[2:])))
        self.voltages.append(voltage)
        for observer in self.observers:
            observer(self, reading, voltage)
        if self.command_delay_s > 0.0:
            self.plant.advance(self.command_delay_s)
        self.plant.set_voltage(voltage)
        self.plant.advance(self.period_s - self.reading_age_s - self.command_delay_s)
        self.lowest_m = min(self.lowest_m, float(self.forbidden.lowest_point_m(self.true_q)))
        return voltage

    def run(self, seconds: float, until: Optional[Callable[[], bool]] = None) -> bool:
        """Step for ``seconds``, or until ``until()`` is true; returns whether it is."""
        for _ in range(round(seconds / self.period_s)):
            self.step()
            if until is not None and until():
                return True
        return until is None or until()

    def in_state(self, state: ArmState) -> Callable[[], bool]:
        return lambda: self.core.state == state
