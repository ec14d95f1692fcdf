"""A configuration field and its flag, declared once (``option``): the flag's group, help and
metavar, how its text is read, and which values it takes.

From that one declaration ``add_flags`` makes the argparse entries (and so the help and
docs/USAGE.md's synopsis, generated from the parser), ``from_flags`` the field values of a parsed
command line, and ``check`` the validation every configuration runs at the door. Errors name the
field (``InputError.of``); the error reads as the flag, renamed flags included
(``--no-overlay`` for ``overlay``).
"""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass, field
from typing import Any, Callable

from multigpu import errors
from multigpu.errors import InputError


@dataclass(frozen=True)
class Option:
    """How a field meets the command line. ``help`` may say ``{default}``: the field's default as
    ``show`` writes it (or be a function that writes it: text made from a registry). ``read``:
    the flag's text to the value (raises InputError, field-less);
    ``choices``: the values it takes (a registry, looked up when checked); ``valid`` / ``must``:
    a test and what it demands ("must be >= 1"). ``flag``: the flag where it is not
    ``--field-name``; ``negate``: a ``--no-...`` switch that makes the field False. ``text``: the
    argparse default, where the flag's default is text to read (None: the flag may be absent,
    the default then decided elsewhere: a wall file, another field)."""

    group: str
    help: str | Callable[[], str]
    metavar: str | Callable[[], str] | None = None
    type: Callable | None = None
    read: Callable[[str], Any] | None = None
    choices: Callable[[], Any] | None = None
    valid: Callable[[Any], bool] | None = None
    must: str = ""
    flag: str | None = None
    negate: bool = False
    switch: bool = False
    text: str | None = None
    show: Callable[[Any], str] = str
    const: str | None = None


def option(default, **kw) -> Any:
    """A dataclass field with its ``Option`` (``register`` the class once it is made)."""
    return field(default=default, metadata={"option": Option(**kw)})


def declared(cls) -> list[tuple[dataclasses.Field, Option]]:
    """The fields of ``cls`` that have a flag, in declaration order."""
    return [(f, f.metadata["option"]) for f in dataclasses.fields(cls) if "option" in f.metadata]


def flag_of(name: str, opt: Option) -> str:
    return opt.flag or errors.flag(name)


def register(cls) -> None:
    """Tell ``errors`` the flags of ``cls`` that are not ``--field-name``."""
    for f, opt in declared(cls):
        if opt.flag:
            errors.RENAMED[f.name] = opt.flag


def add_flags(parser: argparse.ArgumentParser, cls, groups: list[str]) -> None:
    """The argparse entries of every flag of ``cls``, group by group in ``groups``' order
    (``metavar`` from ``choices`` where none is given)."""
    made: dict[str, Any] = {}
    for name in groups:
        made[name] = parser.add_argument_group(name)
    for f, opt in declared(cls):
        g = made[opt.group]
        text = opt.help() if callable(opt.help) else opt.help.replace("{default}", opt.show(f.default))
        flag = flag_of(f.name, opt)
        if opt.switch or opt.negate:
            g.add_argument(flag, dest=f.name, action="store_false" if opt.negate else "store_true", help=text)
            continue
        kw: dict[str, Any] = {"dest": f.name, "help": text}
        kw["metavar"] = (opt.metavar() if callable(opt.metavar) else opt.metavar
                         or ("|".join(opt.choices()) if opt.choices else None))
        if opt.type is not None:
            kw["type"] = opt.type
        if opt.const is not None:
            kw.update(nargs="?", const=opt.const)
        kw["default"] = opt.text if opt.read is not None else (None if f.default is dataclasses.MISSING else f.default)
        g.add_argument(flag, **kw)


def read(name: str, opt: Option, text):
    """A flag's text as its field's value; a bad text names the field."""
    try:
        return opt.read(text)
    except InputError as exc:
        if exc.field:
            raise
        raise InputError.of(name, exc.message) from None


def from_flags(cls, a: argparse.Namespace) -> dict:
    """Each flag's field value from a parsed command line: read where it has a reader; a flag
    left absent whose default is decided elsewhere (``text`` None) is left out."""
    out = {}
    for f, opt in declared(cls):
        v = getattr(a, f.name, None)
        if opt.read is not None:
            if v is None:
                continue
            v = read(f.name, opt, v)
        out[f.name] = v
    return out


def check(obj) -> None:
    """Every declared value of a configuration: one of its ``choices``, and ``valid``."""
    for f, opt in declared(type(obj)):
        v = getattr(obj, f.name)
        if opt.choices is not None:
            names = list(opt.choices())
            if v not in names:
                raise InputError.of(f.name, f"must be one of {', '.join(names)}, got '{v}'")
        if opt.valid is not None and not opt.valid(v):
            shown = f"'{v}'" if isinstance(v, str) else v if v is None else opt.show(v)
            raise InputError.of(f.name, f"{opt.must}, got {shown}")
