"""When a scheduled model fits its bins, calibration and learner, and when it only counts.

Naive Bayes learns counts, and counts add up: the counts of a training set are those of
its first trials plus those of the rest. What does not add up is what the counts are
*of*: Omega's naive Bayes binarizes each continuous feature at the training mean, and
the goal head's at its stratum's quartiles, then rescales its log-odds by a logistic
fit over its training rows (Platt scaling). Refitting those on every trial of a long
life costs a pass over the whole training set at every episode.

So a *scheduled* model (one that declares ``scheduled``) fits them, and its learner,
on the first :func:`bins_trials` trials of its training set and counts the rest: a
*counting* one (naive Bayes) into its learner too; logistic regression and the forest
into their rates and priors only, their learner staying the fit's until the set
doubles; the network into its rates and priors, learning the new trials by a warm
start beside a bounded replay (:mod:`llcps.models.neural`). Up to :data:`FULL_FIT_TRIALS` trials that is the whole set, and the
model is exactly the full fit. Past it, the bins are those of the first ``FULL_FIT_TRIALS * 2^k`` trials, the
largest such prefix the set has, so they are fitted again each time the set doubles, and
an episode in between learns its new trials by adding their counts. What a model
predicts is a function of its training set alone, whichever way it was reached: a fit
on the whole set from nothing, or a stored fit brought up to it by counting (the same
sums, added in another order: equal to the last bits of a float); the network's warm
starts are the exception, and depend on how the set grew.
"""

from __future__ import annotations

#: Up to this many trials, a scheduled model fits its bins, calibration and learner on every trial.
FULL_FIT_TRIALS = 4096


def bins_trials(n: int) -> int:
    """How many of a training set's first ``n`` trials fit a scheduled model's bins,
    calibration and learner: all of them up to :data:`FULL_FIT_TRIALS`, else the largest
    ``FULL_FIT_TRIALS * 2^k`` not above ``n``."""
    if n <= FULL_FIT_TRIALS:
        return n
    m = FULL_FIT_TRIALS
    while 2 * m <= n:
        m *= 2
    return m
