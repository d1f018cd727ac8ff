"""Errors a user can act on: the CLI and the service print their message, never a traceback."""


class UserError(Exception):
    """Bad input or a failed step, with a message naming the problem and what to do."""
