"""One exception type for everything a user can fix: it carries where and what."""

from __future__ import annotations


class ChaincompError(Exception):
    """A problem in user input, reported as ``file:line: field: message``."""

    def __init__(self, message: str, file: str | None = None, line: int | None = None,
                 field: str | None = None):
        self.message = message
        self.file = file
        self.line = line
        self.field = field
        super().__init__(self.__str__())

    def __str__(self) -> str:
        where = ""
        if self.file:
            where = self.file + (f":{self.line}" if self.line else "") + ": "
        what = f"{self.field}: " if self.field else ""
        return where + what + self.message


class NoAnswer(ChaincompError):
    """The input was read and is valid, but gives no answer (a fit that does not converge):
    exit 4, apart from bad input (2)."""


class OutsideLimit(ChaincompError):
    """A result outside a limit the user set (identify --strict: a fit that does not fit):
    exit 1."""
