"""The paper's own numbers (Gizzi et al., Figure 2 and its caption), for side-by-side comparison.

Figure 2 reports, per world model x measure and scenarios 2 and 3, the percent change
of exploration with model updates against without ("reset"), averaged over four runs,
for 200 and for 4 pretraining points. Everything here is transcribed from the paper;
nothing is computed from our runs.
"""

from __future__ import annotations

from llcps.models.measures import PAPER_MEASURES
from llcps.models.registry import PAPER_MODELS

#: Scenarios the paper's Figure 2 reports (scenario 1 starts from the pretraining set
#: under both conditions, so there it serves as a control: its change should be ~0).
FIGURE2_SCENARIOS: tuple[str, ...] = ("scenario2", "scenario3")
#: How the paper names its two pretraining sizes.
PRETRAIN_NAMES = {200: "Apriori Training", 4: "No Apriori Training"}


def _paper_block(
    pretrain: int, rows: dict[str, tuple[float, float, float, float]]
) -> dict[tuple[str, str, int, str], float]:
    out: dict[tuple[str, str, int, str], float] = {}
    for measure, (nn2, nn3, nb2, nb3) in rows.items():
        out[("nn", measure, pretrain, "scenario2")] = nn2
        out[("nn", measure, pretrain, "scenario3")] = nn3
        out[("nb", measure, pretrain, "scenario2")] = nb2
        out[("nb", measure, pretrain, "scenario3")] = nb3
    return out


#: ``(model, measure, pretrain_size, scenario) -> % change with updates``, transcribed
#: from Figure 2: "Apriori Training" is 200 pretraining points, "No Apriori Training" 4.
#: Columns per measure: NN scenario 2, NN scenario 3, NB scenario 2, NB scenario 3.
PAPER_FIGURE2: dict[tuple[str, str, int, str], float] = {
    **_paper_block(
        200,
        {
            "least-destructive": (182.0, -10.0, 0.0, 18.0),
            "most-positive-changes": (133.0, 0.0, -1.0, -43.0),
            "least-negative-changes": (121.0, 12.0, -21.0, 0.0),
            "most-changes": (-29.0, 550.0, 553.0, -59.0),
        },
    ),
    **_paper_block(
        4,
        {
            "least-destructive": (-40.0, -1.0, 0.0, -60.0),
            "most-positive-changes": (-3.0, -60.0, 0.0, -87.0),
            "least-negative-changes": (-61.0, -43.0, -46.0, 3.0),
            "most-changes": (109.0, 0.0, 640.0, -1.0),
        },
    ),
}
#: The caption's claims: the fraction of model x measure combinations where updating
#: decreased exploration time. Recomputing them from the table gives other numbers
#: (see :func:`~llcps.analysis.figure2.reduction_summary` on :func:`paper_cells`); the report shows both.
PAPER_CAPTION_FRACTION_REDUCED: dict[int, float] = {200: 0.50, 4: 0.81}
#: The paper averaged four runs per cell.
PAPER_RUNS_PER_CELL = 4

assert len(PAPER_FIGURE2) == len(PAPER_MODELS) * len(PAPER_MEASURES) * 2 * len(FIGURE2_SCENARIOS)


def paper_cells() -> list[tuple[str, int, float]]:
    """The paper's Figure-2 cells, as :func:`~llcps.analysis.figure2.reduction_summary` input."""
    return [(model, size, pct) for (model, _measure, size, _scenario), pct in PAPER_FIGURE2.items()]


__all__ = [
    "FIGURE2_SCENARIOS",
    "PAPER_CAPTION_FRACTION_REDUCED",
    "PAPER_FIGURE2",
    "PAPER_RUNS_PER_CELL",
    "PRETRAIN_NAMES",
    "paper_cells",
]
