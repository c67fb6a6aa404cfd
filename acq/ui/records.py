"""A table that turns into one record per block where no layout of its columns fits the terminal.

Below the width of a :class:`~acq.ui.display.FittedTable`'s narrowest layout, rich squeezes its columns until numbers
and names fold inside themselves ("1001." over "0", "robo" over "join"); :class:`RecordTable` then prints each row as
its first cell on a line of its own and ``header: value`` lines under it (every column, in its widest form: each
line has the terminal's whole width), so a phone-sized terminal or a narrow pane still reads every value whole.
"""

from __future__ import annotations

from rich.cells import cell_len
from rich.console import Group, RenderableType
from rich.padding import Padding
from rich.text import Text

from acq.ui.display import Column, FittedTable


class RecordTable(FittedTable):
    """A :class:`FittedTable` that, where no layout fits, shows its rows as blocks of ``header: value`` lines."""

    def fitted(self, width: int) -> RenderableType:
        """The table of the widest layout that fits ``width`` columns, else :meth:`records`."""
        columns = self.fitting_layout(width)
        return self.build(columns) if columns is not None else self.records(width)

    def records(self, width: int) -> Group:
        """The title, one block per row (its first cell, then ``header: value`` lines indented, in the row's style),
        a blank line between blocks, then the caption. A column's lines are in its widest form where they fit
        ``width`` (the date and time whole), else in its narrow form (e.g. 11-30 19:53)."""
        first = self.columns[0]
        rest = [c if c.narrow is None or max(map(cell_len, _lines(c))) <= width else c.narrow for c in self.columns[1:]]
        parts: list[RenderableType] = [Text.from_markup(self.title, style="bold")]
        for i in range(len(first.cells)):
            style = self.row_styles[i] if self.row_styles else ""
            parts += [Text(""), Text(_one_line(first.cells[i]), style=f"bold {style}".strip())]
            parts += [Padding(Text(line[INDENT:], style=style), (0, 0, 0, INDENT), expand=False)
                      for line in (lines[i] for lines in map(_lines, rest))]
        if self.caption:
            parts += [Text(""), Text("\n".join(self.caption))]
        return Group(*parts)


#: Indent of a block's ``header: value`` lines under its first cell, characters.
INDENT = 2


def _lines(column: Column) -> list[str]:
    """The column's ``header: value`` line of each row, indented."""
    return [f"{' ' * INDENT}{_one_line(column.header)}: {_one_line(cell)}" for cell in column.cells]


def _one_line(text: str) -> str:
    """A header or cell on one line: its lines joined by a space ("K\nN·m/rad" → "K N·m/rad")."""
    return " ".join(text.split("\n"))
