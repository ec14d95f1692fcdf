"""User-facing errors: one clear line naming the flag or file and the problem."""


class InputError(ValueError):
    """Bad user input (a flag, a model file, a path file). Printed as one line, exit code 2."""
