"""The one error type a user sees: a one-line message, no traceback."""


class FacecleanError(Exception):
    """Bad input or a refused operation. The CLI prints ``faceclean: <message>`` and exits 2."""
