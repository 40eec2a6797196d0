"""Reading back what the command line prints: its tables row by row, its prose
whatever the line breaks (tests/test_tables.py and the other table tests)."""

from __future__ import annotations

import re

__all__ = ["flat", "unfold", "row"]


def flat(text: str) -> str:
    """Printed text with its line breaks and runs of spaces as one space."""
    return " ".join(text.split())


#: A cell of a printed row: words apart by single spaces, between borders or wider gaps.
_CELL = re.compile(r"[^\s│┃]+(?: [^\s│┃]+)*")


def unfold(text: str) -> str:
    """Printed tables with each folded cell joined back into its row: a line whose
    first cell is empty continues the row above, column by column."""
    rows: list[list[tuple[int, str]]] = []
    for line in text.splitlines():
        cells = [(m.start(), m.group()) for m in _CELL.finditer(line)]
        above = rows[-1] if rows else []
        if cells and len(above) > 1 and cells[0][0] > above[0][0] + len(above[0][1]):
            for start, part in cells:  # into the cell of the column it starts in
                k = max(i for i, (at, _) in enumerate(above) if at <= start or i == 0)
                above[k] = (above[k][0], above[k][1] + part)
        else:
            rows.append(cells)
    return "\n".join("  ".join(cell for _, cell in cells) for cells in rows)


def row(text: str, *cells: str) -> str:
    """The row of a printed table (:func:`unfold`) that shows ``cells`` in this order,
    each whole, one after the other (empty cells between them allowed); fails
    showing the text when there is none."""
    pattern = re.compile("(?:^|  )" + "  ".join(map(re.escape, cells)) + "(?=  |$)")
    found = next((line for line in unfold(text).splitlines() if pattern.search(line)), None)
    assert found is not None, f"no row {cells} in:\n{text}"
    return found
