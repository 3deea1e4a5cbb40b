"""The controller's state machine (arm paper §6.2): explicit states, explicit transitions.

Every allowed transition is one row of ``TRANSITIONS``; anything else is refused, so the
arm never reaches a state by an unplanned path. What the arm does in each state:

    no_sensors  no joint states yet, or they stopped: 0 V (nothing to close the loop on)
    waiting     no goal: holds where it is
    planning    a goal is being planned: holds, or keeps to its current motion if preempted
    tracking    following a trajectory to the goal
    holding     at the goal (finished): holds it, dwells, then takes the next goal
    error       the last goal failed (rejected, no plan): holds where it is
    estopped    stopped until reset: an e-stop by service brakes to rest and holds there
                (``estop_holds_arm``: at 0 V a 45 kg arm with no brake falls); one that
                control itself failed (tracking error, a joint past its limit), a second
                e-stop, or losing the sensors meanwhile: 0 V
    disabled    0 V until enabled
    driver      end-effector velocity commands from a driver
"""

from enum import Enum


class ArmState(str, Enum):
    NO_SENSORS = 'no_sensors'
    WAITING = 'waiting'
    PLANNING = 'planning'
    TRACKING = 'tracking'
    HOLDING = 'holding'
    ERROR = 'error'
    ESTOPPED = 'estopped'
    DISABLED = 'disabled'
    DRIVER = 'driver'

    def __str__(self) -> str:
        return self.value


class Trigger(str, Enum):
    SENSORS_BACK = 'sensors_back'      # joint states (again) fresh
    SENSORS_BACK_HELD = 'sensors_back_held'  # fresh again, and back to the goal it held
    SENSORS_LOST = 'sensors_lost'      # no joint states for joint_state_timeout_s
    GOAL = 'goal'                      # a goal becomes current: plan it
    PLAN_READY = 'plan_ready'          # a timed, checked trajectory is accepted
    PLAN_FAILED = 'plan_failed'        # no plan, planner timeout, untimeable path
    ARRIVED = 'arrived'                # within tolerance and still
    GOAL_FAILED = 'goal_failed'        # a goal was rejected while idle
    CANCEL = 'cancel'                  # queue cleared: hold
    ESTOP = 'estop'
    RESET = 'reset'                    # clears an e-stop or an error
    DISABLE = 'disable'
    ENABLE = 'enable'
    DRIVER_COMMAND = 'driver_command'
    DRIVER_IDLE = 'driver_idle'        # driver commands stopped and the arm is still
    MOVED = 'moved'                    # the sensors jumped: the arm was moved, the sim reset

    def __str__(self) -> str:
        return self.value


S, T = ArmState, Trigger
# The states in which the controller commands the motors to follow a setpoint.
COMMANDING = frozenset({S.WAITING, S.PLANNING, S.TRACKING, S.HOLDING, S.ERROR, S.DRIVER})
# The states that take no goal and follow no plan: 0 V, but for an e-stop holding the arm.
STOPPED = frozenset({S.NO_SENSORS, S.ESTOPPED, S.DISABLED})

TRANSITIONS: dict[tuple[ArmState, Trigger], ArmState] = {
    (S.NO_SENSORS, T.SENSORS_BACK): S.WAITING,
    (S.NO_SENSORS, T.SENSORS_BACK_HELD): S.HOLDING,
    (S.NO_SENSORS, T.CANCEL): S.NO_SENSORS,
    (S.NO_SENSORS, T.ESTOP): S.ESTOPPED,
    (S.NO_SENSORS, T.DISABLE): S.DISABLED,

    (S.WAITING, T.GOAL): S.PLANNING,
    (S.WAITING, T.GOAL_FAILED): S.ERROR,
    (S.WAITING, T.CANCEL): S.WAITING,

    (S.PLANNING, T.PLAN_READY): S.TRACKING,
    (S.PLANNING, T.PLAN_FAILED): S.ERROR,
    (S.PLANNING, T.GOAL): S.PLANNING,          # a preempting goal replaces the pending one
    (S.PLANNING, T.CANCEL): S.WAITING,

    (S.TRACKING, T.ARRIVED): S.HOLDING,
    (S.TRACKING, T.GOAL): S.PLANNING,          # preempted: replan from the moving state
    (S.TRACKING, T.CANCEL): S.WAITING,

    (S.HOLDING, T.GOAL): S.PLANNING,
    (S.HOLDING, T.GOAL_FAILED): S.ERROR,
    (S.HOLDING, T.CANCEL): S.WAITING,

    (S.ERROR, T.GOAL): S.PLANNING,
    (S.ERROR, T.GOAL_FAILED): S.ERROR,
    (S.ERROR, T.RESET): S.WAITING,
    (S.ERROR, T.CANCEL): S.WAITING,

    (S.DRIVER, T.DRIVER_IDLE): S.WAITING,
    (S.DRIVER, T.GOAL): S.PLANNING,
    (S.DRIVER, T.CANCEL): S.WAITING,

    (S.ESTOPPED, T.RESET): S.WAITING,
    (S.ESTOPPED, T.CANCEL): S.ESTOPPED,

    (S.DISABLED, T.ENABLE): S.WAITING,
    (S.DISABLED, T.CANCEL): S.DISABLED,
    (S.DISABLED, T.ESTOP): S.ESTOPPED,
}
# From every state that commands the motors: e-stop, disable, losing the sensors, the arm
# found elsewhere (hold there, then replan), and a driver taking over.
for _state in COMMANDING:
    TRANSITIONS[(_state, T.ESTOP)] = S.ESTOPPED
    TRANSITIONS[(_state, T.MOVED)] = S.WAITING
    TRANSITIONS[(_state, T.DISABLE)] = S.DISABLED
    TRANSITIONS[(_state, T.SENSORS_LOST)] = S.NO_SENSORS
    if _state != S.DRIVER:
        TRANSITIONS[(_state, T.DRIVER_COMMAND)] = S.DRIVER


class InvalidTransition(RuntimeError):
    """A trigger that the current state does not accept."""


class StateMachine:
    """The current state and the one way to change it: ``fire(trigger)``."""

    def __init__(self, initial: ArmState = ArmState.NO_SENSORS):
        self.state = initial
        self.history: list[tuple[ArmState, Trigger, ArmState]] = []

    def can(self, trigger: Trigger) -> bool:
        return (self.state, trigger) in TRANSITIONS

    def fire(self, trigger: Trigger) -> ArmState:
        """Take the transition ``trigger`` names from the current state, or raise."""
        try:
            target = TRANSITIONS[(self.state, trigger)]
        except KeyError:
            raise InvalidTransition(
                f"'{trigger}' is not allowed in state '{self.state}'") from None
        self.history.append((self.state, trigger, target))
        del self.history[:-100]
        self.state = target
        return target

    def __str__(self) -> str:
        return str(self.state)
