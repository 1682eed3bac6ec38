"""Markdown pieces of the design note: tables, figure links and link targets relative to the report."""

from pathlib import Path

from workflow.pipeline.runner import RunContext


def table(header, rows) -> str:
    """A markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines)


def figure(context: RunContext, name: str, caption: str) -> str:
    """A markdown image link to a figure written by a step."""
    return f"![{caption}]({context.figures[name]})\n\n*{caption}*"


def relative_link(context: RunContext, path) -> str:
    """A link target relative to the report (absolute when outside the output folder)."""
    path = Path(path).resolve()
    try:
        return path.relative_to(context.out.resolve()).as_posix()
    except ValueError:
        return path.as_uri()
