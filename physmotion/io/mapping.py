"""A user's rig described in a JSON file: which of the file's joints is each of our 22 joints.

Schema (``physmotion import FILE --mapping map.json``; ``docs/examples/mapping_bandai.json``)::

    {
      "joints": {"pelvis": "Hips", "left_hip": "UpperLeg_L", ...,
                 "spine2": [["Spine", 0.5], ["Chest", 0.5]]},
      "units": "cm",
      "up_axis": "Y",
      "fps": 30
    }

``joints`` is required and names all 22 joints of :data:`physmotion.skeleton.JOINT_NAMES`; a value is
one of the file's joint names (a BVH ``End Site`` is ``<parent>_end``, an ASF bone's end ``<bone>_end``:
``docs/examples/mapping_mixamo_no_toes.json`` maps the toes of a rig without toe bones so), or a blend: a list of ``[joint name, weight]`` pairs, weights >= 0
summing to 1 (see :data:`~physmotion.io.rigs.JointSource`). ``units`` (a name as
:func:`~physmotion.io.rigs.parse_units` reads it, or metres per file unit), ``up_axis`` (X, Y or Z)
and ``fps`` (the file's true rate) are optional; a value given on the command line wins. Keys
starting with ``_`` are comments and ignored.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from physmotion.errors import PhysmotionError
from physmotion.io.rigs import UP_AXES, JointSource, parse_units
from physmotion.skeleton import JOINT_NAMES

_KEYS = ("joints", "units", "up_axis", "fps")
_MAX_BYTES = 1_000_000  # a mapping is a few hundred bytes; anything this big is the wrong file


class MappingError(PhysmotionError):
    """A rig mapping file that cannot be used: unreadable, not JSON, wrong keys, types or joint names."""


@dataclass(frozen=True)
class RigMapping:
    """A parsed mapping file: joints (all 22 of ours -> the file's joints) and optional settings."""

    path: Path
    joints: dict[str, JointSource]
    units: float | None = None
    up_axis: str | None = None
    fps: float | None = None


def load_mapping(path: str | Path) -> RigMapping:
    """Read and check a mapping file; every problem is a one-line :class:`MappingError` naming it."""
    path = Path(path)
    where = f"mapping {path}"
    data = _read_json(path, where)
    if not isinstance(data, dict):
        raise MappingError(f'{where}: expected a JSON object {{"joints": {{...}}, ...}}, got {_kind(data)}')
    unknown = [k for k in data if k not in _KEYS and not str(k).startswith("_")]
    if unknown:
        raise MappingError(f"{where}: unknown key(s) {_names(unknown)} (allowed: {', '.join(_KEYS)})")
    if "joints" not in data:
        raise MappingError(f'{where}: no "joints" object (our joint name -> the file\'s joint name)')
    return RigMapping(
        path=path,
        joints=_joints(data["joints"], where),
        units=_units(data["units"], where) if data.get("units") is not None else None,
        up_axis=_up_axis(data["up_axis"], where) if data.get("up_axis") is not None else None,
        fps=_fps(data["fps"], where) if data.get("fps") is not None else None,
    )


def _read_json(path: Path, where: str) -> Any:
    if not path.exists():
        raise MappingError(f"{where}: no such file")
    if not path.is_file():
        raise MappingError(f"{where}: not a file")
    try:
        if path.stat().st_size > _MAX_BYTES:
            raise MappingError(f"{where}: {path.stat().st_size} bytes is too large for a rig mapping")
        text = path.read_bytes().decode("utf-8-sig")
    except OSError as exc:
        raise MappingError(f"{where}: cannot read the file ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise MappingError(
            f"{where}: not a JSON text file (bytes that are not UTF-8 at offset {exc.start})"
        ) from None

    def no_constants(word: str) -> None:  # json accepts NaN and Infinity, which JSON does not
        raise ValueError(f"{word} is not a JSON number")

    try:
        return json.loads(text, parse_constant=no_constants)
    except json.JSONDecodeError as exc:
        raise MappingError(
            f"{where}: not valid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})"
        ) from None
    except ValueError as exc:  # from no_constants, or an integer too long to convert
        raise MappingError(f"{where}: not valid JSON ({str(exc)[:80]})") from None
    except RecursionError:
        raise MappingError(f"{where}: not a rig mapping (JSON nested too deeply)") from None


def _joints(value: Any, where: str) -> dict[str, JointSource]:
    if not isinstance(value, dict):
        raise MappingError(
            f'{where}: "joints" must be an object of our joint -> file joint, got {_kind(value)}'
        )
    unknown = [k for k in value if k not in JOINT_NAMES]
    if unknown:
        raise MappingError(
            f"{where}: unknown joint name(s) {_names(unknown)}; ours are {', '.join(JOINT_NAMES)}"
        )
    missing = [j for j in JOINT_NAMES if j not in value]
    if missing:
        raise MappingError(f'{where}: "joints" lacks {_names(missing)} (all 22 of ours must be mapped)')
    return {joint: _source(joint, value[joint], where) for joint in JOINT_NAMES}


def _source(joint: str, value: Any, where: str) -> JointSource:
    """A joint name, or a blend [[name, weight], ...] with weights >= 0 summing to 1."""
    if isinstance(value, str):
        if not value.strip():
            raise MappingError(f"{where}: {joint} maps to an empty joint name")
        return value
    shape = f"{joint} must map to a joint name or a list of [joint name, weight] pairs"
    if not isinstance(value, list) or not value:
        raise MappingError(f"{where}: {shape}, got {_kind(value)}")
    blend: list[tuple[str, float]] = []
    for pair in value:
        if not (
            isinstance(pair, list) and len(pair) == 2 and isinstance(pair[0], str) and _is_number(pair[1])
        ):
            raise MappingError(f"{where}: {shape}, got the item {json.dumps(pair)[:60]}")
        blend.append((pair[0], float(pair[1])))
    weights = [w for _, w in blend]
    if min(weights) < 0 or abs(sum(weights) - 1.0) > 1e-6:
        raise MappingError(f"{where}: the weights of {joint} must be >= 0 and sum to 1, got {weights}")
    return tuple(blend)


def _units(value: Any, where: str) -> float:
    if not (isinstance(value, str) or _is_number(value)):
        raise MappingError(
            f'{where}: "units" must be a name (m, cm, mm, inch) or metres per unit, got {_kind(value)}'
        )
    try:
        return parse_units(value)
    except PhysmotionError as exc:
        raise MappingError(f"{where}: {exc}") from None


def _up_axis(value: Any, where: str) -> str:
    if not isinstance(value, str) or value.upper() not in UP_AXES:
        raise MappingError(
            f'{where}: "up_axis" must be one of {", ".join(UP_AXES)}, got {json.dumps(value)[:40]}'
        )
    return value.upper()


def _fps(value: Any, where: str) -> float:
    if not (_is_number(value) and value > 0):
        raise MappingError(f'{where}: "fps" must be a positive number, got {json.dumps(value)[:40]}')
    return float(value)


def _is_number(value: Any) -> bool:
    """A finite JSON number (bool is an int in Python but not a number in JSON)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:  # an int beyond float's range
        return False


def _kind(value: Any) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "true/false", type(None): "null"}.get(
        type(value), "a number"
    )


def _names(items: list[Any]) -> str:
    shown = ", ".join(repr(str(k)[:40]) for k in items[:4])
    return shown + (f" and {len(items) - 4} more" if len(items) > 4 else "")
