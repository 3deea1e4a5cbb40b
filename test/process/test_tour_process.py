"""The main job: sim, planner and controller as processes, and a tour of presets."""

import re


def test_tour_reaches_its_goals_and_ends(launch):
    for name in ('sim', 'planner', 'controller'):
        launch(name)
    tour = launch('tour', '-p', 'goals:=[mid_score, back_score, stow]', '-p', 'loops:=1')
    assert tour.process.wait(timeout=120) == 0, tour.output()
    output = tour.output()
    assert 'tour finished' in output
    live = output.split('tour finished')[0]          # the per-goal lines, not the summary
    reached = re.findall(r'(\w+) \([^)]*\) m: reached in ([\d.]+) s, held ([\d.]+) mm from',
                         live)
    assert [name for name, _, _ in reached] == ['mid_score', 'back_score', 'stow'], output
    for _, seconds, error_mm in reached:
        assert float(seconds) < 10.0
        assert float(error_mm) < 1.8 * 17.45      # 1 deg on each joint at full reach
