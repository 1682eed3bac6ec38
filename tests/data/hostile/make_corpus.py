"""Write the hand-edited logs of the hostile corpus from the complete logs beside them (tests/data/hostile/README.md).

    python tests/data/hostile/make_corpus.py

Each ``resume/<procedure>/complete.csv`` is a small log written by ``tactile measure <procedure> --simulate``
(the commands are in README.md); every edit below is what a user does to a log by hand or with a
spreadsheet, written as ``resume/<procedure>/<edit>.csv``.  Rerunning the script rewrites the same files.
"""

from pathlib import Path

HERE = Path(__file__).resolve().parent
KEY_REWRITES = {
    "frequency_hz": lambda text: f"{float(text):.12e}",
    "drive_voltage_v": lambda text: f"{float(text):.3f}",
    "sweep": lambda text: f"{int(text)}.0",
    "decay_time_s": lambda text: f"{float(text):.10e}",
    "x_mm": lambda text: "-0" if float(text) == 0 else f"{float(text):g}",
    "y_mm": lambda text: f"{float(text):g}",
    "hold_time_s": lambda text: f"{float(text):.3f}",
}
"""A spreadsheet's rewriting of the key columns: the same values, other digits (5 -> 5.000, -43.0000 -> -43, 0 -> -0)."""
PLAN_KEYS = {"resonance": "plan_coarse_points", "campaign": "plan_center_frequency", "voltage-sweep": "plan_frequency",
             "ringdown": "plan_frequency", "scan": "plan_frequency", "hold": "plan_target_velocity"}
"""The plan metadata item each procedure's ``plan_edited.csv`` spoils."""
FOREIGN_COLUMNS = {"hold": "hold_time_s"}
"""The key column ``foreign_row.csv`` moves by 0.5 (the frequency, except in a hold, where it is measured)."""


def split(text: str) -> tuple[list, list, list]:
    """(metadata lines, header fields, data rows as field lists) of a complete log."""
    lines = text.splitlines()
    header = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    return lines[:header], lines[header].split(","), [line.split(",") for line in lines[header + 1:]]


def join(meta: list, header: list, rows: list, end: str = "\n") -> str:
    return "\n".join(meta + [",".join(header)] + [",".join(row) for row in rows]) + end


def edits(procedure: str, text: str) -> dict:
    """Edited copies of a complete log: name -> text."""
    meta, header, rows = split(text)
    column = {name: i for i, name in enumerate(header)}
    reformatted = [[KEY_REWRITES[name](cell) if name in KEY_REWRITES else cell for name, cell in zip(header, row)]
                   for row in rows]
    first = [row for row in rows if row[column["sweep"]] == rows[0][column["sweep"]]]
    foreign, moved = [list(row) for row in rows], column[FOREIGN_COLUMNS.get(procedure, "frequency_hz")]
    foreign[1][moved] = str(float(rows[1][moved]) + 0.5)
    cut = [list(row) for row in rows]
    cut[2] = cut[2][:2]
    not_integer, unplanned = [list(row) for row in rows], [list(row) for row in rows]
    not_integer[3][column["sweep"]] = "x"
    unplanned[3][column["sweep"]] = "7"
    key = PLAN_KEYS[procedure]
    spoiled = [f"# {key}: abc" if line.startswith(f"# {key}:") else line for line in meta]
    last = ",".join(rows[-1])
    files = {
        "complete": text,
        "duplicate_row": join(meta, header, rows[:2] + rows[1:]),
        "pasted_block": join(meta, header, rows + first),
        "reformatted_last_missing": join(meta, header, reformatted[:-1]),
        "truncated_middle": join(meta, header, cut),
        "truncated_last": join(meta, header, rows[:-1]) + last[: len(last) // 2],
        "no_final_newline": join(meta, header, rows, end=""),
        "foreign_row": join(meta, header, foreign),
        "plan_edited": join(spoiled, header, rows),
        "sweep_not_integer": join(meta, header, not_integer),
        "sweep_unplanned": join(meta, header, unplanned),
        "crlf": join(meta, header, rows).replace("\n", "\r\n"),
    }
    if procedure == "ringdown":
        files["burst_cut_short"] = join(meta, header, rows[:-4])
    return files


def main() -> None:
    for folder in sorted((HERE / "resume").iterdir()):
        for name, text in edits(folder.name, (folder / "complete.csv").read_text(encoding="utf-8")).items():
            (folder / f"{name}.csv").write_bytes(text.encode())


if __name__ == "__main__":
    main()
