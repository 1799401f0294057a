"""stratawalk: quasi-static quadruped planning in a stratified configuration space."""

__version__ = "0.1.0"
