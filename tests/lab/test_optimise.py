"""The moment fit's search: a scan of the new coordinates, then Brent's method (one free
coordinate) or Nelder-Mead (several)."""

import numpy as np

# private: the search kernel's accuracy and evaluation count, which no fit output isolates
from gift_theory.lab._fit_moments import XATOL, optimise


class Counted:
    def __init__(self, f):
        self.f, self.n = f, 0

    def __call__(self, th):
        self.n += 1
        return self.f(np.asarray(th, np.float64))


def test_one_coordinate_reaches_the_minimum_between_grid_points_in_few_evaluations():
    grid = np.linspace(-3.0, 3.0, 16)
    for t_star in (-2.17, 0.031, 1.4):  # off the grid: the scan alone is 0.2 away
        f = Counted(lambda th: 3.0 * (th[0] - t_star) ** 2 + 0.2 * (th[0] - t_star) ** 4 + 5.0)
        theta, val = optimise(f, np.array([0.0]), {0: grid})
        assert abs(theta[0] - t_star) < 3 * XATOL
        assert val <= 5.0 + 3.0 * (3 * XATOL) ** 2
        assert f.n - len(grid) <= 15, f.n  # Nelder-Mead needed 22-31 on the lab's losses


def test_one_coordinate_still_falling_at_the_bracket_limit_keeps_the_best_value_found():
    # no minimum in reach (a loss that keeps falling): the search may not return worse than its start
    f = Counted(lambda th: -float(th[0]))
    theta, val = optimise(f, np.array([0.0]), {0: np.linspace(-1.0, 1.0, 5)})
    assert val <= -1.0 and np.isfinite(val)
    assert val == f(theta)


def test_several_coordinates_go_to_nelder_mead_and_reach_the_minimum():
    t_star = np.array([0.37, -1.2])
    f = Counted(lambda th: float(np.sum((th - t_star) ** 2 * np.array([1.0, 4.0])) + 0.5 * (th[0] - t_star[0]) * (th[1] - t_star[1])))
    theta, val = optimise(f, np.array([0.0, 0.0]), {1: np.linspace(-2.0, 2.0, 9)})
    np.testing.assert_allclose(theta, t_star, atol=0.02)
    assert val < 1e-3
