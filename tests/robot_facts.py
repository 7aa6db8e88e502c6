"""ROBOT.md's dimensions and closed-form IK, written out again so that the tests do not
trust the code under test (test_two_hosts.py and security_rig.py use them)."""

import math

# metres: shoulder height, main arm, forearm, tool offset beyond the wrist
H, L2, L3, TOOL_DX = 0.094, 0.135, 0.147, 0.0393


def ik(x, y, z):
    """Closed-form IK of ROBOT.md: (base, shoulder, elbow), radians."""
    base = math.atan2(y, x)
    r, h = math.hypot(x, y) - TOOL_DX, z - H
    s2 = r * r + h * h
    cos_e = (s2 - L2 * L2 - L3 * L3) / (2 * L2 * L3)
    sin_e = -math.sqrt(((L2 + L3) ** 2 - s2) * (s2 - (L2 - L3) ** 2)) / (2 * L2 * L3)
    elbow = math.atan2(sin_e, cos_e)
    shoulder = math.atan2(h, r) - math.atan2(L3 * sin_e, L2 + L3 * cos_e)
    return base, shoulder, elbow


def servo_deg(x, y, z):
    """The servo horn angles (degrees) of base, main arm and forearm at rest at (x, y, z):
    the IK above and ROBOT.md's default servo mapping."""
    base, shoulder, elbow = ik(x, y, z)
    d = math.degrees
    return [90 - 2 * d(base), 180 - d(shoulder), 90 + d(shoulder + elbow)]
