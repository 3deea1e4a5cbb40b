"""The controller's core and the simulated robot in one process, on the robot's clock.

The robot reads its sensors and applies the latest command it has at its loop's instants,
``phase_s + k·period`` (``robot_loop``), or applies each command the instant it arrives and
reads at those instants (``on_arrival``, the sim's other mode). The controller ticks every
period (sending profiles, as the node does: ``Commander.tick_due``) and its command
arrives ``command_lag_s`` later; a reading reaches it
``reading_transit_s`` after it was taken. The controller sends plain volts computed for its
tick plus the lag (``volts``, the controller's ``command_mode: volts``), plain volts
computed for the robot's next instant learned from the stamps (``volts_at_instant``), or a
profile for that instant (``profile``); ``lag_jitter_ms``: each command arrives up to this
much earlier or later than the controller expects (seeded), never before the one sent
before (one publisher's messages keep their order). Physics on 1 ms steps; deterministic.
"""

from dataclasses import replace
import math
from typing import Optional

import numpy as np

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.control.controller import ArmController
from arm_control.control.robot_command import Commander
from arm_control.model.plant import ArmPlant
from arm_control.model.profile import Profile, ProfilePlayer
from arm_control.plans.port import plan_in_process

MODES = ('volts', 'volts_at_instant', 'profile')
STEP_MS = 1


class RobotLoop:
    """The closed loop; ``run`` it, then read ``history`` (time s, true state) and
    ``lowest_m``."""

    def __init__(self, arm: ArmConfig, controller_config: ControllerConfig, planner=None,
                 start=(1.5708, -1.5708), seed: Optional[int] = 0, mode: str = 'profile',
                 phase_s: float = 0.0, robot_loop: bool = True, command_lag_s: float = 0.004,
                 reading_transit_s: float = 0.001, lag_jitter_ms: int = 0):
        if mode not in MODES:
            raise ValueError(f'mode {mode!r}: expected one of {MODES}')
        self.plant = ArmPlant(arm, start, 0.001 * STEP_MS, seed)
        self.core = plan_in_process(ArmController(arm, controller_config), planner)
        self.mode, self.robot_loop = mode, robot_loop
        self.period_ms = round(1000.0 * controller_config.period_s)
        self.phase_ms = round(1000.0 * phase_s) % self.period_ms
        self.lag_ms = round(1000.0 * command_lag_s)
        self.transit_ms = round(1000.0 * reading_transit_s)
        self.jitter_ms = int(lag_jitter_ms)
        self.rng = np.random.default_rng(seed)
        self.commander = Commander(replace(controller_config, command_mode=(
            'volts' if mode == 'volts' else 'profile')))
        self.clock = self.commander.clock
        self.player = ProfilePlayer(arm.battery.nominal_voltage)
        self.now_ms = 0
        self.readings = []           # (arrives ms, stamp s, reading)
        self.commands = []           # (arrives ms, volts pair or Profile)
        self.plain = (0.0, 0.0)      # the last plain command applied
        self.playing = False         # a profile is in charge
        self.history = []            # (t s, true state)
        self.next_tick_ms = 0
        self.lowest_m = math.inf

    @property
    def now_s(self) -> float:
        return self.now_ms / 1000.0

    def poke(self) -> None:
        """Tick at the next millisecond, as the node's loop does when a plan is ready
        (``ControlLoop.poke``); the ticks then keep to their schedule from there."""
        self.next_tick_ms = self.now_ms

    def submit_goal(self, x: float, y: float) -> None:
        """A goal now, taken at once: the core plans it in that tick."""
        self.core.submit_goal(self.now_s, x, y)
        self.poke()

    def run(self, seconds: float, until=None) -> bool:
        for _ in range(round(seconds * 1000.0 / STEP_MS)):
            self._step()
            if until is not None and until():
                return True
        return until is None or until()

    def _step(self) -> None:
        now_ms, now_s = self.now_ms, self.now_s
        instant = (now_ms - self.phase_ms) % self.period_ms == 0
        arrived = [c for c in self.commands if c[0] <= now_ms]
        self.commands = [c for c in self.commands if c[0] > now_ms]
        if instant:
            reading = self.plant.read()
            self.readings.append((now_ms + self.transit_ms, now_s, reading))
        for _, command in arrived:
            if isinstance(command, Profile):
                self.player.offer(command)
                self.playing = True
            else:
                self.plain, self.playing = command, False
                self.player.clear()
        if instant or (arrived and not self.robot_loop):
            if not instant:          # on arrival: the sensors now, as the robot's controller
                reading = self.plant.read()
            volts = self.plain
            if self.playing:
                played = self.player.volts(now_s, reading.potentiometer_rad,
                                           reading.velocity_rad_s)
                volts = self.plain if played is None else played
            self.plant.set_voltage(volts)
        if now_ms >= self.next_tick_ms:
            self._tick(now_ms)
            due_s = self.commander.tick_due((now_ms + self.period_ms) / 1000.0)
            self.next_tick_ms = round(1000.0 * due_s)
        self.plant.advance(0.001 * STEP_MS)
        self.now_ms += STEP_MS
        self.history.append((self.now_s, np.array(self.plant.state)))
        self.lowest_m = min(self.lowest_m, self._lowest_m(self.plant.state))

    def _lowest_m(self, state) -> float:
        """The lower of the elbow and the tool (m above the pivot's level)."""
        upper, fore = self.plant.arm.shoulder.length_m, self.plant.arm.elbow.length_m
        elbow_y = upper * math.sin(state[0])
        return min(elbow_y, elbow_y + fore * math.sin(state[0] + state[1]))

    def _tick(self, now_ms: int) -> None:
        heard = [r for r in self.readings if r[0] <= now_ms]
        self.readings = [r for r in self.readings if r[0] > now_ms]
        stamp_s, reading = (heard[-1][1], heard[-1][2]) if heard else (None, None)
        if stamp_s is not None:
            self.clock.observe(stamp_s)
        arrives_s = (now_ms + self.lag_ms) / 1000.0
        acts_s = self.commander.acts_s(arrives_s) if self.mode != 'volts_at_instant' \
            else self.clock.acting_at(arrives_s)
        volts = self.core.step(acts_s, reading, stamp_s).volts
        command = self.commander.command(self.core, volts, acts_s) \
            if self.mode != 'volts_at_instant' else tuple(float(v) for v in volts)
        jitter = int(self.rng.integers(-self.jitter_ms, self.jitter_ms + 1)) if self.jitter_ms \
            else 0
        arrives_ms = now_ms + max(self.lag_ms + jitter, 0)
        if self.commands:            # one publisher's messages arrive in the order sent
            arrives_ms = max(arrives_ms, self.commands[-1][0])
        self.commands.append((arrives_ms, command))
