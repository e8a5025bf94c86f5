"""A part of :class:`~cam.drive.session.MachineSession`: the machine's tool table at the tool-change prompt
(issue #47 point 4).

The session keeps the path of the machine's tool table (:attr:`SessionTools.tool_table_path`, set by the front
end: :func:`cam.tool_table.tool_table_path` of its machine file) and reads it at every tool change, so a tool set
on the page or with ``cam tools`` while a job waits is the one named.  Each prompt's note gets the table's tool
(:func:`cam.tool_table.annotate_tool_change`); a table that cannot be read is logged and the note kept as it is.
"""
from __future__ import annotations

from typing import Any, Optional

from ..errors import CamError
from ..tool_table import annotate_tool_change, read_tool_table

__all__ = ["SessionTools"]


class SessionTools:
    """The tool-change prompt naming the table's tool (a mixin before the session's prompt; see the module)."""

    tool_table_path: Optional[str] = None
    """The machine's tool table (None: none; a missing file is an empty table)."""

    def tool_change_note(self, note: str) -> str:
        """``note`` with the table's tool named (unchanged without a table, or for a pause that is no tool change
        of a drill file or a G-code program)."""
        if not self.tool_table_path:
            return note
        try:
            return annotate_tool_change(note, read_tool_table(self.tool_table_path))
        except CamError as exc:
            self.log(f"the tool table was not read: {exc}", "warning")  # type: ignore[attr-defined]
            return note

    def prompt(self, position_steps: Any, note: str) -> None:
        """The session's prompt (:meth:`~cam.drive._session_parts.SessionControls.prompt`) with the table's tool
        named in ``note``."""
        super().prompt(position_steps, self.tool_change_note(note))  # type: ignore[misc]
