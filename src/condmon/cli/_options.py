"""Options that take several values after one flag: ``--healthy a.csv b.csv``.

click (under typer) gives an option one value per flag, so ``--healthy a b``
would read ``b`` as a stray argument; a shell glob (``--healthy h*.csv``)
expands to exactly that. A command made with :func:`greedy_command` reads the
bare words that follow such an option as more of its values, leaving the
command's own arguments their words: ``isolate hst rec.csv --healthy a b`` and
``isolate hst --healthy a b rec.csv`` both read two healthy records.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from typer.core import TyperCommand

__all__ = ["greedy_command", "spread_values"]


def spread_values(args: Sequence[str], greedy: set[str], flags: set[str],
                  arguments: int) -> list[str]:
    """``args`` with the extra bare words after a greedy option given their own flag.

    Parameters
    ----------
    args : sequence of str
        The command line after the command's name.
    greedy : set of str
        Options that take several values (``{"--healthy"}``).
    flags : set of str
        Options that take no value (``--json``, ``--help``).
    arguments : int
        How many bare words the command's own arguments take.

    Example
    -------
    >>> spread_values(["hst", "--healthy", "a", "b", "rec.csv"], {"--healthy"}, set(), 2)
    ['hst', '--healthy', 'a', '--healthy', 'b', 'rec.csv']
    >>> spread_values(["hst", "r.csv", "--healthy", "a", "b", "--json"], {"--healthy"},
    ...               {"--json"}, 2)
    ['hst', 'r.csv', '--healthy', 'a', '--healthy', 'b', '--json']
    """
    bare: list[int] = []       # indices of words that are no option and no option's value
    follows: dict[int, str] = {}  # bare word -> the greedy option it directly follows
    i, after = 0, None
    while i < len(args):
        tok = args[i]
        if tok == "--":
            bare.extend(range(i + 1, len(args)))
            break
        if tok.startswith("-") and len(tok) > 1:
            name = tok.split("=", 1)[0]
            takes = 0 if "=" in tok or name in flags else 1
            after = name if name in greedy else None
            i += 1 + takes
            continue
        bare.append(i)
        if after is not None:
            follows[i] = after
        i += 1
    extra = len(bare) - arguments
    out: list[str] = []
    for k, tok in enumerate(args):
        if extra > 0 and k in follows:
            out += [follows[k], tok]
            extra -= 1
        else:
            out.append(tok)
    return out


def greedy_command(*options: str) -> type[TyperCommand]:
    """A typer command class whose ``options`` each take several values.

    Example
    -------
    >>> greedy_command("--healthy").__name__
    'GreedyCommand'
    """
    greedy = set(options)

    class GreedyCommand(TyperCommand):
        def parse_args(self, ctx: Any, args: list[str]) -> Any:
            # typer carries its own click: parameters are told by their kind's name
            flags = {"--help"}
            arguments = 0
            for p in self.get_params(ctx):
                if p.param_type_name == "option" and (getattr(p, "is_flag", False)
                                                      or getattr(p, "count", False)):
                    flags.update(p.opts)
                    flags.update(p.secondary_opts)
                elif p.param_type_name == "argument":
                    arguments += p.nargs if p.nargs > 0 else len(args)
            return super().parse_args(ctx, spread_values(args, greedy, flags, arguments))

    return GreedyCommand
