"""The core's goals: the one being worked on and those waiting, in the order they go."""

from collections import deque
from typing import Optional

from arm_control.plans.goals import Goal


class GoalQueue:
    """The goal being worked on and the goals waiting, in the order they will be visited;
    ``version`` changes whenever they do (the node republishes the queue then)."""

    def __init__(self, size: int):
        self.size = size
        self.waiting: deque[Goal] = deque()
        self.current: Optional[Goal] = None
        self.version = 0

    def __len__(self) -> int:
        return len(self.waiting) + (self.current is not None)

    @property
    def full(self) -> bool:
        return len(self.waiting) >= self.size

    def append(self, goal: Goal) -> None:
        self.waiting.append(goal)
        self.version += 1

    def start_next(self) -> Goal:
        self.current = self.waiting.popleft()
        self.version += 1
        return self.current

    def start(self, goal: Goal) -> None:
        self.current = goal
        self.version += 1

    def finish(self) -> Optional[Goal]:
        """The current goal is done (reached or failed): returns it."""
        goal, self.current = self.current, None
        self.version += 1
        return goal

    def put_back(self) -> None:
        """Interrupted (the sensors stopped, the arm was moved): the current goal goes first
        again, unless it is a client's trajectory (``replan`` False), which ends there."""
        if self.current is not None:
            if self.current.replan:
                self.waiting.appendleft(self.current)
            self.current = None
            self.version += 1

    def clear(self) -> int:
        """Drop every goal; returns how many there were."""
        dropped = len(self)
        if dropped:
            self.version += 1
        self.waiting.clear()
        self.current = None
        return dropped

    def pending(self) -> list[Goal]:
        """The current goal (first) and the waiting ones."""
        return ([self.current] if self.current is not None else []) + list(self.waiting)
