"""The optimisation problems Theta1..Theta4 of the paper (sections 7.2-7.5), and their options.

The problems load CasADi; they are imported on first use (PEP 562) so that the light
:mod:`planner.problems.options` (the command line's settings) loads without it.
"""

from importlib import import_module

_WHERE = {
    "ThetaOptions": "options",
    "ThetaProblem": "base",
    "ThetaSolution": "base",
    "Theta1": "theta1",
    "Theta2": "theta2",
    "Theta3": "theta3",
    "Theta4": "theta4",
}

__all__ = ["Theta1", "Theta2", "Theta3", "Theta4", "ThetaOptions", "ThetaProblem", "ThetaSolution"]


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(import_module(f"planner.problems.{_WHERE[name]}"), name)
    raise AttributeError(f"module 'planner.problems' has no attribute {name!r}")
