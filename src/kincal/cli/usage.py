"""The command line's argument parser: argparse's, with hints for usage errors whose cause
argparse cannot see."""

from __future__ import annotations

import argparse
import sys


class UsageParser(argparse.ArgumentParser):
    """argparse's parser, with a hint where a usage error has a likely cause argparse cannot
    see: an option that takes several values (``--tip`` and ``--base`` one frame per data
    file, ``--validate``, ``--fix`` ...) given before the data files swallows them, and
    argparse then says only that the data are missing."""

    argv: tuple[str, ...] = ()  # the command line being parsed (by the top parser)

    def parse_args(self, args=None, namespace=None):
        UsageParser.argv = tuple(sys.argv[1:] if args is None else args)
        return super().parse_args(args, namespace)

    def error(self, message):
        if "the following arguments are required" in message and "data" in message:
            options = {o for a in self._actions if a.nargs in ("+", "*") for o in a.option_strings}
            taken, where = None, None
            for token in UsageParser.argv:
                if token.startswith("-"):
                    where = token if token in options else None
                elif where and token.lower().endswith((".csv", ".txt", ".tsv")):
                    taken = (where, token)
                    break
            if taken:
                message += (f" ({taken[0]} took {taken[1]!r} as one of its values: it takes "
                            "several; give the data files right after the robot, before the "
                            "options)")
        super().error(message)
