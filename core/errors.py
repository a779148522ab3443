"""The one exception type for input a user can fix."""


class ZoopraxisError(ValueError):
    """Bad input, explained in one line that names the file, frame, view or joint at fault.

    Operators report it as a short error and the command line prints it and exits non-zero;
    anything else is a bug and keeps its traceback.
    """
