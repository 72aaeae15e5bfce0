"""The documented bounds of everything llcps reads: one list, the same for a scenario
file as for a scene read back from the store.

Input comes from files a user names and from databases someone else may have written;
either can be damaged or hostile. A value beyond these bounds is refused with the file
(or row) and field named, before anything is simulated, planned or stored, so that a
file of a few kilobytes can neither hold the planner for hours nor fill the memory.
docs/scenarios.md ("Limits") lists them with their reasons.
"""

from __future__ import annotations

# -- files a user names ----------------------------------------------------------------

#: Largest scenario file (bytes): the shipped ones are 1-3 kB.
MAX_SCENARIO_FILE_BYTES = 1 << 20
#: Largest results file (results.csv or results.json, bytes): ~200 bytes a row, so
#: about 300,000 rows.
MAX_RESULTS_FILE_BYTES = 64 << 20
#: Largest file a report embeds (a film or plot in report.html, bytes).
MAX_EMBEDDED_BYTES = 64 << 20
#: Deepest nesting of tables and arrays in a scenario file (the format needs 6:
#: conditions.novelty.entities.bin.size with a range in it).
MAX_FILE_DEPTH = 8
#: Most items in one array or table of a scenario file.
MAX_FILE_ITEMS = 256
#: Longest text in a scenario file (a title or story, in characters).
MAX_TEXT = 4096

# -- scenes: files and stored snapshots alike -------------------------------------------

#: Most entities (objects and containers) a scene may hold. The planner grounds every
#: operator over every entity: its state space grows exponentially with them.
MAX_ENTITIES = 12
#: Most bodies (entities and fixtures, a shelf's post included) a scene may hold.
MAX_SCENE_BODIES = 64
#: Most atoms in a goal.
MAX_GOAL_ATOMS = 32
#: Largest extent of a body (m), farthest position from the robot's base (m), heaviest
#: body (kg), longest name (characters).
MAX_EXTENT = 10.0
MAX_DISTANCE = 100.0
MAX_MASS = 1000.0
MAX_NAME = 64
#: Largest Coulomb friction coefficient of a body or the table.
MAX_FRICTION = 10.0
#: Largest grip (N) a scene may give the robot.
MAX_GRIP_FORCE = 1000.0

# -- the candidate grid exploration searches -------------------------------------------

#: End-effector speeds (m/s) a grid may list: the Panda's end effector moves at most
#: about 1.7 m/s, and a controller needs a few steps per centimetre.
MIN_RATE = 0.01
MAX_RATE = 2.0
#: Longest motion (m) a grid may list: beyond the arm's whole reach.
MAX_MOVEMENT_MAGNITUDE = 1.0
#: Most values on one axis of the grid (rates, movement magnitudes; the default grid
#: lists 3 of each).
MAX_GRID_VALUES = 8
#: Most points of the grid: 8 rates x 8 magnitudes x the 4 orientations. The candidates
#: of one failed action are its argument choices times this.
MAX_GRID_POINTS = 256

# -- the planner -----------------------------------------------------------------------

#: Most ground actions the planner builds for one task.
MAX_GROUND_ACTIONS = 20_000
#: Most states the planner holds at once (reached, with their cost and parent): with
#: well under 1 kB a state (measured: 1M states, 600 MB) this bounds its memory to tens of MB.
MAX_PLANNER_STATES = 20_000
