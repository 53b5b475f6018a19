"""Where each option of a command does something: an option given where it has no effect is
refused in one line, never taken and ignored (``texsense simulate ramp --hours 3``, ``texsense
monitor --source replay:x.h5 --grid 8x12``, ``texsense station --member a`` without
``--group``): the user would believe it acted.

A command declares its rules where it declares its options: :func:`only_where` adds
:class:`Rule` s to a parser (``parser.set_defaults(option_rules=...)``), and
:func:`check_given` (run by ``texsense.cli`` before every command) refuses an option given
where its rule says it does nothing. An option is *given* when its value differs from its
default or its name is on the command line. What can only be known once a file is read (a
``--calibration`` for a recording that already holds pressure) is refused where it is known,
in the same words (:func:`refuse_unless`, or :func:`no_effect` where the option's value
alone says it was given).

Examples
--------
>>> rule = Rule("--hours", lambda a: a.protocol == "night", "simulate night")
>>> import argparse
>>> rule.applies(argparse.Namespace(protocol="ramp"))
False
>>> no_effect("--hours", "simulate night")
'--hours has no effect here: it applies to simulate night'
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from texsense.exceptions import ParameterError

__all__ = [
    "Rule",
    "check_given",
    "given",
    "given_flags",
    "no_effect",
    "only_where",
    "refuse_unless",
    "rules_of",
]


@dataclass(frozen=True)
class Rule:
    """``flag`` does something only where ``applies(args)`` holds, said as ``where`` (what
    the user must ask for: ``"simulate night"``, ``"a bed (--bed)"``)."""

    flag: str
    applies: Callable[[argparse.Namespace], bool]
    where: str


def no_effect(flag: str, where: str) -> str:
    """The one line for ``flag`` given where it does nothing."""
    return f"{flag} has no effect here: it applies to {where}"


def only_where(parser: argparse.ArgumentParser, rules: Iterable[Rule]) -> None:
    """Declare ``rules`` for the options of ``parser`` (each flag must be one of its
    options: a typo is a programming error, raised now)."""
    rules = list(rules)
    for rule in rules:
        if rule.flag not in parser._option_string_actions:
            raise ValueError(f"{parser.prog}: no option {rule.flag} to give a rule")
    known = list(parser.get_default("option_rules") or [])
    parser.set_defaults(option_rules=known + rules)


def rules_of(parser: argparse.ArgumentParser) -> list[Rule]:
    """The rules declared for ``parser``'s options."""
    return list(parser.get_default("option_rules") or [])


def leaf_parser(parser: argparse.ArgumentParser, args: argparse.Namespace) -> Any:
    """The (sub)parser that parsed ``args``: the command's, or its subcommand's."""
    while True:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs:
            return parser
        chosen = getattr(args, subs[0].dest, None)
        if chosen is None or chosen not in subs[0].choices:
            return parser
        parser = subs[0].choices[chosen]


def given_flags(parser: argparse.ArgumentParser, args: argparse.Namespace,
                argv: Sequence[str]) -> set[str]:  # fmt: skip
    """The options of the command ``args`` that were given: named on the command line
    (``--x``, ``--x=...``, ``-oFILE``, or a prefix argparse took for it) or with a value other
    than the default."""
    leaf = leaf_parser(parser, args)
    options = leaf._option_string_actions
    named = set()
    for word in argv:
        word = word.split("=", 1)[0]
        if not word.startswith("-") or word == "--":
            continue
        if word in options:
            named.add(options[word])
        elif word.startswith("--"):  # a prefix argparse took for the one option it begins
            near = {options[n] for n in options if n.startswith(word)}
            named |= near if len(near) == 1 else set()
        elif word[:2] in options:  # -oFILE
            named.add(options[word[:2]])
    given = set()
    for action in leaf._actions:
        if not action.option_strings or action.dest in (argparse.SUPPRESS, "help"):
            continue
        if action in named or getattr(args, action.dest, action.default) != action.default:
            given.update(action.option_strings)
    return given


def check_given(parser: argparse.ArgumentParser, args: argparse.Namespace,
                argv: Sequence[str]) -> None:  # fmt: skip
    """Refuse (:class:`ParameterError`, one line) the first option given where its rule
    says it has no effect; keep the options given in ``args`` (:func:`given`) for the checks
    a file read later makes (:func:`refuse_unless`)."""
    flags = given_flags(parser, args, argv)
    args.given_flags = frozenset(flags)
    for rule in getattr(args, "option_rules", None) or []:
        if rule.flag in flags and not rule.applies(args):
            raise ParameterError(no_effect(rule.flag, rule.where))


def given(args: argparse.Namespace, flag: str) -> bool:
    """Whether ``flag`` was given on the command line ``args`` was parsed from (named, or a
    value other than its default; :func:`check_given` keeps them)."""
    return flag in getattr(args, "given_flags", ())


def refuse_unless(args: argparse.Namespace, flag: str, applies: bool, where: str,
                  why: str = "") -> None:  # fmt: skip
    """Where only a file tells whether ``flag`` does something: refuse it, in the words of
    :func:`no_effect` (and ``why``: what the file holds), when it was given and does not
    apply.

    >>> args = argparse.Namespace(given_flags=frozenset({"--range"}))
    >>> try:
    ...     refuse_unless(args, "--range", False, "a recording of capacitance", "this is pressure")
    ... except ParameterError as e:
    ...     print(e)
    --range has no effect here: it applies to a recording of capacitance; this is pressure
    """
    if not applies and given(args, flag):
        raise ParameterError(no_effect(flag, where) + (f"; {why}" if why else ""))
