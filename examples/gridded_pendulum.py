"""The damped pendulum of ``damped_pendulum.py`` with its state space as a grid, so that
``evaluate --optimum`` can answer whether the task is feasible and where a trained controller
stands: it solves the task, each action held for the task's 0.1 s control period, by dynamic
programming on that grid and judges the grid's controller from the starts the trained one is
judged from. From this directory:

    diffcontrol train damped_pendulum:DampedPendulum --out runs/damped
    diffcontrol evaluate runs/damped --task gridded_pendulum:GriddedPendulum --optimum 401
"""

import numpy as np
from damped_pendulum import DampedPendulum

from diffcontrol.optimal import GridAxis


class GriddedPendulum(DampedPendulum):
    name = "user-damped-pendulum-grid"  # a name of its own: both may be used in one process

    def state_grid(self, params):
        # phi wraps around; phi' within +-10 rad/s (passing the bottom with the energy to
        # reach the top is sqrt(4 g) = 6.3 rad/s)
        return GridAxis(-np.pi, np.pi, periodic=True), GridAxis(-10.0, 10.0)
