"""Markdown pieces of the design note: tables, figure links and link targets relative to the report."""

from pathlib import Path

from workflow.pipeline.runner import RunContext


def table(header, rows) -> str:
    """A markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines)


def figure(context: RunContext, name: str) -> str:
    """A markdown image link to the figure ``name`` a step wrote, under the caption the step gave it."""
    written = context.figures[name]
    return f"![{written.caption}]({written.name})\n\n*{written.caption}*"


def step_figures(context: RunContext, step: str) -> str:
    """Markdown image links to every figure the step ``step`` (its key) wrote, in order (empty if none)."""
    return "\n\n".join(figure(context, written.name) for written in context.figures_of(step))


def relative_link(context: RunContext, path) -> str:
    """A link target relative to the report (absolute when outside the output folder)."""
    path = Path(path).resolve()
    try:
        return path.relative_to(context.out.resolve()).as_posix()
    except ValueError:
        return path.as_uri()


def median_band(values, unit: float = 1.0, digits: int = 3) -> str:
    """'median (p05 to p95)' of (p05, p50, p95) in ``unit`` (the calibrated predictions' notation)."""
    low, median, high = (float(v) / unit for v in values)
    return f"{median:.{digits}f} ({low:.{digits}f} to {high:.{digits}f})"


def median_interval(values, unit: float = 1.0, digits: int = 3) -> str:
    """'median [p05, p95]' of (p05, p50, p95) in ``unit`` (the designs' and the fit's notation)."""
    low, median, high = (float(v) / unit for v in values)
    return f"{median:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"
