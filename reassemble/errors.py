"""The one exception type users see: its message is a single line naming the file and the fix."""


class ReassembleError(Exception):
    """A problem with the user's input or options, reported as one line without a traceback."""


def first_line(exc: BaseException) -> str:
    """The first line of an exception's message ('' when it has none)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else ""
