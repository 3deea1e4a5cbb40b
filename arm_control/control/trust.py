"""What the controller cannot trust, said as events, and what it does about it.

DDS, as these wheels ship it (no security plugins), lets any process on the domain publish
any topic and take any node name. So the controller watches for what it cannot tell apart:

- another publisher of an input it depends on (``joint_states``, ``/clock`` in simulated
  time) or of its output (``voltage_command``: another controller driving the same motors),
  and another node of its own name: an ``untrusted`` event (cause: the topic or the name),
  at error level, and ``trusted`` when it ends. While joint_states has another publisher,
  a reading that leaps away from the estimate is refused (``Sensing.refuse_leaps``): the arm
  is held where the trusted estimate says, not re-held where the leap says. (The node also
  sets it as each reading comes: DDS matches a publisher before its first message arrives,
  so the first leap is already refused, before the graph is next watched);
- readings that disagree with each other or with physics: a leap of the potentiometers no
  motor could make, where the encoders say the arm did not move, is refused
  (``Sensing._refused``) and said as ``sensors_disagree`` -- the first at once, then a count
  per window;
- the clock jumping (``ClockGuard``): each jump said as ``clock_jumped``; control time goes
  on from where it was.
"""

from dataclasses import dataclass

from arm_control.control.events import EventKind as Kind

# Refusals beyond the first are said at most once per this window (s of control time).
SAY_EVERY_S = 1.0


@dataclass(frozen=True)
class GraphCounts:
    """What the ROS graph shows: publishers of each watched topic, and nodes of this name
    (the node's own publisher and name included)."""

    joint_states: int
    clock: int                  # 0 when the node does not run on /clock
    voltage_command: int
    same_name: int

    def problems(self) -> dict:
        """{cause: sentence} for each count above one."""
        said = {}
        for cause, count, what in (
                ('joint_states', self.joint_states, 'readings may come from elsewhere; a '
                 'reading that leaps from the estimate is refused while this lasts'),
                ('/clock', self.clock, 'time may jump; each jump is taken out of control '
                 'time'),
                ('voltage_command', self.voltage_command, 'another node commands the motors: '
                 'of two controllers the one that took the arm first keeps it, the other '
                 'yields (voltage_command_claim); one that claims nothing cannot be stopped '
                 'from here'),
                ('node name', self.same_name, 'its parameters, services and states may be '
                 'answered by another node')):
            if count > 1:
                noun = 'nodes of this name' if cause == 'node name' else f'publishers of {cause}'
                said[cause] = f'{count} {noun}, one expected: {what}'
        return said


class TrustWatch:
    """Turns what the node sees into the core's events and reactions."""

    def __init__(self, core):
        self.core = core
        self.problems: dict = {}            # cause -> sentence, said while it lasts
        self.refused_said = 0
        self.refusals_said_s = -float('inf')
        self.clock_jumps = 0

    def graph(self, now_s: float, counts: GraphCounts) -> None:
        """Say each problem as it begins and ends; refuse leaps while joint_states has
        another publisher."""
        problems = counts.problems()
        for cause, sentence in problems.items():
            if self.problems.get(cause) != sentence:
                self.core.events.say(now_s, Kind.UNTRUSTED, 'error', sentence, cause)
        for cause in set(self.problems) - set(problems):
            self.core.events.say(now_s, Kind.TRUSTED, 'info', f'one publisher of {cause} '
                                 'again' if cause != 'node name' else 'one node of this name '
                                 'again', cause)
        self.problems = problems
        self.core.sensing.refuse_leaps = 'joint_states' in problems

    def step(self, now_s: float, clock_jumps_s=()) -> None:
        """After a control step: the clock's jumps, and readings refused since the last."""
        for jump_s in clock_jumps_s:
            self.clock_jumps += 1
            self.core.events.say(now_s, Kind.CLOCK_JUMPED, 'warning',
                                 f'the clock jumped {jump_s:+.3f} s: taken out, control time '
                                 'goes on from where it was', 'jump')
        sensing = self.core.sensing
        new = sensing.refused - self.refused_said
        if new and (self.refused_said == 0 or now_s - self.refusals_said_s >= SAY_EVERY_S):
            cause, why = sensing.refusal
            more = f' ({new} readings refused since the last said)' if new > 1 else ''
            self.core.events.say(now_s, Kind.SENSORS_DISAGREE, 'warning',
                                 f'joint_states refused: {why}; held where the estimate '
                                 f'says{more}', cause)
            self.refused_said, self.refusals_said_s = sensing.refused, now_s

    @property
    def level(self) -> str:
        """'error' while an input is untrusted, else 'ok'."""
        return 'error' if self.problems else 'ok'
