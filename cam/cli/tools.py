"""``cam tools``: the machine's tool table (issue #47 point 4), a thin adapter over :mod:`cam.tool_table`."""
from __future__ import annotations

import argparse
import json

from ..tool_table import TableTool, read_tool_table, tool_table_path, write_tool_table

__all__ = ["cmd_tools"]


def cmd_tools(args: argparse.Namespace) -> int:
    """List the table (the default), ``set N --shape ... --diameter ...`` or ``remove N``; prints what it did."""
    path = tool_table_path(args.machine)
    table = read_tool_table(path)
    action = args.tools_action or "list"
    if action == "set":
        tool = TableTool(args.number, args.shape, args.diameter, args.angle, args.length)
        write_tool_table(path, table.with_tool(tool), args.machine or "")
        print(f"set {tool.describe()} in {path}")
        return 0
    if action == "remove":
        write_tool_table(path, table.without(args.number), args.machine or "")
        print(f"removed T{args.number} from {path}")
        return 0
    if args.json:
        print(json.dumps({"file": str(path), "tools": [t.to_json() for t in table.sorted()]}, indent=1))
        return 0
    print(f"tool table {path}: {len(table)} tool{'s' if len(table) != 1 else ''}")
    for tool in table.sorted():
        print(f"  {tool.describe()}")
    return 0
