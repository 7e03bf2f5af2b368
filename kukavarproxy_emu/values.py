"""Value rules of the variable store: coercion, validation and partial-aggregate merging.

:mod:`kukavarproxy_emu.store` decides *where* a value goes; this module decides *what* may go
there. Everything here is a pure function of a value and its KRL type (no store state), so each
rule can be read, and changed, on its own:

* :func:`parse_text` — KUKAVARPROXY write text to a validated value;
* :func:`coerce` — a typed Python value (``set_system``) to a value of the target type;
* :func:`check` / :func:`check_ranges` — what a KRC cannot hold (float32 range, CHAR length,
  latin-1, declared limits);
* :func:`rebuild` — a value put at a member path, merging partial structs as KRL does.

A refusal is raised as :class:`Refused` (no variable name yet); the store turns it into a
:class:`~kukavarproxy_emu.store.WriteRefused` for its caller.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from math import isfinite
from numbers import Integral, Real

from pyopenshowvar.errors import KrlValueError
from pyopenshowvar.krl import (
    TYPED_STRUCTS,
    Kind,
    KrlEnum,
    KrlValue,
    Struct,
    TypeRegistry,
    TypeSpec,
    parse_value,
)
from pyopenshowvar.sysvars import INT_MAX, INT_MIN

__all__ = [
    "CHAR_LEN",
    "Range",
    "Refused",
    "check",
    "check_ranges",
    "coerce",
    "member_specs",
    "normalise",
    "parse_text",
    "rebuild",
]

Range = tuple[float, float]
_FLOAT32_MAX = 3.4028234663852886e38  # a KRL REAL is a float32
#: ``CHAR[32]``: the element type of a CHAR array as the store spells it (the length limit).
CHAR_LEN = re.compile(r"CHAR\s*\[\s*([0-9]+)\s*\]\Z")
_MEMBER_BRACKETS = re.compile(r'("[^"]*")|([A-Za-z_$][A-Za-z0-9_$]*)[ \t]*\[[ \t]*\]')
_PLAIN_INT = re.compile(r"\s*[+-]?[0-9]+\s*\Z")


class Refused(Exception):
    """A reason to refuse a write, before the caller's variable name is attached."""


def member_specs(
    registry: TypeRegistry, spec: TypeSpec, type_name: str, members: tuple[str, ...]
) -> list[tuple[TypeSpec, str]]:
    """(spec, type name) of the element and of each member on the path, outermost first."""
    chain = [(spec, type_name)]
    for member in members:
        if spec.struct is None:
            raise Refused(f"{type_name} has no members")
        member_type = spec.struct.member_type(member)
        if member_type is None:
            raise Refused(f"{spec.struct.name} has no member {member}")
        spec, type_name = registry.resolve(member_type), member_type
        chain.append((spec, type_name))
    return chain


def normalise(value: KrlValue, spec: TypeSpec) -> KrlValue:
    """A struct in its declared type with members in declaration order (as a KRC prints it)."""
    if spec.struct is None or not isinstance(value, Struct):
        return value
    sdef = spec.struct
    cls = TYPED_STRUCTS.get(sdef.name)
    if cls is not None and isinstance(value, cls):
        return value  # typed structs keep canonical order themselves
    if cls is not None:
        return cls().merged(value)  # coerces and orders the members
    names = sdef.member_names
    members = value.members
    if value.type_name == sdef.name and tuple(members) == names[: len(members)]:
        return value  # already in its type and order (the names come from the declaration)
    return Struct._new(sdef.name, {m: members[m] for m in names if m in members})


def rebuild(
    old: KrlValue | None, chain: list[tuple[TypeSpec, str]], members: tuple[str, ...], new: KrlValue
) -> KrlValue:
    """``old`` with ``new`` put at ``members``; partial structs merge, as KRL aggregates do."""
    spec = chain[0][0]
    if not members:
        if isinstance(old, Struct) and isinstance(new, Struct):
            if spec.struct is not None and len(new) == len(spec.struct.members):
                # complete and flat (nested partials must merge), or a complete value of this
                # very type (a variable copied whole): nothing to keep from old
                if new.type_name == spec.struct.name or not any(
                    isinstance(v, Struct) for v in new.values()
                ):
                    return normalise(new, spec)
            return normalise(old.merged(new), spec)
        return normalise(new, spec)
    base = old if isinstance(old, Struct) else Struct(spec.name, {})
    child = rebuild(base.get(members[0]), chain[1:], members[1:], new)
    # the child is the merged member already: replace it (merging it again costs a copy of
    # every nested structure, per assignment)
    return normalise(base.replace(**{members[0]: child}), spec)


def coerce(value: object, spec: TypeSpec, registry: TypeRegistry) -> KrlValue:
    """A typed Python value converted to ``spec`` (numpy scalars accepted), or Refused."""
    kind = spec.kind
    if kind is Kind.REAL and isinstance(value, Real) and not isinstance(value, bool):
        return float(value)
    if kind is Kind.INT and isinstance(value, Integral) and not isinstance(value, bool):
        if not INT_MIN <= int(value) <= INT_MAX:
            raise Refused(f"INT {value} out of the 32-bit range")
        return int(value)
    if (kind is Kind.BOOL and isinstance(value, bool)) or (
        kind is Kind.STR and isinstance(value, str)
    ):
        return value
    if kind is Kind.ENUM and isinstance(value, KrlEnum):
        if spec.enum is not None and value.name not in spec.enum.values:
            raise Refused(f"{value} is not a value of ENUM {spec.name}")
        return value
    if kind is Kind.STRUCT and isinstance(value, Struct) and spec.struct is not None:
        cls = TYPED_STRUCTS.get(spec.struct.name)
        if cls is not None and isinstance(value, cls):
            return value  # the typed constructor has coerced the members already
        members: dict[str, KrlValue] = {}
        for member, member_value in value.items():
            member_type = spec.struct.member_type(member)
            if member_type is None:
                raise Refused(f"{spec.struct.name} has no member {member}")
            members[member] = coerce(member_value, registry.resolve(member_type), registry)
        return normalise(Struct(spec.name, members), spec)
    raise Refused(f"{value!r} is not a {spec.name} value")


def check(value: KrlValue, spec: TypeSpec, type_name: str, registry: TypeRegistry) -> None:
    """Refuse what the parser lets through but a KRC cannot hold or print."""
    if isinstance(value, float):
        if not (isfinite(value) and abs(value) <= _FLOAT32_MAX):
            raise Refused(f"{value!r} is out of the REAL (float32) range")
    elif isinstance(value, str):
        limit = CHAR_LEN.match(type_name)
        if limit is not None and len(value) > int(limit.group(1)):
            raise Refused(f"text longer than {limit.group(1)} characters")
        if '"' in value or (not value.isascii() and not _is_latin1(value)):
            raise Refused("a CHAR text must be latin-1 without double quotes")
    elif isinstance(value, Struct) and spec.struct is not None:
        for member, member_value in value.items():
            member_type = spec.struct.member_type(member)
            if member_type is not None:
                member_spec = registry.resolve(member_type)
                check(member_value, member_spec, member_type, registry)


def _is_latin1(text: str) -> bool:
    try:
        text.encode("latin-1")
    except UnicodeEncodeError:
        return False
    return True


def parse_text(
    text: str, spec: TypeSpec, type_name: str, registry: TypeRegistry, *, strict: bool
) -> KrlValue:
    """Parse ``text`` as a fully validated value of the given type.

    ``strict`` refuses REAL text for an INT target, which a KRC would convert (``50.0``).
    """
    if strict and spec.kind is Kind.INT and not _PLAIN_INT.match(text):
        raise Refused("strict: an INT needs plain decimal text")
    if "[" in text:
        # $CONFIG.DAT writes CHAR members as NAME[] "text"; the krl parser wants NAME "text"
        text = _MEMBER_BRACKETS.sub(lambda m: m.group(1) or m.group(2), text)
    try:
        value = parse_value(text, type_name, registry=registry)
    except KrlValueError as exc:
        raise Refused(str(exc)) from None
    check(value, spec, type_name, registry)
    return value


def _check_range(value: KrlValue | None, rng: Range, what: str) -> None:
    if isinstance(value, int | float) and not isinstance(value, bool):
        if not rng[0] <= value <= rng[1]:
            raise Refused(f"{what} {value} out of range {rng[0]}..{rng[1]}")


def check_ranges(ranges: Range | Mapping[str, Range] | None, name: str, value: KrlValue) -> None:
    """Refuse ``value`` of variable ``name`` outside its declared limits (see ``declare``)."""
    if ranges is None:
        return
    if isinstance(ranges, tuple):
        _check_range(value, ranges, name)
        return
    for member_path, rng in ranges.items():
        part: KrlValue | None = value
        for member in member_path.upper().split("."):
            part = part.get(member) if isinstance(part, Struct) else None
        _check_range(part, rng, f"{name}.{member_path.upper()}")
