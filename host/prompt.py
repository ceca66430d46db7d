"""One answer typed at a prompt on the terminal: the line, or None when the user stops."""

from __future__ import annotations


def ask_line(stdin, stderr, prompt: str) -> str | None:
    """Write ``prompt`` to ``stderr`` and read one line from ``stdin``; None at the end of input or 'q' (after a
    line end, so that what is written next starts a line of its own)."""
    stderr.write(prompt)
    stderr.flush()
    line = stdin.readline()
    if not line or line.strip().lower() in ("q", "quit"):
        stderr.write("\n")
        return None
    return line
