"""When two bodies touch: the contact distance every contact query filters on.

The robot's grasp test, the controllers' checks and perception's ``touching`` all
read contacts the same way, through here.
"""

from __future__ import annotations

from typing import Any

#: Contact distance below which two bodies touch (m); manifolds also keep points
#: a little apart, so every contact query filters on distance.
TOUCH_DISTANCE = 0.002


def in_contact(client: Any, a: int, b: int, link_a: int = -2) -> bool:
    """Whether bodies ``a`` (optionally only its link ``link_a``) and ``b`` touch now."""
    points = client.getContactPoints(a, b) if link_a == -2 else client.getContactPoints(a, b, link_a)
    return any(cp[8] <= TOUCH_DISTANCE for cp in points)
