"""The one exception type that command-line tools turn into a single line and exit status 2."""


class InputError(ValueError):
    """Bad input from a user: a file, an option or a value. The message is shown as is."""
