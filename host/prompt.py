"""One answer typed at a prompt on the terminal: the line, or None when the user stops."""

from __future__ import annotations


def ask_line(stdin, stderr, prompt: str) -> str | None:
    """Write ``prompt`` to ``stderr`` and read one line from ``stdin``; None at the end of input or 'q'. Those and
    Ctrl-C (its KeyboardInterrupt raised on) end the prompt's line: what is written next starts a line of its own."""
    try:  # the prompt's writing too: once it shows, Ctrl-C may come before the read begins
        stderr.write(prompt)
        stderr.flush()
        line = stdin.readline()
    except KeyboardInterrupt:
        stderr.write("\n")
        raise
    if not line or line.strip().lower() in ("q", "quit"):
        stderr.write("\n")
        return None
    return line
