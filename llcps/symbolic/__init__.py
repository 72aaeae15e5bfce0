"""The symbolic half: the knowledge base K in PDDL, the planner, an independent plan
validator, the execution monitor, and learned operators (K -> K'). See docs/knowledge.md."""
