"""The one exception for bad input, shared by every command of both worlds (docs/contract.md)."""


class UserError(Exception):
    """Bad input (missing file, bad YAML, NaN pose, unknown id, corrupt model).

    Commands print it as one line on stderr and exit non-zero; library callers catch it.
    """
