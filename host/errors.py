"""The exception type the CLI turns into a clear one-line message, and the warning category of the library."""


class UserError(Exception):
    """Bad input from the user (a file, an argument, a recording).

    ``str()`` is one line that says what was wrong and what is accepted; the
    CLI prints it as ``accelnav: error: ...`` and exits with status 2, never
    with a traceback.
    """


class AccelnavWarning(UserWarning):
    """What the library warns a caller about through :mod:`warnings`: something to act on that did not stop the
    work. The CLI prints it as ``accelnav: warning: ...``; a program filters it as any warning
    (``warnings.simplefilter("ignore", AccelnavWarning)``, or ``"error"`` to stop on it)."""
