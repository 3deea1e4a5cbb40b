"""Inputs beyond what the controller answers one by one: dropped before they reach the core,
counted, and said.

Each kind of input passes a token bucket: ``rate_hz`` a second on average, ``burst`` at once
(wall time); and all of them share one of work: the core's time they take (``spent``, under
the node's lock) is at most ``WORK_SHARE`` of the wall time, ``WORK_BURST_S`` at once. Each
input answered holds the core's lock (and Python's) for its work, which a loaded machine
stretches: at their rates alone, floods on every input could keep the executor behind the
joint states and the loop waiting for the lock. What passes is answered one by one (queued,
accepted or rejected, with the reason); what does not is counted, and the node says each
second's count as one
``goals_rejected`` event (its first word the number, as the core's own summaries), adds it
to the goals rejected in its diagnostics, and logs it. Every input is then answered or
counted, and a flood costs the process a message's take, not the core's lock and a publish
per message.
"""

from dataclasses import dataclass

from arm_control.control.events import EventKind as Kind


@dataclass(frozen=True)
class Rate:
    """What a kind of input may bring: on average ``rate_hz`` a second, ``burst`` at once."""

    rate_hz: float
    burst: float


WORK_SHARE = 0.2          # of the wall time, at most, the core's work for inputs
WORK_BURST_S = 0.05      # ... at most this much of it at once (s)
# A script's batch of goals passes whole (the queue holds 32); a driver's stick streams at
# 50-100 Hz; a preset is a button.
RATES = {'goal_point': Rate(100.0, 100.0), 'goal_preset': Rate(20.0, 10.0),
         'driver_velocity': Rate(200.0, 20.0)}


class InputGate:
    """``admit(kind, wall_s)`` for each input as it arrives; ``flush`` says what was dropped.
    One thread (the node's executor) calls both."""

    def __init__(self, rates=RATES, work_share: float = WORK_SHARE,
                 work_burst_s: float = WORK_BURST_S):
        self.rates = dict(rates)
        self.work_share, self.work_burst_s = work_share, work_burst_s
        self.work_s, self.work_last_s = work_burst_s, None      # the shared bucket of work
        self.busy = 0                                           # dropped for want of it
        self.tokens = {kind: rate.burst for kind, rate in self.rates.items()}
        self.last_s = dict.fromkeys(self.rates)
        self.dropped = dict.fromkeys(self.rates, 0)       # since start, per kind
        self._unsaid = dict.fromkeys(self.rates, 0)
        self._since_s = None

    def admit(self, kind: str, wall_s: float) -> bool:
        """True: answer it; False: it is counted as dropped."""
        rate = self.rates[kind]
        last = self.last_s[kind]
        if last is not None:
            self.tokens[kind] = min(rate.burst,
                                    self.tokens[kind] + rate.rate_hz * max(wall_s - last, 0.0))
        self.last_s[kind] = wall_s
        if self.work_last_s is not None:
            self.work_s = min(self.work_burst_s, self.work_s + self.work_share * max(
                wall_s - self.work_last_s, 0.0))
        self.work_last_s = wall_s
        if self.tokens[kind] >= 1.0 and self.work_s > 0.0:
            self.tokens[kind] -= 1.0
            return True
        self.busy += self.tokens[kind] >= 1.0
        self.dropped[kind] += 1
        self._unsaid[kind] += 1
        if self._since_s is None:
            self._since_s = wall_s
        return False

    def spent(self, seconds: float) -> None:
        """The core's time an input admitted took: taken from the shared bucket of work."""
        self.work_s -= max(float(seconds), 0.0)

    def flush(self, core, now_s: float, wall_s: float) -> int:
        """Add what was dropped since the last flush to the core's goals rejected, and say
        it as one ``goals_rejected`` event; returns how many (0: nothing said)."""
        total = sum(self._unsaid.values())
        if not total:
            return 0
        kinds = ', '.join(f'{count} {kind} (more than {self.rates[kind].rate_hz:g} a second, '
                          f'or beyond {self.work_share:.0%} of the time in work)'
                          for kind, count in self._unsaid.items() if count)
        core.goals.counts['rejected'] += total
        core.events.say(now_s, Kind.GOALS_REJECTED, 'warning',
                        f'{total} more goals rejected in the last '
                        f'{wall_s - self._since_s:.1f} s: dropped unread, {kinds}', 'flood')
        self._unsaid = dict.fromkeys(self.rates, 0)
        self._since_s = None
        return total
