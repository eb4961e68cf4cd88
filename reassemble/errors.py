"""The one exception type users see: its message is a single line naming the file and the fix."""


class ReassembleError(Exception):
    """A problem with the user's input or options, reported as one line without a traceback."""
