"""Motion pieces.

The trajectory tau, interpolation along leaves (section 7.4), footholds, swings, the time
law, the guide path, the gait order.
"""
