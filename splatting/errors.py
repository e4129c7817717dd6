class UserError(Exception):
    """Bad input (missing file, bad YAML, NaN pose, unknown id, corrupt model).

    The CLI prints it as one line on stderr and exits non-zero; library callers catch it.
    """
