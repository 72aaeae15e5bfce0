"""K' of a branch: the naive K plus everything the branch has learned, costed by its
experience, and that experience as an episode adds to it."""

from __future__ import annotations

from llcps.errors import LlcpsError, StoreError
from llcps.store import Store
from llcps.symbolic.experience import Context, Experience
from llcps.symbolic.knowledge_base import KnowledgeBase


def load_knowledge(store: Store, branch: str) -> KnowledgeBase:
    """The default K plus every learned operator (and refinement) ``branch`` sees, oldest
    first, costed by the operator executions ``branch`` sees.

    Raises:
        StoreError: a stored operator does not describe an operator, or a stored
            execution's context is malformed (the message names the row).
    """
    kb = KnowledgeBase.default()
    for record in sorted(store.visible_operators(branch), key=lambda r: r.id):
        try:
            kb = kb.apply_learned(record.definition)
        except (LlcpsError, ValueError, TypeError, KeyError, AttributeError, IndexError, RecursionError) as exc:
            detail = exc.message if isinstance(exc, LlcpsError) else f"{type(exc).__name__}: {exc}"
            raise StoreError(
                f"stored operator {record.id} ({record.name!r}) is malformed: {detail}",
                hint="the row was changed outside llcps; delete it or restore the database from a copy",
            ) from None
    return kb.with_experience(load_experience(store, branch))


def load_experience(store: Store, branch: str) -> Experience:
    """The operator executions ``branch`` sees, counted per operator and context."""
    return Experience.from_counts((c.operator, c.context, c.successes, c.failures) for c in store.operator_experience(branch))


class BranchExperience:
    """The operator executions a branch sees, this episode's counted as they happen.

    Every plan step executed counts as an execution of its operator in its context
    (:mod:`llcps.symbolic.experience`), stored and counted here; K costed by these counts
    (:meth:`costed`) demotes an operator that failed before the next plan is made.
    """

    def __init__(self, store: Store, branch: str, *, episode_id: int | None = None, experience: Experience | None = None) -> None:
        """``experience``: what the branch's executions were when read already (e.g. with
        its K by :func:`load_knowledge`); None reads them now."""
        self.store = store
        self.branch = branch
        self.episode_id = episode_id
        self.experience: Experience = load_experience(store, branch) if experience is None else experience
        #: Whether the branch had executions before this episode (see :meth:`taught`).
        self.inherited = bool(self.experience.entries)
        #: This episode's executions alone.
        self.episode: Experience = Experience()

    def costed(self, kb: KnowledgeBase) -> KnowledgeBase:
        """``kb`` costed by the experience the branch has, this episode's included."""
        return kb.with_experience(self.experience)

    def alone(self, kb: KnowledgeBase) -> KnowledgeBase:
        """K without what earlier episodes taught: no learned operators, costed by this
        episode's executions alone. The K an agent reset to its pretraining plans with."""
        return kb.initial().with_experience(self.episode)

    def taught(self, kb: KnowledgeBase) -> bool:
        """Whether earlier episodes taught ``kb`` anything (learned operators, or executions
        before this episode): if not, :meth:`alone` and :meth:`costed` are the same K."""
        return bool(kb.learned) or self.inherited

    def knowledge(self, kb: KnowledgeBase) -> tuple[KnowledgeBase, ...]:
        """K' costed by experience, then K alone if earlier episodes made them differ."""
        return (self.costed(kb), self.alone(kb)) if self.taught(kb) else (self.costed(kb),)

    def record(self, operator: str, context: Context, success: bool, trial_id: int | None) -> None:
        """Store one execution of ``operator`` as a plan step in ``context``; the
        operator's cost follows from the counts."""
        self.store.add_operator_execution(
            branch=self.branch,
            operator=operator,
            success=success,
            context=sorted(context),
            episode_id=self.episode_id,
            trial_id=trial_id,
        )
        self.count(operator, context, success)

    def count(self, operator: str, context: Context, success: bool) -> None:
        """Count one execution in memory (the branch's experience and this episode's)."""
        self.experience = self.experience.added(operator, context, success)
        self.episode = self.episode.added(operator, context, success)
