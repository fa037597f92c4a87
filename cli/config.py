"""Command-line flags generated from documented dataclasses.

A command's options are one dataclass: each field is a flag (``theta_i`` ->
``--theta-i``), the string literal under a field is its ``--help`` text (read
with ``ast``, the way nerfstudio documents its configs), its default is the
flag's default, and its type decides the parsing:

- ``bool``: a switch (``--name`` when the default is False, ``--no-name`` when True);
- a mode enum (``viewer/modes.py``) or a ``Literal``: ``choices``;
- ``int``/``float``/``str`` and their ``X | None`` forms: converted by argparse;
  a float flag takes finite numbers only (:func:`finite_float`: ``nan`` and
  ``inf`` are never a setting, and would render black or train to NaN);
- anything else (``tuple[int, int]`` sizes, ``X,Y,Z`` points): a parser given
  in the field's ``metadata["parse"]``, run after argparse so that its error is
  the command's own one-line message.

A field whose ``metadata["nested"]`` is true holds another such dataclass: its
fields marked ``metadata["cli"]`` become flags of their own (the previewer's
view settings, declared once in viewer/view_settings.py). A field without a
default is a required flag. ``metadata`` may also set
``positional`` (an optional positional argument), ``flag`` (another flag name),
``metavar``, ``choices`` and ``shown`` (how the default reads in ``--help``).
Each flag's action carries ``field_type``, the field's type with ``None``
unwrapped, so that checks over every flag of every command (tests) start from
the dataclasses.

Usage errors never print usage text: :class:`Parser` raises ``NbrdfError``,
which the entry points turn into one line on stderr and exit status 2.
"""
from __future__ import annotations

import argparse
import ast
import dataclasses
import enum
import inspect
import math
import textwrap
import types
import typing
from functools import lru_cache
from typing import Any, Callable, Iterable, Mapping, Sequence

from nbrdf.neural.errors import NbrdfError


class Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line (an ``NbrdfError``,
    so exit status 2 through ``run_guarded``) instead of usage text.

    ``populate(parser)``, when given, adds the flags on first use (parsing or
    help): a subcommand whose config lives in a heavy module (torch) costs
    nothing until it is the one run."""

    def __init__(self, *args: Any, populate: Callable[["Parser"], None] | None = None, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self.populate = populate

    def ready(self) -> "Parser":
        """Adds the deferred flags (once)."""
        if self.populate is not None:
            fn, self.populate = self.populate, None
            fn(self)
        return self

    def parse_known_args(self, args=None, namespace=None):
        self.ready()
        return super().parse_known_args(args, namespace)

    def format_usage(self) -> str:
        self.ready()
        return super().format_usage()

    def format_help(self) -> str:
        self.ready()
        return super().format_help()

    def error(self, message: str):
        raise NbrdfError(f"{self.prog}: {message}")


def finite_float(text: str) -> float:
    """The converter of every float flag: a finite number, else argparse's
    one-line usage error naming the flag."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid float value: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


@lru_cache(maxsize=None)
def field_docs(cls: type) -> dict[str, str]:
    """``{field: docstring}`` from the string literals that follow the
    annotated fields in the source of ``cls`` and of its dataclass bases."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass) or klass is object:
            continue
        try:
            src = textwrap.dedent(inspect.getsource(klass))
        except (OSError, TypeError):  # no source (e.g. a frozen build): no help text
            continue
        body = ast.parse(src).body[0].body  # type: ignore[attr-defined]
        for stmt, nxt in zip(body, body[1:]):
            if (isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name)
                    and isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant)
                    and isinstance(nxt.value.value, str)):
                docs[stmt.target.id] = " ".join(nxt.value.value.split())
    return docs


def flag_name(name: str) -> str:
    """``theta_i`` -> ``--theta-i``."""
    return "--" + name.replace("_", "-")


def _unwrap_optional(tp: Any) -> tuple[Any, bool]:
    """``X | None`` -> (X, True); anything else -> (tp, False)."""
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(tp)) == 2:
            return args[0], True
    return tp, False


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


def _shown(value: Any) -> str:
    if isinstance(value, enum.Enum):
        return str(value.value)
    if isinstance(value, tuple):
        return ",".join(str(v) for v in value)
    return str(value)


def _typed(action: argparse.Action, tp: object) -> None:
    """Records a flag's dataclass field type on its action (what the flag tests walk)."""
    vars(action)["field_type"] = tp


def add_arguments(parser: argparse.ArgumentParser, cls: type, *, only: Iterable[str] | None = None,
                  exclude: Iterable[str] = (), defaults: Mapping[str, Any] | None = None,
                  help: Mapping[str, str] | None = None, choices: Mapping[str, Sequence[str]] | None = None,
                  required: Iterable[str] = ()) -> list[str]:
    """Adds one flag per field of the dataclass ``cls`` to ``parser``; returns
    the field names added. ``only``/``exclude`` select fields; ``defaults``,
    ``help`` and ``choices`` override per field (for dataclasses whose source
    this module does not own); ``required`` makes defaulted fields required."""
    hints = typing.get_type_hints(cls)
    docs = field_docs(cls)
    keep = set(only) if only is not None else None
    skip = set(exclude)
    defaults, help, choices, required = dict(defaults or {}), dict(help or {}), dict(choices or {}), set(required)
    added = []
    for f in dataclasses.fields(cls):
        if not f.init or f.name in skip or (keep is not None and f.name not in keep):
            continue
        meta = f.metadata
        if meta.get("nested"):
            inner = hints[f.name]
            added += add_arguments(parser, inner, only=_cli_fields(inner))
            continue
        tp, optional = _unwrap_optional(hints[f.name])
        default = defaults.get(f.name, _default(f))
        text = help.get(f.name, docs.get(f.name, "")).replace("%", "%%")  # argparse %-formats help
        kw: dict[str, Any] = {"dest": f.name}
        names = [meta.get("flag", flag_name(f.name))]
        if meta.get("positional"):
            names, kw = [f.name], {"nargs": "?"}
        if "metavar" in meta:
            kw["metavar"] = meta["metavar"]
        if tp is bool and optional and default is None:  # three states: --x, --no-x, or unset
            g = parser.add_mutually_exclusive_group()
            _typed(g.add_argument(*names, action="store_true", default=None, help=text), tp)
            _typed(g.add_argument("--no-" + names[0][2:], dest=f.name, action="store_false",
                                  help=meta.get("no_help", f"not {names[0]}")), tp)
            added.append(f.name)
            continue
        if tp is bool:
            if default is True:
                names = [meta.get("flag", "--no-" + f.name.replace("_", "-"))]
                kw.update(action="store_false", default=True)
            else:
                kw.update(action="store_true", default=False)
            _typed(parser.add_argument(*names, help=text, **kw), tp)
            added.append(f.name)
            continue
        words = choices.get(f.name, meta.get("choices"))
        if words is None and isinstance(tp, type) and issubclass(tp, enum.Enum):
            words = [str(m.value) for m in tp]
        elif words is None and typing.get_origin(tp) is typing.Literal:
            words = [str(a) for a in typing.get_args(tp)]
        if words is not None:
            kw["choices"] = list(words)
        elif "parse" not in meta and tp is float:
            kw["type"] = finite_float
        elif "parse" not in meta and tp is int:
            kw["type"] = int
        if default is dataclasses.MISSING or f.name in required:
            if meta.get("positional"):
                raise TypeError(f"{cls.__name__}.{f.name}: a positional field needs a default")
            kw["required"] = True
        else:
            kw["default"] = default
            if default is not None:
                text = f"{text} (default: {meta.get('shown', _shown(default))})".strip()
        _typed(parser.add_argument(*names, help=text, **kw), tp)
        added.append(f.name)
    return added


def _cli_fields(cls: type) -> list[str]:
    """The fields of a nested dataclass that are flags (``metadata["cli"]``)."""
    return [f.name for f in dataclasses.fields(cls) if f.metadata.get("cli")]


def values(cls: type, ns: argparse.Namespace, names: Iterable[str] | None = None) -> dict[str, Any]:
    """The parsed values of ``cls``'s fields (those in ``names``, default:
    every field present in ``ns``), converted to the field types: enums from
    their words, and ``metadata["parse"]`` applied (its ``NbrdfError`` is the
    one-line message)."""
    hints = typing.get_type_hints(cls)
    keep = set(names) if names is not None else None
    out: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if f.init and f.metadata.get("nested"):
            inner = hints[f.name]
            out[f.name] = inner(**values(inner, ns, _cli_fields(inner)))
            continue
        if not f.init or not hasattr(ns, f.name) or (keep is not None and f.name not in keep):
            continue
        v = getattr(ns, f.name)
        tp, _ = _unwrap_optional(hints[f.name])
        parse: Callable[[str], Any] | None = f.metadata.get("parse")
        if v is not None and parse is not None and isinstance(v, str):
            v = parse(v)
        elif v is not None and isinstance(tp, type) and issubclass(tp, enum.Enum):
            v = tp(v)
        out[f.name] = v
    return out


def build(cls: type, ns: argparse.Namespace, names: Iterable[str] | None = None, **extra: Any):
    """An instance of ``cls`` from the parsed namespace (see :func:`values`),
    with ``extra`` fields set directly."""
    return cls(**{**values(cls, ns, names), **extra})
