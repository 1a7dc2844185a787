"""Errors that are the user's to fix, reported as one line and a non-zero exit.

Why a dedicated type: the CLI catches exactly these and prints ``error: ...`` without a traceback,
while programming errors still surface with their traceback.
"""

from __future__ import annotations


class UserError(Exception):
    """Bad input (file, flag, value) that the user must correct. Exit code 2."""

    exit_code = 2


class DesignFailed(UserError):
    """An LMI design that is infeasible or solved inaccurately. Exit code 3, and no gains file."""

    exit_code = 3


def run_cli_command(prog: str, args) -> int:
    """Run ``args.func(args)`` the way every command of this project reports errors.

    A ``UserError`` is one line on stderr (``prog command: error: ...``) and its exit code, Ctrl-C is 130,
    a closed stdout pipe (``... | head``) is a quiet exit 2; anything else is a bug and keeps its traceback.
    """
    import os
    import sys

    try:
        return int(args.func(args) or 0)
    except UserError as exc:
        print(f"{prog} {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # the reader went away: say nothing, and keep Python from complaining while it flushes at exit
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 2
