"""How the `trunkslam` command line reads: the typer group behind `experiments.cli.app`.

typer (0.29, on click 8.2+) shows every flag with a `<bool>` type, a required argument as
`{input}` and an optional one as `[input]`, puts pydantic's "Value error, " before a refused
choice, and takes the app's own options (`-v`) only before the subcommand. `TrunkslamGroup`
mends these four in one place, so that the commands themselves stay plain typer:

- flags show no type (their `--x/--no-x` pair says it) and arguments read `INPUT` (required)
  or `[INPUT]` (optional), click's convention;
- a refused value's message loses the "Value error, " prefix;
- `-v`/`--verbose` anywhere before a `--` is taken as the app's option (`trunkslam slam run.npz
  -v` works as `trunkslam -v slam run.npz`); no subcommand has an option of that name.

It also keeps pydantic (0.1 s to import) off the answers that need no value checked: typer
checks every value with a pydantic adapter, built on first use, even a value left out (None),
which it passes through unchecked. An option or argument left out is passed through here
without building one, so `trunkslam slam --help` and `trunkslam presets` never import pydantic
(the app's own `--threads` is left out in both).
"""

from __future__ import annotations

import typer
from typer.core import TyperArgument, TyperGroup, TyperOption

__all__ = ["VERBOSE_FLAGS", "TrunkslamGroup", "counted", "hoist_verbose"]

VERBOSE_FLAGS = ("-v", "--verbose")
_PYDANTIC_PREFIX = "Value error, "


def _pass_through_class():
    """typer's coercion that checks nothing (typer 0.2x's internals; None in a typer without)."""
    try:
        from typer._coercion import PassThroughRuntimeParam  # loaded with typer.core
    except ImportError:
        return None
    return PassThroughRuntimeParam


def _process_left_out(self, ctx: typer.Context, value):
    """`process_value` of a parameter whose value, when left out (None), is passed on without
    typer's pydantic adapter: typer's coercion returns None (or `()` for a multi-valued one)
    before it would use the adapter, but builds the adapter first
    (`typer.core._TyperParameter`)."""
    cls = type(self).__mro__[1]  # typer's class
    stand_in = _pass_through_class()
    if value is not None or stand_in is None or getattr(self, "_runtime_param", 0) is not None:
        return cls.process_value(self, ctx, value)  # a given value, or another typer
    desc = self.type_descriptor
    self._runtime_param = stand_in(desc.parameter_info, desc.annotation)
    try:  # typer's own path (required check, callback), with a stand-in that checks nothing
        return cls.process_value(self, ctx, value)
    finally:
        self._runtime_param = None  # a value given later still gets the real adapter


class _Option(TyperOption):
    """An option whose left-out value imports no pydantic. (One base only: `_tidy` swaps
    the class of typer's objects, which a mixin's layout would refuse.)"""

    process_value = _process_left_out


class _Argument(TyperArgument):
    """An argument shown as click shows it: `INPUT`, `[INPUT]` when optional; its left-out
    value imports no pydantic."""

    process_value = _process_left_out

    def _usage_display_name(self) -> str:
        name = self.display_name_raw.upper()
        if self.nargs != 1:
            name += "..."
        return name if self.required else f"[{name}]"


def counted(n: int, noun: str) -> str:
    """ "1 scan", "2 scans", "0 scans": a count and its noun (regular plurals only)."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def hoist_verbose(args: list[str]) -> list[str]:
    """`args` with every `-v`/`--verbose` before a `--` moved to the front (the app's option)."""
    end = args.index("--") if "--" in args else len(args)
    flags = [a for a in args[:end] if a in VERBOSE_FLAGS]
    rest = [a for a in args[:end] if a not in VERBOSE_FLAGS]
    return flags + rest + args[end:]


def _tidy(command) -> None:
    """Flags without a type; arguments in click's style; down every subcommand."""
    for param in command.params:
        if isinstance(param, TyperOption) and param.is_flag and param.metavar is None:
            param.metavar = ""
        if type(param) is TyperOption:
            param.__class__ = _Option  # only `process_value` differs
        elif isinstance(param, TyperArgument) and type(param) is TyperArgument:
            param.__class__ = _Argument  # only display methods differ
    own_help = command.get_help_option  # --help is made when first asked for

    def get_help_option(ctx):
        option = own_help(ctx)
        if option is not None and option.metavar is None:
            option.metavar = ""
        if type(option) is TyperOption:
            option.__class__ = _Option  # not given (None) on every command's way: no pydantic
        return option

    command.get_help_option = get_help_option
    for sub in getattr(command, "commands", {}).values():
        _tidy(sub)


class TrunkslamGroup(TyperGroup):
    """The app's group: see the module doc."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        _tidy(self)

    def parse_args(self, ctx: typer.Context, args: list[str]) -> list[str]:
        return super().parse_args(ctx, hoist_verbose(args))

    def invoke(self, ctx: typer.Context):
        try:
            return super().invoke(ctx)
        except typer.BadParameter as exc:
            exc.message = exc.message.replace(_PYDANTIC_PREFIX, "")
            raise
