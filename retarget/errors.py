"""User-facing errors: one clear line naming the file and the problem, no traceback."""


class RetargetError(Exception):
    """An error caused by the user's input (file, option, weights, checkpoint).

    The CLI prints ``error: <message>`` on one line and exits with status 2. The message must name
    the offending file (when there is one) and the problem.
    """


class RetargetWarning(UserWarning):
    """Something in the user's input that works but may not be what was meant (e.g. two heads in
    one mesh file). The CLI prints ``warning: <message>`` on one line."""
