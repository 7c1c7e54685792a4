"""Exception types that map onto the CLI's exit codes.

- :class:`InputError` -> exit 2: the user's input (file, field, parameter) is unusable.
  The message is one line naming the file/field and what is wrong.
- :class:`ValidationFailed` -> exit 1: a validation against a closed-form or reference
  result missed its tolerance (its outputs are still written, for inspection).
- :class:`ConvergenceError` -> exit 1: a solver did not reach its tolerance. It is never
  swallowed; a result that did not converge is not returned.
"""


import os


class SimfabError(Exception):
    """Base class of simfab's own errors."""


class InputError(SimfabError, ValueError):
    """Bad user input. ``str(err)`` is a one-line message naming where the problem is.

    Args:
        message: what is wrong, one line.
        where: the file, field or CLI flag at fault (``str(err)`` is ``"WHERE: message"``); None when
            the message names it.
    """

    def __init__(self, message: str, *, where: str | None = None):
        self.where = where
        self.message = message
        super().__init__(f"{where}: {message}" if where else message)

    def in_file(self, file) -> "InputError":
        """The same error located in ``file`` (its field kept): ``FILE: FIELD: message``.

        Args:
            file: the file the error's input came from.

        Returns:
            An :class:`InputError` naming ``file`` (this error itself when it already does).
        """
        if str(file) in str(self) or (self.where and os.path.basename(str(file)) in str(self.where)):
            return self  # already located
        field = f"{self.where}: " if self.where else ""
        return InputError(f"{field}{self.message}", where=str(file))


class ConvergenceError(SimfabError, RuntimeError):
    """A solver did not converge to its documented tolerance."""


class ValidationFailed(SimfabError):
    """A validation case missed its stated tolerance."""
