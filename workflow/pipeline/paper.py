"""Figures quoted from the source paper (:data:`CITATION`): validation targets.

They are used by tests and shown beside our results in the report's reproduction table;
no computation returns them.
"""

from dataclasses import dataclass

CITATION = (
    "P. Sergeant, F. Giraud, B. Lemaire-Semail, \"Geometrical optimization of an ultrasonic tactile plate "
    "for surface texture rendering\", *Sensors and Actuators A: Physical* (2010)"
)
"""The source paper, as the report cites it (markdown)."""


@dataclass(frozen=True)
class PaperFigure:
    """One quoted figure.

    Attributes
    ----------
    key : str
        Identifier used by the report and the tests.
    description : str
        What the paper reports.
    value : float
        The value, in ``unit``.
    unit : str
        Display unit.
    """

    key: str
    description: str
    value: float
    unit: str


FIGURES = {
    figure.key: figure
    for figure in (
        PaperFigure("analytical_w", "original plate, beam model, Q = 54, 15 V: deflection", 1.070, "µm"),
        PaperFigure("analytical_f", "original plate, beam model: resonance", 32.13, "kHz"),
        PaperFigure(
            "literal_w",
            "original plate, the paper's beam formula taken literally with Q = 54 "
            "(an independent hand evaluation, not a figure printed in the paper)",
            2.89,
            "µm",
        ),
        PaperFigure("fem_f", "original plate, FEM, Q = 54, 15 V: resonance", 31.17, "kHz"),
        PaperFigure("fem_w", "original plate, FEM, Q = 54, 15 V: deflection", 1.151, "µm"),
        PaperFigure("fem_nlopt_evaluations", "direct FEM optimisation (gradient method): FEM evaluations", 48, ""),
        PaperFigure("space_mapping_evaluations", "space mapping: FEM evaluations", 4, ""),
        PaperFigure("space_mapping_distance", "space-mapping optimum from the direct one: at most", 0.1, "mm"),
        PaperFigure("working_q", "plate Q at the original working point", 54, ""),
        PaperFigure("working_v", "surface velocity at the original working point (15 V)", 0.23, "m/s"),
    )
}
"""The paper's figures by key."""
