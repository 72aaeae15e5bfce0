"""llcps: life-long creative problem solving with world models.

A PyBullet robot with a symbolic PDDL knowledge base runs plans; a novelty makes a
plan fail; the robot explores alternative action parameterizations, guided by a
world model trained on every trial it has ever executed, until it resolves the
novelty and learns a new operator.
"""

__version__ = "0.1.0"
