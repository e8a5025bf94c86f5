"""Small units everywhere (issue #28 point 9): no function or method in ``cam/`` over 80 lines and no class over
300, so each can be read, tested and reviewed as one piece.

A unit's lines are the non-blank source lines from its ``def`` / ``class`` line to its last line, comments
included, its own docstring's lines not counted (a nested function's or method's docstring counts towards the
unit around it: it is part of that unit's text)."""
import ast
from pathlib import Path

from conftest import parsed_source

MAX_FUNCTION_LINES = 80
MAX_CLASS_LINES = 300

CAM = Path(__file__).resolve().parent.parent / "cam"


def _docstring_lines(node: ast.AST) -> set[int]:
    """The line numbers of ``node``'s own docstring (empty if it has none)."""
    body = getattr(node, "body", [])
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
            and isinstance(body[0].value.value, str):
        return set(range(body[0].lineno, body[0].end_lineno + 1))
    return set()


def unit_sizes(path: Path) -> list[tuple[int, str, str, int]]:
    """Every function, method and class of one file: ``(line, kind, qualified name, lines)``."""
    text = path.read_text(encoding="utf-8")
    source = text.splitlines()
    out = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                doc = _docstring_lines(child)
                count = sum(1 for no in range(child.lineno, child.end_lineno + 1)
                            if source[no - 1].strip() and no not in doc)
                kind = "class" if isinstance(child, ast.ClassDef) else "def"
                name = prefix + child.name
                out.append((child.lineno, kind, name, count))
                visit(child, name + ".")
            else:
                visit(child, prefix)

    visit(parsed_source(path), "")
    return out


def offenders(root: Path = CAM) -> list[str]:
    """``file:line kind name count`` of every unit over its limit under ``root``."""
    found = []
    for path in sorted(root.rglob("*.py")):
        for line, kind, name, count in unit_sizes(path):
            limit = MAX_CLASS_LINES if kind == "class" else MAX_FUNCTION_LINES
            if count > limit:
                found.append(f"{path.relative_to(root.parent)}:{line} {kind} {name} {count} lines (limit {limit})")
    return found


def test_counting_rule(tmp_path):
    """Blank lines and the unit's own docstring do not count; comments and nested docstrings do."""
    f = tmp_path / "m.py"
    f.write_text('class C:\n    """Doc\n    string."""\n\n    # a comment\n    def f(self):\n'
                 '        """One line."""\n        return 1\n')
    sizes = {name: count for _, _, name, count in unit_sizes(f)}
    assert sizes == {"C": 5, "C.f": 2}


def test_no_unit_over_its_limit():
    found = offenders()
    assert not found, (f"functions over {MAX_FUNCTION_LINES} lines or classes over {MAX_CLASS_LINES} lines "
                       "(non-blank, docstring not counted); split them:\n" + "\n".join(found))
