"""What a command that runs many tasks prints (``clean`` of a batch, ``pairs``).

Each finished task advances one progress bar; its line goes above the bar on stdout (a
failure always, ``FAILED label: why``; a success when the command echoes them); the
failures are kept, and ``summary`` names each one and why on stderr at the end.
"""

from __future__ import annotations

import sys

Failure = tuple[str, str]  # (the task's label, why it failed)


def done(bar, label: str, result: tuple[bool, str], failed: list[Failure], echo=False) -> None:
    """One task finished: ``result`` (True, its line) or (False, why)."""
    ok, text = result
    if not ok:
        bar.write(f"FAILED {label}: {text}", file=sys.stdout)
        failed.append((label, text))
    elif echo:
        bar.write(text, file=sys.stdout)
    bar.update(1)


def summary(failed: list[Failure]) -> int:
    """The failures named on stderr; the command's exit status (1 when any failed)."""
    if not failed:
        return 0
    print(f"faceclean: {len(failed)} failed:", file=sys.stderr)
    for label, why in failed:
        print(f"  {label}: {why}", file=sys.stderr)
    return 1
