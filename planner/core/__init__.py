"""Foundations, importing nothing of the planner.

Errors, interrupts, output files, the machine, Lie groups, leg names.
"""
