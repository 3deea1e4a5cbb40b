"""The identification drive in two stages: learn the arm gently, then push it.

Stage 1 moves from where the arm is to the centre, then makes each joint's quasistatic
sweeps and the coupled multi-sine, designed and tracked with the robot file's model. What it
logged is fitted (gravity and friction are well known by then, the inertias nearly), and
stage 2 -- each joint's fast sweeps and dynamic steps, the fastest parts -- is designed (its
current checked) and tracked with that model. So a robot file that is far off (the demo's
forearm is half as heavy again as its file says, with twice the moment) neither overloads a
motor nor loses track where it matters most. If the stage-1 fit fails, stage 2 uses the robot file.

``Session`` is shared by the node (which fits between the stages on a worker thread while
the arm is held at the centre) and the in-process run (``simulated``).
"""

from dataclasses import replace

from arm_control.config import ArmConfig
from arm_control.sysid.excitation import (design_excitation, DYNAMIC, ExcitationRun, FAST,
                                          MULTISINE, QUASISTATIC)
from arm_control.sysid.fit import fit_log
from arm_control.sysid.handover import holding, lowering
from arm_control.sysid.log import Log
from arm_control.sysid.quality import identified_values
from arm_control.sysid.regressor import RealisationError, with_values
from arm_control.sysid.settings import SysIdConfig


def provisional_model(log: Log, nominal: ArmConfig, settings: SysIdConfig):
    """The arm stage 1's log says (``(ArmConfig, note)``), or the robot file's and why."""
    try:
        fit = fit_log(log, nominal, settings.smoothing_window_s, settings.max_command_lag_s,
                      settings.min_speed_rad_s)
        return with_values(nominal, identified_values(fit, nominal)[0].values), \
            'stage 2 designed and tracked with the stage-1 fit'
    except (ValueError, RealisationError) as error:
        return nominal, f'stage 2 designed and tracked with the robot file: stage 1 gave {error}'


class Session:
    """Both stages, one after the other: ``command`` gives the voltages throughout."""

    def __init__(self, nominal: ArmConfig, settings: SysIdConfig, start_rad):
        self.nominal, self.settings = nominal, settings
        excitation, notes = design_excitation(nominal, settings, start_rad,
                                              kinds=(QUASISTATIC, MULTISINE))
        self.notes = list(notes)
        self.run = ExcitationRun(nominal, settings, excitation)
        self.stage = 1
        self.began_s = None             # the first command's time

    @property
    def stopped(self):
        return self.run.stopped

    @property
    def reference(self):
        """(q, q̇) the last command was computed for: the plan, logged as the instruments."""
        return self.run.reference

    def command(self, now_s, position, velocity, bus_v=None):
        if self.began_s is None:
            self.began_s = now_s
        return self.run.command(now_s, position, velocity, bus_v)

    def elapsed_s(self, now_s) -> float:
        """Arm time: since the first command."""
        return 0.0 if self.began_s is None else now_s - self.began_s

    def label_at(self, now_s) -> str:
        if self.stage == 1 and self.run.finished(now_s) and self.run.stopped is None:
            return 'holding for the stage-1 fit'
        return self.run.label_at(now_s)

    def stage_one_done(self, now_s) -> bool:
        """Stage 1 is over (and not stopped): time to fit it and call ``begin_stage_two``;
        meanwhile ``command`` holds the arm at the centre."""
        return self.stage == 1 and self.run.stopped is None and self.run.finished(now_s)

    def begin_stage_two(self, model: ArmConfig, note: str) -> None:
        self.notes.append(note)
        try:
            excitation, notes = design_excitation(
                model, self.settings, kinds=(FAST, DYNAMIC),
                current_share=self.settings.stage_two_current_share)
        except ValueError as error:
            self.notes.append(f'no dynamic steps: {error}')
            self.stage = 2
            return
        self.notes += notes
        self._take(ExcitationRun(model, self.settings, excitation))
        self.stage = 2

    def _take(self, run: ExcitationRun) -> None:
        """Drive ``run`` from now on, keeping the list of stalls ridden through."""
        run.stalls = self.run.stalls
        self.run = run

    @property
    def stalls(self) -> list:
        return self.run.stalls

    def finished(self, now_s) -> bool:
        if self.run.stopped is not None:
            return self.run.finished(now_s)
        return self.stage == 2 and self.run.finished(now_s)

    def hold(self, model: ArmConfig, q) -> None:
        """From now on hold the arm at ``q`` with ``model`` (after the excitation)."""
        self._take(ExcitationRun(model, self.settings, holding(q)))
        self.stage = 3

    def lower(self, model: ArmConfig, q, rest) -> None:
        """From now on lower the arm from ``q`` onto ``rest`` with ``model``; ValueError when
        the way is not free. Forbidden space is watched without a margin: a rest may be
        near it."""
        self._take(ExcitationRun(model, replace(self.settings, margin_rad=0.0),
                                 lowering(model, q, rest)))
        self.stage = 3
