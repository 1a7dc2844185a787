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
