"""The optimisation problems Theta1..Theta4 of the paper (sections 7.2-7.5)."""

from planner.problems.base import ThetaOptions, ThetaProblem, ThetaSolution
from planner.problems.theta1 import Theta1
from planner.problems.theta2 import Theta2
from planner.problems.theta3 import Theta3
from planner.problems.theta4 import Theta4

__all__ = ["Theta1", "Theta2", "Theta3", "Theta4", "ThetaOptions", "ThetaProblem", "ThetaSolution"]
