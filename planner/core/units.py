"""Physical constants shared by every layer, in SI units."""

GRAVITY_M_S2 = 9.81  # standard gravity's magnitude [m/s^2]: statics, checks, the simulator

__all__ = ["GRAVITY_M_S2"]
