"""The one exception type the CLI turns into a clear one-line message."""


class UserError(Exception):
    """Bad input from the user (a file, an argument, a recording).

    ``str()`` is one line that says what was wrong and what is accepted; the
    CLI prints it as ``accelnav: error: ...`` and exits with status 2, never
    with a traceback.
    """
