"""The one error type a user sees: a one-line message, no traceback."""


class FacecleanError(Exception):
    """Bad input or a refused operation. The CLI prints ``faceclean: <message>`` and exits 2."""


def seed(value: object, what: str = "seed") -> int:
    """A random seed: an integer in [0, 2**63), else FacecleanError (numpy wants >= 0)."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2**63:
        raise FacecleanError(f"{what} must be an integer in [0, 2**63), got {value!r:.40}")
    return value


def within(value: float, what: str, low: float, high: float) -> float:
    """``value`` when it is a number in [low, high], else FacecleanError (one line)."""
    try:
        ok = low <= float(value) <= high  # NaN compares False
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise FacecleanError(f"{what} must be in [{low:g}, {high:g}], got {value!r:.40}")
    return float(value)
