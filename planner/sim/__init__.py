"""The simulator.

LittleDog in MuJoCo (section 10), executed open loop, with feedback (8.3) or correction (8.4).
"""
