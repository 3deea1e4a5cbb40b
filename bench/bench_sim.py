"""How fast the simulated physics runs, and what its step size buys.

For RK4 substeps of 1, 0.5 and 0.25 ms (and 20 ms, the step GoArmSim used): the cost of one
20 ms control period of simulated time, the real-time factor, and the energy error of a
10 s unpowered swing (no friction, τ = 0: energy must be conserved), and the angle error of
2 s of ±12 V square waves against a 0.0625 ms reference (the motors' back-EMF is the stiff
part of this system).

    python bench/bench_sim.py
"""

import statistics
import time

from arm_control import config
from arm_control.model.dynamics import ArmDynamics, rk4
from arm_control.model.plant import ArmPlant

CONTROL_PERIOD_S = 0.02


def period_cost_s(arm, step_s, repeats=200):
    plant = ArmPlant(arm, (0.3, 0.5), physics_step_s=step_s)
    plant.set_voltage((3.0, -2.0))
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        plant.advance(CONTROL_PERIOD_S)
        plant.read()
        samples.append(time.perf_counter() - start)
    return statistics.median(samples)


def energy_error(arm, step_s, duration_s=10.0):
    dynamics = ArmDynamics(arm)
    state = [0.3, 0.5, 0.0, 0.0]
    energy = dynamics.energy_j(state)
    swing = energy - dynamics.energy_j([-1.5708, 0.0, 0.0, 0.0])
    worst = 0.0
    for _ in range(round(duration_s / step_s)):
        state = rk4(dynamics.derivative_with_torque, state, (0.0, 0.0), step_s)
        worst = max(worst, abs(dynamics.energy_j(state) - energy))
        if worst > swing:
            return float('inf')
    return worst / swing


def powered_error_rad(arm, step_s, reference_step_s=0.0000625, duration_s=2.0):
    """Largest joint-angle error over 2 s of ±12 V square waves against a fine step.

    The waves keep both joints clear of their hard stops, whose clamping is only first order.
    """
    def run(step):
        plant = ArmPlant(arm, (1.2, -1.0), physics_step_s=step)
        trace = []
        for period in range(round(duration_s / CONTROL_PERIOD_S)):
            sign = 1.0 if (period // 15) % 2 == 0 else -1.0
            plant.set_voltage((12.0 * sign, -12.0 * sign))
            plant.advance(CONTROL_PERIOD_S)
            trace.append(plant.state[:2])
        return trace
    reference = run(reference_step_s)
    return max(abs(a - b) for got, want in zip(run(step_s), reference)
               for a, b in zip(got, want))


def main():
    arm, _ = config.load('sim')
    print('| RK4 step | cost of one 20 ms period | real-time factor | '
          'energy error, 10 s unpowered swing | angle error, 2 s at 12 V |')
    print('|---|---|---|---|---|')
    for step_s in (0.001, 0.0005, 0.00025, 0.02):
        cost = period_cost_s(arm, step_s)
        error = energy_error(arm, step_s)
        error_text = 'diverged' if error == float('inf') else f'{100 * error:.2e} %'
        powered = powered_error_rad(arm, step_s)
        print(f'| {1000 * step_s:g} ms | {1e6 * cost:.0f} µs | {CONTROL_PERIOD_S / cost:.0f}× | '
              f'{error_text} | {powered:.1e} rad |')


if __name__ == '__main__':
    main()
