"""Every value of the machine file, listed and edited (issue #47 point 5).

:func:`list_settings` gives each key of the machine file (:mod:`cam.settings`) with its value, unit, range and
help (the help is the settings' own attribute docstrings, else the comment of the module's example file), so a
front end shows them without knowing any; :func:`save_settings` changes some of them in the file:

* each value is checked first against its key's range (:func:`check_setting`): one line naming the key, the
  unit and the range; then the whole file as :func:`cam.settings.load_settings` reads it (the rules between
  keys: a start speed at most the top speed, pins used once ...), again one line naming the key;
* the old file is copied to ``NAME.toml.bak`` (atomically, replacing the previous backup), then the new text is
  written atomically (:func:`cam.fileio.atomic_write_text`): a failed write leaves the old file as it was;
* only the lines of the keys changed are rewritten (a value in place, its comment kept; a key not in the file is
  added to its table); a file this cannot edit line by line (an inline table, a dotted key) is written anew.

Units come from the keys' suffixes (``_mm``, ``_mm_s``, ``_steps``, ``_ms``, ...) and a few names; ranges are
those :mod:`cam.settings` checks (a range that depends on another key says so in ``range``).
"""
from __future__ import annotations

import ast
import dataclasses
import inspect
import math
import os
import re
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Mapping, Optional

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from . import settings as _settings
from .errors import SettingsError
from .fileio import atomic_write_bytes, atomic_write_text, state_dir
from .settings import (COMMAND_KEYS, MAX_TRAVEL_STEPS, MIN_MM_PER_STEP, MIN_SPEED_MM_S, RAMP_MODES, MachineSettings,
                       settings_from_mapping)
from .tool import TOOL_SHAPES

__all__ = ["SettingInfo", "list_settings", "check_setting", "save_settings", "backup_path", "setting_keys",
           "machine_file_of", "DEFAULT_MACHINE_NAME"]


@dataclass(frozen=True)
class SettingInfo:
    """One key of the machine file.

    Attributes:
        key: its name, ``table.key`` inside a table (``"maximus.delay_x"``).
        value: its value now (None: an optional key not given).
        kind: ``"int"``, ``"float"``, ``"bool"`` or ``"str"``.
        unit: its unit (``"mm/s"``, ``"steps"``; ``""`` none).
        lo, hi: its range (None: no bound on that side, or not a number).
        choices: the values it may take (``()``: any of its kind).
        range: the range in words (``"0.01..10000 mm/s, at most max_speed_x_mm_s"``).
        help: what it is, one paragraph.
        optional: it may be left out (``""`` / None clears it).
    """

    key: str
    value: Any
    kind: str
    unit: str = ""
    lo: Optional[float] = None
    hi: Optional[float] = None
    choices: tuple[str, ...] = ()
    range: str = ""
    help: str = ""
    optional: bool = False

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self) | {"choices": list(self.choices)}


_SECTIONS = {"travel": _settings.Travel, "pins": _settings.Pins, "maximus": _settings.Maximus,
             "commands": _settings.Commands, "tool": _settings.ToolShape, "inputs": _settings.Inputs,
             "homing": _settings.Homing, "mock": _settings.MockSwitches}
_DERIVED = {"mm_per_step_y"}  # not a machine-file key (settings._DERIVED)

_UNITS_BY_SUFFIX = (("_mm_s2", "mm/s^2"), ("_mm_s", "mm/s"), ("_mm", "mm"), ("_ms", "ms"), ("_us", "us"),
                    ("_steps", "steps"), ("_after_s", "s"), ("_s", "s"), ("_deg", "degrees"))
_UNITS_BY_NAME = {"steps_per_px_xy": "steps/pixel", "steps_per_px_z": "steps/pixel",
                  "mm_per_step_xy": "mm/step", "mm_per_step_z": "mm/step", "maximus.baud": "baud"}


def _unit(key: str) -> str:
    if key in _UNITS_BY_NAME:
        return _UNITS_BY_NAME[key]
    name = key.split(".")[-1]
    if key.startswith("maximus.mm_per_full_step"):
        return "mm/full step"
    if key.startswith("maximus.delay_"):
        return "Delay byte"
    if key.startswith("pins."):
        return "pin"
    if key.startswith("commands.") and name in COMMAND_KEYS:
        return "byte"
    for suffix, unit in _UNITS_BY_SUFFIX:
        if name.endswith(suffix):
            return unit
    return ""


def _range(key: str) -> tuple[Optional[float], Optional[float], tuple[str, ...], str]:
    """(lo, hi, choices, note) of ``key``: the bounds :mod:`cam.settings` checks, and what depends on other keys."""
    name = key.split(".")[-1]
    axis = next((a for a in "xyz" if f"_{a}_" in f"_{name}_"), "")
    if key in ("steps_per_px_xy", "steps_per_px_z"):
        return 1, 10000, (), ""
    if key in ("delay_xy_ms", "delay_z_ms"):
        return 0.001, 10000, (), ""
    if key in ("mm_per_step_xy", "mm_per_step_z") or key.startswith("maximus.mm_per_full_step_"):
        return MIN_MM_PER_STEP, 100, (), ""
    if key == "ramp":
        return None, None, RAMP_MODES, ""
    if key.startswith("max_speed_"):
        return MIN_SPEED_MM_S, 10000, (), ""
    if key.startswith("start_speed_"):
        return MIN_SPEED_MM_S, 10000, (), f"at most max_speed_{axis}_mm_s"
    if key.startswith("accel_"):
        return MIN_SPEED_MM_S, 1e6, (), ""
    if key.startswith(("g28_", "g30_")):
        return -1e6, 1e6, (), ""
    if key.startswith("travel."):
        return (-MAX_TRAVEL_STEPS, 0, (), "") if "_min_" in key else (0, MAX_TRAVEL_STEPS, (), "")
    if key.startswith("pins."):
        return 2, 9, (), "each pin used once"
    if key.startswith("maximus."):
        if name.startswith("delay_"):
            return 1, 255, (), ""
        if name in ("drill_z_up_steps", "drill_z_down_steps"):
            return 0, 65535, (), "down 0 (from the job) or deeper than up"
        if name == "baud":
            return 1, 4_000_000, (), ""
        if name == "reply_margin_s":
            return 0.05, 60, (), ""
        return None, None, (), ""
    if key.startswith("commands."):
        if name in COMMAND_KEYS:
            return -1, 255, (), "-1: not declared; each byte used once"
        if name == "strobe_us":
            return 0.1, 10000, (), ""
        return 0.1, 100000, (), "at least commands.strobe_us"
    if key == "tool.shape":
        return None, None, TOOL_SHAPES, ""
    if key.startswith("tool."):
        return (0, 179, (), "a V bit 1..179") if name == "angle_deg" else (0, 100, (), "")
    if key.startswith("inputs."):
        return None, None, (), 'a pin 10, 11, 12, 13 or 15, "!" before it for active low; "" not wired'
    if key.startswith("homing."):
        if name == "order":
            return None, None, (), 'the axes, each once (e.g. "zxy")'
        if name.startswith("direction_"):
            return None, None, ("-", "+"), ""
        if name.startswith(("search_speed_", "latch_speed_")):
            return 0, 10000, (), (f"0 or at most start_speed_{axis}_mm_s" if name.startswith("search")
                                  else "0 or at most the search speed")
        if name.startswith("backoff_"):
            return 0, 1000, (), ""
        return -1e6, 1e6, (), f"within the {axis.upper()} travel"
    if key.startswith("mock."):
        if name == "estop_after_s":
            return 0, 1e6, (), ""
        if name == "probe_surface":
            return None, None, (), "z0,ax,ay,b,cx,cy"
        return -MAX_TRAVEL_STEPS, MAX_TRAVEL_STEPS, (), ""
    return None, None, (), ""


@lru_cache(maxsize=1)
def _docstrings() -> dict[str, str]:
    """key -> help: the attribute docstrings of :mod:`cam.settings`' classes (a docstring after several fields
    is theirs all), else the comment of the key in the module docstring's example file."""
    out: dict[str, str] = {}
    example = _settings.__doc__ or ""
    table = ""
    for line in example.splitlines():
        s = line.strip()
        m = re.match(r"^\[(\w+)\]", s)
        if m:
            table = m.group(1)
            continue
        m = re.match(r"^(\w+)\s*=\s*[^#]*#\s*(.+)$", s)
        if m:
            out[f"{table}.{m.group(1)}" if table else m.group(1)] = m.group(2).strip()
    tree = ast.parse(inspect.getsource(_settings))
    prefixes = {cls.__name__: f"{name}." for name, cls in _SECTIONS.items()} | {"MachineSettings": ""}
    for node in tree.body:
        if not isinstance(node, ast.ClassDef) or node.name not in prefixes:
            continue
        pending: list[str] = []
        for item in node.body:
            if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
                pending.append(item.target.id)
            elif isinstance(item, ast.Expr) and isinstance(item.value, ast.Constant) and \
                    isinstance(item.value.value, str) and pending:
                text = " ".join(item.value.value.split())
                for name in pending:
                    out[prefixes[node.name] + name] = text
                pending = []
            else:
                pending = []
    return out


def _fields(cls: type, prefix: str) -> list[tuple[str, str, bool]]:
    """(key, kind, optional) of each field of ``cls``."""
    out = []
    for f in dataclasses.fields(cls):
        if prefix == "" and (f.name in _SECTIONS or f.name in _DERIVED):
            continue
        kind = f.type if isinstance(f.type, str) else f.type.__name__
        out.append((prefix + f.name, kind.replace(" | None", ""), "None" in kind))
    return out


@lru_cache(maxsize=1)
def setting_keys() -> dict[str, tuple[str, bool]]:
    """Every key of the machine file, in the file's order: ``key -> (kind, optional)``."""
    keys = _fields(MachineSettings, "")
    for name, cls in _SECTIONS.items():
        keys += _fields(cls, f"{name}.")
    return {k: (kind, opt) for k, kind, opt in keys}


def _value_of(settings: MachineSettings, key: str) -> Any:
    obj: Any = settings
    for part in key.split("."):
        obj = getattr(obj, part)
    return obj


def list_settings(settings: MachineSettings) -> list[SettingInfo]:
    """Every key of the machine file with its value in ``settings``, its unit, range and help."""
    docs = _docstrings()
    out = []
    for key, (kind, optional) in setting_keys().items():
        lo, hi, choices, note = _range(key)
        unit = _unit(key)
        if choices:
            words = " | ".join(choices)
        elif lo is not None:
            words = f"{lo:g}..{hi:g}{' ' + unit if unit else ''}"
        else:
            words = ""
        words = "; ".join(w for w in (words, note) if w)
        out.append(SettingInfo(key, _value_of(settings, key), kind, unit, lo, hi, choices, words,
                               docs.get(key, ""), optional))
    return out


def check_setting(key: Any, value: Any) -> Any:
    """``value`` for ``key``, of its kind and in its range (an int given as a float with no fraction is an int;
    ``""`` or None for an optional key: None).

    Raises:
        SettingsError: an unknown key, a value of another kind or out of its range: one line naming the key, the
            unit and the range.
    """
    keys = setting_keys()
    if not isinstance(key, str) or key not in keys:
        raise SettingsError(f"unknown machine setting {str(key)[:60]!r} (see cam settings, or the page's Settings)")
    kind, optional = keys[key]
    lo, hi, choices, _ = _range(key)
    unit = _unit(key)
    if optional and value in (None, ""):
        return None
    if isinstance(value, str) and kind != "str":  # a form's text: a number, true or false
        value = _from_text(key, kind, value)
    if kind == "bool":
        if not isinstance(value, bool):
            raise SettingsError(f"'{key}' must be true or false, got {str(value)[:40]!r}")
        return value
    if kind == "str":
        if not isinstance(value, str):
            raise SettingsError(f"'{key}' must be text, got {str(value)[:40]!r}")
        if choices and value not in choices:
            raise SettingsError(f"'{key}' must be one of {', '.join(choices)}, got {value[:40]!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            (isinstance(value, float) and not math.isfinite(value)):
        raise SettingsError(f"'{key}' must be a number of {unit or kind}, got {str(value)[:40]!r}")
    if kind == "int":
        if isinstance(value, float) and not value.is_integer():
            raise SettingsError(f"'{key}' must be a whole number of {unit or 'units'}, got {value!r}")
        value = int(value)
    else:
        value = float(value)
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise SettingsError(f"'{key}' must be {lo:g}..{hi:g}{' ' + unit if unit else ''}, got {_shown(value)}")
    return value


def _from_text(key: str, kind: str, text: str) -> Any:
    """A form field's ``text`` as the value of a ``kind`` key (SettingsError, one line, when it is none)."""
    t = text.strip().lower()
    if kind == "bool":
        if t in ("true", "false"):
            return t == "true"
        raise SettingsError(f"'{key}' must be true or false, got {text[:40]!r}")
    try:
        return int(t, 0) if kind == "int" and re.fullmatch(r"[+-]?(0x[0-9a-f]+|\d+)", t) else float(t)
    except ValueError:
        raise SettingsError(f"'{key}' must be a number of {_unit(key) or kind}, got {text[:40]!r}") from None


def _shown(value: Any) -> str:
    """A number as an error message shows it: short (a whole number of thousands of digits cut)."""
    text = f"{value:g}" if isinstance(value, float) else str(value)
    return text if len(text) <= 24 else text[:20] + "..."


def backup_path(path: str | os.PathLike) -> Path:
    """Where :func:`save_settings` keeps the file as it was before: ``NAME.toml.bak``."""
    p = Path(path)
    return p.with_name(p.name + ".bak")


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    return '"' + str(value).replace("\\", "\\\\").replace('"', '\\"') + '"'


def _edit_lines(text: str, changes: Mapping[str, Any]) -> str:
    """``text`` with each changed key's line rewritten in place (its comment kept) or added to its table (a
    removed optional key: its line dropped)."""
    lines = text.splitlines()
    section = ""
    where: dict[str, int] = {}
    insert_at: dict[str, int] = {}  # table -> the line index new keys of it go before
    first_table = len(lines)
    for i, line in enumerate(lines):
        s = line.strip()
        m = re.match(r"^\[\s*([A-Za-z0-9_]+)\s*\]", s)
        if m:
            section = m.group(1)
            first_table = min(first_table, i)
            insert_at[section] = i + 1
            continue
        m = re.match(r"^([A-Za-z0-9_]+)\s*=", s)
        if m:
            where[f"{section}.{m.group(1)}" if section else m.group(1)] = i
            if section:
                insert_at[section] = i + 1
    insert_at[""] = first_table
    drop: set[int] = set()
    added: dict[int, list[str]] = {}
    new_tables: dict[str, list[str]] = {}
    for key, value in changes.items():
        table, _, name = key.rpartition(".")
        if key in where:
            i = where[key]
            if value is None:
                drop.add(i)
                continue
            m = re.match(r"^(\s*[A-Za-z0-9_]+\s*=\s*)(.*)$", lines[i])
            old = m.group(2)
            cm = re.search(r"\s+#[^\"']*$", old)
            lines[i] = m.group(1) + _toml_value(value) + (cm.group(0) if cm else "")
        elif value is not None:
            entry = f"{name} = {_toml_value(value)}"
            if table in insert_at:
                added.setdefault(insert_at[table], []).append(entry)
            else:
                new_tables.setdefault(table, []).append(entry)
    out: list[str] = []
    for i in range(len(lines) + 1):
        out += added.get(i, [])
        if i < len(lines) and i not in drop:
            out.append(lines[i])
    for table, entries in new_tables.items():
        out += ["", f"[{table}]"] + entries
    return "\n".join(out) + "\n"


def _nested(flat: Mapping[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in flat.items():
        table, _, name = key.rpartition(".")
        (out.setdefault(table, {}) if table else out)[name] = value
    return out


def _flat(table: Mapping[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in table.items():
        if isinstance(value, dict):
            out.update({f"{key}.{k}": v for k, v in value.items()})
        else:
            out[key] = value
    return out


def _full_text(flat: Mapping[str, Any]) -> str:
    lines = ["# cam machine file (written by cam: the page's Settings or save_settings)"]
    nested = _nested(flat)
    lines += [f"{k} = {_toml_value(v)}" for k, v in nested.items() if not isinstance(v, dict)]
    for table, values in nested.items():
        if isinstance(values, dict):
            lines += ["", f"[{table}]"] + [f"{k} = {_toml_value(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"


def save_settings(path: str | os.PathLike, changes: Mapping[str, Any], *, base: Optional[MachineSettings] = None,
                  adapt: Optional[Callable[[MachineSettings], MachineSettings]] = None) -> MachineSettings:
    """Change the keys ``changes`` (``key -> value``, keys as :func:`list_settings` names them; None or ``""``
    clears an optional key) in the machine file ``path`` (a missing file is made), keeping the old file as
    :func:`backup_path`.  Returns the settings the new file gives on ``base`` (as
    :func:`cam.settings.load_settings` reads it), through ``adapt`` when given (a machine's own rules, e.g. the
    MAXIMUS board's :meth:`~cam.drive.machines.Backend.adapt_settings`: checked before anything is written).

    Nothing is written unless every value is in range and the whole file is valid.

    Raises:
        SettingsError: a bad key or value (:func:`check_setting`), a file that is not valid TOML, or settings the
            new file would make invalid (one line naming the key); CamError: the file cannot be written (the old
            one is then as it was).
    """
    if not isinstance(changes, Mapping) or not changes:
        raise SettingsError("no settings to change: give key = value pairs")
    checked = {key: check_setting(key, value) for key, value in changes.items()}
    p = Path(path)
    try:
        old_bytes: Optional[bytes] = p.read_bytes()
    except FileNotFoundError:
        old_bytes = None
    except OSError as exc:
        raise SettingsError(f"{p}: cannot read the machine file ({exc.strerror or exc})") from None
    old_text = "" if old_bytes is None else old_bytes.decode("utf-8", errors="replace")
    try:
        old_flat = _flat(tomllib.loads(old_text))
    except (tomllib.TOMLDecodeError, ValueError) as exc:
        raise SettingsError(f"{p}: not valid TOML ({exc}): fix it by hand first") from None
    new_flat = {k: v for k, v in {**old_flat, **checked}.items() if v is not None}
    new_settings = settings_from_mapping(_nested(new_flat), source=str(p), base=base)
    if adapt is not None:
        new_settings = adapt(new_settings)
    text = _edit_lines(old_text, checked)
    try:
        edited_ok = _flat(tomllib.loads(text)) == new_flat
    except (tomllib.TOMLDecodeError, ValueError):
        edited_ok = False
    if not edited_ok:  # a file the lines cannot say (an inline table, a dotted key): written anew
        text = _full_text(new_flat)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SettingsError(f"{p}: cannot make its folder ({exc.strerror or exc})") from None
    if old_bytes is not None:
        atomic_write_bytes(backup_path(p), old_bytes)
    atomic_write_text(p, text)
    return new_settings


DEFAULT_MACHINE_NAME = "default.toml"
"""The machine file the built-in settings are saved to when none was given (in the state folder)."""


def machine_file_of(machine_file: Optional[str | os.PathLike], environ: Optional[Mapping[str, str]] = None) -> Path:
    """The machine file settings are saved to: ``machine_file``, or with none (None, ``""``: the built-in
    settings) ``{state folder}/default.toml``, which a machine's state file then records, so the next command on
    that machine without ``--machine`` runs with it (:func:`cam.cli.common.use_recorded_machine`; on the mock its
    default state file keeps its name, ``default-mock.json``).  Its tool table is then
    ``{state folder}/default.tools.toml``, the built-in settings' (:func:`cam.tool_table.tool_table_path`).

    >>> machine_file_of(None, {"XDG_STATE_HOME": "/s"}).as_posix()
    '/s/cam/default.toml'
    """
    if machine_file:
        return Path(machine_file)
    return state_dir(environ) / DEFAULT_MACHINE_NAME
